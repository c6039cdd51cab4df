"""Shared fixtures: the same integration tests run over every transport, or against ``--device URL``.

Without ``--device`` each device test runs back-to-back over: an in-process simulator (sim://),
a simulator in a second process behind a real pseudo-terminal opened by pyserial, one behind a
real TCP socket (pyserial's socket://), and one plugged into the simulated USB bus and opened
through the real pyusb core (usb://?serial=...). With ``--device URL`` they run against that
camera only, and tests marked ``sim_only`` (they need the simulator's internals: its ground
truth, its flash, pulling its plug) are skipped with their reason.

Every test gets its own simulated USB bus, so tests can run in any order.
"""
from __future__ import annotations

import os
import re

import pytest

from stereocam.device_sim.process import ServedSimulator
from stereocam.tools.conformance.budget import TIME_FACTOR_ENV
from tests.support.device import SMALL, url_of

TRANSPORTS = ("sim", "pty", "tcp", "usb")
BUSY_HOST_TIME_FACTOR = "3"
"""Real-link budgets (conformance, wait_until) are stretched this much unless STEREOCAM_TIME_FACTOR
says otherwise: simulators on a busy 2-core host deliver late for reasons that are not the
firmware's. Set in the environment so child processes (served simulators, CLI runs) see it too."""
os.environ.setdefault(TIME_FACTOR_ENV, BUSY_HOST_TIME_FACTOR)


# Tests that share one expensive run go to one worker (``--dist loadgroup``): node id pattern ->
# group. (pytest 9 node ids no longer carry xdist_group's "@name" suffix, so the groups are named
# here, where the scheduler, which sees only node ids, can read them.)
WORKER_GROUPS = {
    # the whole conformance suite runs once per transport; each check's outcome is a test of its own
    re.compile(r"tests/tools/conformance/test_device\.py::\w+\[(\w+)"): "conformance-{0}",
}


def pytest_xdist_make_scheduler(config: pytest.Config, log):
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadGroupScheduling

    class Grouped(LoadGroupScheduling):
        def _split_scope(self, nodeid: str) -> str:
            for pattern, group in WORKER_GROUPS.items():
                if m := pattern.match(nodeid):
                    return group.format(*m.groups())
            return super()._split_scope(nodeid)

    return Grouped(config, log)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--device", action="store", default=None, metavar="URL",
                     help="run the device tests against this camera URL instead of simulators")


DEVICE_FIXTURES = ("device_url", "device_kind")  # parametrised over TRANSPORTS (or --device URL)


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    url = metafunc.config.getoption("--device")
    for name in DEVICE_FIXTURES:
        if name in metafunc.fixturenames:
            metafunc.parametrize(name, [url] if url else list(TRANSPORTS), indirect=True)
            return


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    external = config.getoption("--device")
    for item in items:
        if set(DEVICE_FIXTURES) & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.device)
        if "device_sim" in item.path.relative_to(item.config.rootpath).parts:
            item.add_marker(pytest.mark.sim_only("tests the simulator itself"))
        marker = item.get_closest_marker("sim_only")
        if external and marker is not None:
            reason = marker.args[0] if marker.args else marker.kwargs.get("reason", "needs the simulator")
            item.add_marker(pytest.mark.skip(reason=f"simulator only: {reason}"))


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    if "device" not in report.keywords:
        return
    if report.when == "call" or (report.when == "setup" and report.outcome != "passed"):
        _DEVICE_OUTCOMES[report.outcome] = _DEVICE_OUTCOMES.get(report.outcome, 0) + 1


_DEVICE_OUTCOMES: dict[str, int] = {}


def pytest_terminal_summary(terminalreporter, exitstatus: int, config: pytest.Config) -> None:
    url = config.getoption("--device")
    if not url or not _DEVICE_OUTCOMES:
        return
    ran = _DEVICE_OUTCOMES.get("passed", 0) + _DEVICE_OUTCOMES.get("failed", 0)
    terminalreporter.write_sep("=", f"{ran} tests ran against the device at {url}: "
                                    f"{_DEVICE_OUTCOMES.get('passed', 0)} passed, "
                                    f"{_DEVICE_OUTCOMES.get('failed', 0)} failed, "
                                    f"{_DEVICE_OUTCOMES.get('skipped', 0)} skipped")
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


@pytest.fixture(scope="session", autouse=True)
def detection_cache(tmp_path_factory: pytest.TempPathFactory) -> None:
    """One board-detection cache for the session, shared by the xdist workers and the CLI runs they
    start (tools/calibration/detection_cache.py): the calibration tests detect each image once."""
    from stereocam.tools.calibration.detection_cache import ENV

    root = tmp_path_factory.getbasetemp()
    os.environ[ENV] = str((root.parent if os.environ.get("PYTEST_XDIST_WORKER") else root) / "detections")


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


@pytest.fixture(autouse=True)
def usb_bus(monkeypatch):
    """A simulated USB bus of this test's own: ``simusb.plug`` and ``usb://`` see only it."""
    import stereocam.device_sim.usb as simusb

    bus = simusb.SimUsbBus(number=1)
    monkeypatch.setattr(simusb, "BUS", bus)  # the SDK scans simusb.get_backend(), its entry point
    try:
        yield bus
    finally:
        bus.unplug_all()


@pytest.fixture
def usb_camera(usb_bus):
    """A simulated camera plugged into this test's USB bus; its usb:// URL."""
    from stereocam.device_sim import SimulatedCamera

    sim = SimulatedCamera(serial="IT-USB-7", seed=7)
    handle = usb_bus.plug(sim)
    yield f"usb://?serial={sim.serial}"
    handle.unplug()
    sim.close()


@pytest.fixture
def device_url(request) -> str:
    return url_of(request.param, request)


@pytest.fixture
def device_kind(request) -> str:
    """The transport name (or --device's URL) alone, for tests that start the device only when they
    need it (``url_of``)."""
    return request.param


@pytest.fixture
def cam(device_url):
    """An open camera in its default configuration, at a small format so tests run fast."""
    import stereocam
    from stereocam.protocol.params import defaults

    camera = stereocam.open(device_url, timeout=2.0)
    try:
        camera.configure(**{**defaults(), **SMALL})
        yield camera
    finally:
        camera.close()
