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
from stereocam.protocol.framing import VERSION_MINOR
from stereocam.device_sim.process import ServedSimulator
from stereocam.tools import cli
from tests.support.hangs import returns_within

pytestmark = pytest.mark.sim_only("updates the simulated unit's firmware")


def stereocam(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "stereocam.tools.cli", *args], capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture
def signed(tmp_path: Path):
    """A vendor key and its images: 1.2.0 (fps default 12), 1.1.0 as a rollback image, 1.1.0 plain."""
    key = tmp_path / "vendor.pem"
    assert stereocam("firmware", "keygen", "--out", str(key)).returncode == 0
    code = tmp_path / "code.bin"
    code.write_bytes(os.urandom(300_000))
    images = {}
    for name, version, extra in (("new", "1.2.0", ()), ("rollback", "1.1.0", ("--security-counter", "16908289")),
                                 ("old", "1.1.0", ())):
        out = tmp_path / f"{name}.img"
        build = tmp_path / f"build-{version}.json"
        build.write_text(json.dumps({**json.loads(FACTORY_BUILD.to_json()), "version": version,
                                     "parameter_defaults": {**FACTORY_BUILD.parameter_defaults, "fps": 12}}))
        r = stereocam("firmware", "sign", "--key", str(key), "--code", str(code), "--out", str(out), *extra,
                      str(build))
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
        assert f"protocol 1.{VERSION_MINOR}" in stereocam("info", sim.url).stdout


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


def test_keygen_never_overwrites_a_signing_key_unless_forced(tmp_path: Path, capsys) -> None:
    key = tmp_path / "vendor.pem"
    assert cli.main(["firmware", "keygen", "--out", str(key)]) == 0
    original, original_pub = key.read_bytes(), (tmp_path / "vendor.pem.pub").read_bytes()
    capsys.readouterr()
    assert cli.main(["firmware", "keygen", "--out", str(key)]) == 2
    err = capsys.readouterr().err
    assert "already exist" in err and "--force" in err and "Traceback" not in err
    assert key.read_bytes() == original and (tmp_path / "vendor.pem.pub").read_bytes() == original_pub
    (tmp_path / "lone.pem.pub").write_bytes(original_pub)  # a public half alone is kept too
    assert cli.main(["firmware", "keygen", "--out", str(tmp_path / "lone.pem")]) == 2
    assert not (tmp_path / "lone.pem").exists() and (tmp_path / "lone.pem.pub").read_bytes() == original_pub
    assert cli.main(["firmware", "keygen", "--out", str(key), "--force"]) == 0
    assert key.read_bytes() != original and key.stat().st_mode & 0o777 == 0o600
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lone.pem.pub", "vendor.pem", "vendor.pem.pub"]


@pytest.mark.parametrize("force", [False, True])
def test_keygen_creates_the_private_key_0600_from_the_start(tmp_path: Path, monkeypatch, force: bool) -> None:
    """With a permissive umask and no later chmod, the key is still never readable by others."""
    key = tmp_path / "vendor.pem"
    if force:
        key.write_bytes(b"old key")
        key.chmod(0o644)
    monkeypatch.setattr(Path, "chmod", lambda self, mode, **kw: None)
    monkeypatch.setattr(os, "chmod", lambda *a, **kw: None)
    old_umask = os.umask(0)
    try:
        assert cli.main(["firmware", "keygen", "--out", str(key), *(["--force"] if force else [])]) == 0
    finally:
        os.umask(old_umask)
    assert key.stat().st_mode & 0o777 == 0o600 and key.read_bytes().startswith(b"-----BEGIN PRIVATE KEY")


