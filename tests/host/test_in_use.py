"""A second host is told the camera is 'in use by another host', whatever the transport (issue 20
item 5): not a timeout, not a bare disconnect, not a garbled link shared by two hosts."""
from __future__ import annotations

import pytest

import stereocam
from stereocam.device_sim import SimulatedCamera

pytestmark = pytest.mark.sim_only("opens one simulated unit from two hosts")


@pytest.fixture
def in_process_unit():
    sim = SimulatedCamera(serial="INUSE1", seed=9)
    yield f"sim://?serial={sim.serial}"
    sim.close()


@pytest.mark.parametrize("kind", ["sim", "usb", "pty", "tcp"])
def test_a_second_host_is_told_the_camera_is_in_use_by_another_host(kind, request, served):
    url = {"sim": lambda: request.getfixturevalue("in_process_unit"),
           "usb": lambda: request.getfixturevalue("usb_camera"),
           "pty": lambda: served("pty").url, "tcp": lambda: served("tcp").url}[kind]()
    with stereocam.open(url, timeout=2.0) as first:
        with pytest.raises(stereocam.TransportError, match="in use by another host"):
            stereocam.open(url, timeout=1.0)
        assert first.info().serial  # the first host still has its camera
