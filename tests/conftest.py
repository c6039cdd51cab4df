"""Shared fixtures: the same integration tests run over every transport, or against ``--device URL``.

Without ``--device`` each test runs back-to-back over: an in-process simulator (sim://), a
simulator in a second process behind a real pseudo-terminal opened by pyserial, one behind a
real TCP socket (pyserial's socket://), and one plugged into the simulated USB bus and opened
through the real pyusb core (usb://?serial=...).
"""
from __future__ import annotations

import os

import pytest

from stereocam.device_sim.process import ServedSimulator

TRANSPORTS = ("sim", "pty", "tcp", "usb")


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--device", action="store", default=None, metavar="URL",
                     help="run the integration tests against this camera URL instead of simulators")


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    if "device_url" in metafunc.fixturenames:
        url = metafunc.config.getoption("--device")
        metafunc.parametrize("device_url", [url] if url else list(TRANSPORTS), indirect=True)


@pytest.fixture(scope="session", autouse=True)
def factory_db_in_tmp(tmp_path_factory: pytest.TempPathFactory):
    """Calibration runs record their attempts in a session-scoped SQLite file, not in the home folder."""
    old = os.environ.get("STEREOCAM_FACTORY_DB")
    os.environ["STEREOCAM_FACTORY_DB"] = str(tmp_path_factory.mktemp("factory") / "factory.sqlite")
    yield
    if old is None:
        os.environ.pop("STEREOCAM_FACTORY_DB")
    else:
        os.environ["STEREOCAM_FACTORY_DB"] = old


@pytest.fixture(scope="session")
def served():
    """Lazily started child-process simulators, one per served transport, for the whole session."""
    servers: dict[str, ServedSimulator] = {}

    def get(kind: str) -> ServedSimulator:
        if kind not in servers:
            servers[kind] = ServedSimulator("pty" if kind == "pty" else "tcp:127.0.0.1:0")
        return servers[kind]

    yield get
    for s in servers.values():
        s.stop()


@pytest.fixture(scope="session")
def usb_camera():
    """A simulated camera plugged into the simulated USB bus for the whole session."""
    import stereocam.device_sim.usb as simusb
    from stereocam.device_sim import SimulatedCamera

    sim = SimulatedCamera(serial="IT-USB-7", seed=7)
    handle = simusb.plug(sim)
    yield f"usb://?serial={sim.serial}"
    handle.unplug()
    sim.close()


@pytest.fixture
def device_url(request, served) -> str:
    kind = request.param
    if kind == "sim":
        return "sim://?seed=7"
    if kind == "usb":
        return request.getfixturevalue("usb_camera")
    if kind in ("pty", "tcp"):
        return served(kind).url
    return kind  # an external device URL from --device


@pytest.fixture
def cam(device_url):
    """An open camera in its default configuration, at a small format so tests run fast."""
    import stereocam
    from stereocam.protocol.params import defaults

    camera = stereocam.open(device_url, timeout=2.0)
    try:
        camera.configure(**{**defaults(), "width": 320, "height": 240, "num_disparities": 32, "block_size": 11})
        yield camera
    finally:
        camera.close()