def _sign(tmp_path: Path, build: dict | str, *extra: str) -> tuple[int, Path]:
    key = tmp_path / "vendor.pem"
    if not key.exists():
        assert cli.main(["firmware", "keygen", "--out", str(key)]) == 0
    path = tmp_path / "build.json"
    path.write_text(json.dumps(build) if isinstance(build, dict) else build)
    out = tmp_path / "out.img"
    out.unlink(missing_ok=True)
    return cli.main(["firmware", "sign", "--key", str(key), "--version", "1.2.0", "--out", str(out), *extra,
                     str(path)]), out


FACTORY = {**json.loads(FACTORY_BUILD.to_json()), "version": "1.2.0"}


@pytest.mark.parametrize("build, words", [
    ({**FACTORY, "protocol_minor": 99999999999}, "protocol_minor"),
    ({**FACTORY, "version": "1.2"}, "MAJOR.MINOR.PATCH"),
    ({**FACTORY, "capabilities": -5}, "capabilities"),
    ({**FACTORY, "capabilities": 2**32}, "capabilities"),
    ({**FACTORY, "parameter_defaults": {"fps": 1000}}, "fps"),
    ({**FACTORY, "parameter_defaults": {"fps": 2**40}}, "fps"),
    ({**FACTORY, "parameter_defaults": {"no_such": 1}}, "no such parameter"),
    (json.dumps(FACTORY).replace(f'"capabilities": {FACTORY["capabilities"]}', '"capabilities": 1e400'),
     "capabilities"),
    (json.dumps({**FACTORY, "parameter_defaults": {"fps": 0}}).replace('"fps": 0', '"fps": 1e400'), "fps"),
    ("{not json", "not a firmware build")])
def test_sign_refuses_a_build_a_unit_could_not_run(tmp_path: Path, capsys, build, words: str) -> None:
    rc, out = _sign(tmp_path, build)
    err = capsys.readouterr().err
    assert rc == 2 and words in err and "Traceback" not in err
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.parametrize("extra, words", [
    (("--security-counter", "-1"), "0..4294967295"), (("--security-counter", "99999999999999"), "0..4294967295"),
    (("--target", "ABCDEFGHIJKLMNOPQ"), "at most 16"), (("--target", "ABCDEFGHIJKLMNOé"), "16 printable ASCII"),
    (("--version", "1.2"), "disagrees with"), (("--version", "1.3.0"), "whose version is 1.2.0")])
def test_sign_refuses_header_fields_the_image_cannot_hold(tmp_path: Path, capsys, extra, words: str) -> None:
    rc, out = _sign(tmp_path, FACTORY, *extra)
    err = capsys.readouterr().err
    assert rc == 2 and words in err and "Traceback" not in err and not out.exists()


def test_sign_accepts_header_fields_at_their_limits(tmp_path: Path, capsys) -> None:
    from stereocam.protocol.firmware_image import inspect_image

    rc, out = _sign(tmp_path, FACTORY, "--security-counter", str(2**32 - 1), "--target", "ABCDEFGHIJKLMNOP")
    assert rc == 0, capsys.readouterr().err
    img = inspect_image(out.read_bytes())
    assert (img.security_counter, img.target, img.build.version) == (2**32 - 1, "ABCDEFGHIJKLMNOP", "1.2.0")


def test_sign_never_writes_over_its_own_key(tmp_path: Path, capsys) -> None:
    key = tmp_path / "vendor.pem"
    assert cli.main(["firmware", "keygen", "--out", str(key)]) == 0
    original = key.read_bytes()
    (tmp_path / "build.json").write_text(json.dumps(FACTORY))
    rc = cli.main(["firmware", "sign", "--key", str(key), "--version", "1.2.0", "--out", str(key),
                   str(tmp_path / "build.json")])
    assert rc == 2 and "--key" in capsys.readouterr().err and key.read_bytes() == original


