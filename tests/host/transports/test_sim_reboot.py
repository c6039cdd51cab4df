"""A unit opened by seed (``sim://?seed=N``: the link owns it) lives through its own reboot: the
host reconnects to the same unit, flash and all, and closing the camera then ends it."""
from __future__ import annotations

import pytest

import stereocam
from stereocam.device_sim import registry
from tests.support.firmware import image

pytestmark = pytest.mark.sim_only("opens in-process simulators by seed")


def test_an_update_of_a_unit_opened_by_seed_boots_the_new_image():
    with stereocam.open("sim://?seed=2&serial=SEEDFW", timeout=2.0) as cam:
        result = cam.update_firmware(image("1.2.0"))
        assert (result.version, result.slot) == ("1.2.0", "B") and cam.info().firmware_version == "1.2.0"
        assert [s.serial for s in registry.live_simulators()].count("SEEDFW") == 1  # the same unit, not a new one
    assert "SEEDFW" not in [s.serial for s in registry.live_simulators()]  # its owner closed it


def test_a_reboot_then_a_reconnect_keeps_the_unit_and_its_configuration():
    with stereocam.open("sim://?seed=3&serial=SEEDRB", timeout=2.0) as cam:
        cam.configure(gain=17)
        (unit,) = [s for s in registry.live_simulators() if s.serial == "SEEDRB"]
        unit.reboot()
        cam.reconnect(timeout=10)
        assert cam.config()["gain"] == 17  # re-applied by the host
        assert [s for s in registry.live_simulators() if s.serial == "SEEDRB"] == [unit]
    assert unit not in registry.live_simulators()
