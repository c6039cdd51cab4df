"""The README's firmware commands, run as written (issue 20 item 6): the shipped example build signs
and installs, the rollback takes the next security counter, and after it a later release still
installs (a large counter would have locked every release out for good)."""
from __future__ import annotations

import json
import logging
import re
import shlex
from importlib import resources
from pathlib import Path

import pytest

from stereocam.device_sim import SimulatedCamera
from stereocam.protocol.firmware_image import auto_security_counter, inspect_image, load_private_key
from stereocam.tools import cli

pytestmark = pytest.mark.sim_only("updates the simulated unit's firmware")

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE = "tools/firmware/build.example.json"


def readme_commands() -> list[list[str]]:
    text = (ROOT / "README.md").read_text()
    block = re.search(r"<!-- firmware-example -->\n```sh\n(.*?)```", text, re.S).group(1)
    lines = [re.sub(r"\[.*?\]|#.*", "", line) for line in block.splitlines()]  # optional parts, comments
    return [shlex.split(line)[1:] for line in lines if line.strip()]


def test_the_example_build_ships_in_the_package():
    shipped = resources.files("stereocam.tools.firmware") / "build.example.json"
    assert shipped.read_text() == (ROOT / EXAMPLE).read_text()
    assert json.loads(shipped.read_text())["version"] == "1.2.0"


def test_the_readme_firmware_commands_run_and_the_rollback_leaves_later_releases_installable(
        tmp_path, monkeypatch, usb_bus, capsys, caplog):
    monkeypatch.chdir(tmp_path)
    example = json.loads((ROOT / EXAMPLE).read_text())
    Path("build-1.1.0.json").write_text(json.dumps({**example, "version": "1.1.0"}))  # as the README says
    url, sim = "usb://?serial=FW-DOCS", None
    try:
        for args in readme_commands():
            args = [url if a.startswith("socket://") else str(ROOT / a) if a == EXAMPLE else a for a in args]
            assert cli.main(args) == 0, (args, capsys.readouterr().err)
            out = capsys.readouterr().out
            if args[:2] == ["firmware", "keygen"]:  # the unit's factory provisioned this key
                sim = SimulatedCamera(serial="FW-DOCS", seed=5, vendor_key=load_private_key(Path("vendor.pem").read_bytes()))
                usb_bus.plug(sim)
            if args[:2] == ["firmware", "update"]:
                assert "1.1.0 -> 1.2.0" in out
            if args[:2] == ["firmware", "status"]:
                floor = int(re.search(r"minimum security counter (\d+)", out).group(1))
                assert floor == auto_security_counter("1.2.0")
        rollback = inspect_image(Path("back-1.1.0.img").read_bytes())
        assert rollback.security_counter == floor + 1  # the next counter
        assert cli.main(["firmware", "update", url, "back-1.1.0.img"]) == 0
        assert "1.2.0 -> 1.1.0" in capsys.readouterr().out
        Path("build-1.2.1.json").write_text(json.dumps({**example, "version": "1.2.1"}))
        assert cli.main(["firmware", "sign", "--key", "vendor.pem", "--out", "fw-1.2.1.img", "build-1.2.1.json"]) == 0
        assert cli.main(["firmware", "update", url, "fw-1.2.1.img"]) == 0  # the next release still installs
        assert "1.1.0 -> 1.2.1" in capsys.readouterr().out
        warnings = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
        assert warnings == []  # the reboots were asked for: no 'link lost' / 'reconnected' WARNINGs
    finally:
        if sim is not None:
            sim.close()


def test_sign_refuses_a_version_that_disagrees_with_the_build_file(tmp_path, capsys):
    key = tmp_path / "vendor.pem"
    assert cli.main(["firmware", "keygen", "--out", str(key)]) == 0
    out = tmp_path / "fw.img"
    rc = cli.main(["firmware", "sign", "--key", str(key), "--version", "1.3.0", "--out", str(out), str(ROOT / EXAMPLE)])
    err = capsys.readouterr().err
    assert rc == 2 and "--version 1.3.0 disagrees" in err and "1.2.0" in err and not out.exists()
    assert cli.main(["firmware", "sign", "--key", str(key), "--version", "1.2.0", "--out", str(out),
                     str(ROOT / EXAMPLE)]) == 0
    assert inspect_image(out.read_bytes()).build.version == "1.2.0"