def test_a_unit_refuses_an_out_of_range_build_and_keeps_answering(tmp_path: Path) -> None:
    """An image from a signer that did not check: the unit refuses it, and GET_INFO still works."""
    import dataclasses

    import stereocam
    from stereocam import firmware_update as fw
    from stereocam.device_sim.boot.factory import DEV_SIGNING_KEY
    from stereocam.protocol.firmware_image import ImageFault, build_image

    bad = build_image(dataclasses.replace(FACTORY_BUILD, version="1.2.0", protocol_minor=99999999999),
                      DEV_SIGNING_KEY, target="STOC-SIM")
    sim = SimulatedCamera(serial="FW-BAD-BUILD", seed=7)
    cam = stereocam.open("sim://?serial=FW-BAD-BUILD", timeout=2.0)
    try:
        with pytest.raises(fw.ImageRefusedError) as refused:
            fw.transfer(cam.request, bad)
        assert refused.value.fault == ImageFault.MALFORMED and "protocol_minor" in str(refused.value)
        assert cam.info().firmware_version == "1.1.0"
    finally:
        cam.close()
        sim.close()


# -- issue 22 items 10 and 16: inputs that are not files, or too large, or missing --------------------
def _not_files(tmp_path: Path) -> dict[str, Path]:
    """A FIFO, a device, a folder and a sparse 3 GiB file: none may be read."""
    fifo = tmp_path / "fifo.img"
    os.mkfifo(fifo)
    big = tmp_path / "big.img"
    with open(big, "wb") as f:
        f.truncate(3 << 30)
    return {"fifo": fifo, "device": Path("/dev/zero"), "folder": tmp_path, "3 GiB": big}


@pytest.mark.parametrize("kind", ["fifo", "device", "folder", "3 GiB"])
def test_update_and_sign_refuse_what_is_not_a_file_or_larger_than_a_slot_before_reading(tmp_path, capsys, kind):
    path = _not_files(tmp_path)[kind]
    why = "more than" if kind == "3 GiB" else "not a regular file"
    rc = returns_within(20, cli.main, ["firmware", "update", "sim://?seed=1", str(path)])
    err = capsys.readouterr().err
    assert rc == 1 and why in err and str(path) in err and "Traceback" not in err
    _sign(tmp_path, FACTORY)[1].unlink()  # the key (its image is not wanted)
    for flag in ("--code", "--key"):
        extra = ("--code", str(path)) if flag == "--code" else ()
        key = ["--key", str(path)] if flag == "--key" else ["--key", str(tmp_path / "vendor.pem")]
        (tmp_path / "build.json").write_text(json.dumps(FACTORY))
        rc = returns_within(20, cli.main, ["firmware", "sign", *key, "--version", "1.2.0", "--out",
                                           str(tmp_path / "out.img"), *extra, str(tmp_path / "build.json")])
        err = capsys.readouterr().err
        assert rc == 2 and why in err and "Traceback" not in err, flag
    assert not (tmp_path / "out.img").exists()


def test_a_missing_input_file_is_a_usage_error_exit_2(tmp_path, capsys):
    _sign(tmp_path, FACTORY)
    for argv in (["firmware", "update", "sim://?seed=1", str(tmp_path / "nonexistent.img")],
                 ["firmware", "sign", "--key", str(tmp_path / "nonexistent.pem"), "--version", "1.2.0", "--out",
                  str(tmp_path / "o.img"), str(tmp_path / "build.json")],
                 ["recording", "info", str(tmp_path / "nonexistent.mcap")]):
        assert cli.main(argv) == 2, argv
        err = capsys.readouterr().err
        assert "nonexistent" in err and "does not exist" in err and "Traceback" not in err


@pytest.mark.parametrize("command", [["keygen"], ["sign", "--key", "vendor.pem", "build.json"]])
def test_an_empty_out_path_is_a_usage_error(capsys, command: list[str]) -> None:
    """``--out ''`` (click's Path makes it '.', a path without a file name): a usage error, no traceback."""
    assert cli.main(["firmware", *command, "--out", ""]) == 2
    err = capsys.readouterr().err
    assert "'--out'" in err and "the path is empty" in err and "Traceback" not in err
