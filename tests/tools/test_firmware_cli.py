"""``stereocam firmware``: keygen, sign, update (TCP: a served simulator in its own process; USB: the
simulated bus), status, a signed rollback, and a host killed mid-transfer then resumed."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.handlers.device_info import FACTORY_BUILD
from stereocam.device_sim.process import ServedSimulator
from stereocam.tools import cli

pytestmark = pytest.mark.sim_only("updates the simulated unit's firmware")


def stereocam(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "stereocam.tools.cli", *args], capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture
def signed(tmp_path: Path):
    """A vendor key and its images: 1.2.0 (fps default 12), 1.1.0 as a rollback image, 1.1.0 plain."""
    key = tmp_path / "vendor.pem"
    assert stereocam("firmware", "keygen", "--out", str(key)).returncode == 0
    build = tmp_path / "build.json"
    build.write_text(json.dumps({**json.loads(FACTORY_BUILD.to_json()),
                                 "parameter_defaults": {**FACTORY_BUILD.parameter_defaults, "fps": 12}}))
    code = tmp_path / "code.bin"
    code.write_bytes(os.urandom(300_000))
    images = {}
    for name, version, extra in (("new", "1.2.0", ()), ("rollback", "1.1.0", ("--security-counter", "99999999")),
                                 ("old", "1.1.0", ())):
        out = tmp_path / f"{name}.img"
        r = stereocam("firmware", "sign", "--key", str(key), "--version", version, "--code", str(code),
                      "--out", str(out), *extra, str(build))
        assert r.returncode == 0, r.stderr
        images[name] = out
    return key, images


def test_update_and_signed_rollback_over_tcp(signed):
    key, images = signed
    with ServedSimulator("tcp:127.0.0.1:0", extra=("--vendor-key", str(key))) as sim:
        r = stereocam("firmware", "update", sim.url, str(images["new"]))
        assert r.returncode == 0, r.stderr
        assert "1.1.0 -> 1.2.0 in slot B, confirmed" in r.stdout
        status = stereocam("firmware", "status", sim.url).stdout
        assert "running B (normal)" in status and "1.2.0" in status and "active" in status and "standby" in status
        r = stereocam("firmware", "update", sim.url, str(images["old"]))
        assert r.returncode == 1 and "rollback: security counter" in r.stderr and "Traceback" not in r.stderr
        r = stereocam("firmware", "update", sim.url, str(images["rollback"]))
        assert r.returncode == 0 and "1.2.0 -> 1.1.0 in slot A, confirmed" in r.stdout, r.stderr
        assert "protocol 1.2" in stereocam("info", sim.url).stdout


def test_an_image_signed_with_another_key_is_refused_over_tcp(signed):
    _, images = signed
    with ServedSimulator("tcp:127.0.0.1:0") as sim:  # this unit trusts the simulator's development key
        r = stereocam("firmware", "update", sim.url, str(images["new"]))
        assert r.returncode == 1 and "IMAGE_REJECTED: wrong_key" in r.stderr
        assert "running A (normal)" in stereocam("firmware", "status", sim.url).stdout


def test_update_over_usb_from_the_cli(signed, usb_bus, capsys):
    key, images = signed
    from stereocam.protocol.firmware_image import load_private_key

    sim = SimulatedCamera(serial="FW-CLI-USB", seed=5, vendor_key=load_private_key(key.read_bytes()))
    usb_bus.plug(sim)
    url = "usb://?serial=FW-CLI-USB"
    assert cli.main(["firmware", "update", url, str(images["new"])]) == 0
    assert "1.1.0 -> 1.2.0 in slot B, confirmed" in capsys.readouterr().out
    assert cli.main(["firmware", "update", url, str(images["rollback"])]) == 0
    assert "1.2.0 -> 1.1.0 in slot A" in capsys.readouterr().out
    assert cli.main(["firmware", "status", url]) == 0
    assert "running A (normal)" in capsys.readouterr().out
    assert cli.main(["firmware", "status", url, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert (doc["running"], doc["mode"]) == ("A", "normal") and [s["slot"] for s in doc["slots"]] == ["A", "B"]
    assert {s["version"] for s in doc["slots"]} == {"1.1.0", "1.2.0"} and all(len(s["sha256"]) == 64 for s in doc["slots"])
    assert usb_bus.devices[0].descriptors.device.bcdDevice == 0x0110  # re-enumerated as what it runs
    usb_bus.unplug_all()
    sim.close()


HOST = """
import sys, stereocam
from stereocam import firmware_update as fw
cam = stereocam.open(sys.argv[1], timeout=2.0)
fw.transfer(cam.request, open(sys.argv[2], "rb").read(), lambda done, total: print(done, total, flush=True))
"""


def test_a_host_killed_mid_transfer_then_a_resumed_update(signed):
    key, images = signed
    size = images["new"].stat().st_size
    with ServedSimulator("tcp:127.0.0.1:0", extra=("--vendor-key", str(key))) as sim:
        host = subprocess.Popen([sys.executable, "-c", HOST, sim.url, str(images["new"])], stdout=subprocess.PIPE,
                                text=True)
        for line in host.stdout:
            if int(line.split()[0]) >= size // 3:
                host.send_signal(signal.SIGKILL)  # the host dies mid-transfer, the unit stays up
                break
        host.wait(timeout=10)
        assert host.returncode == -signal.SIGKILL
        status = stereocam("firmware", "status", sim.url).stdout
        assert f"of {size} bytes" in status
        r = stereocam("firmware", "update", sim.url, str(images["new"]))
        assert r.returncode == 0, r.stderr
        resumed = int(r.stdout.split("resumed at byte ")[1].split()[0].rstrip("("))
        assert size // 3 <= resumed < size
        assert "1.1.0 -> 1.2.0 in slot B, confirmed" in r.stdout
