"""Protocol 1.3 with a 1.2 peer (SPEC §11.2): a 1.2 device has SGM without the capability bit and
no stage limits; a 1.2 host reads a 1.3 INFO as it always did."""
from __future__ import annotations

import dataclasses

import pytest

from stereocam import Camera
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.links.inprocess import InProcessTransport
from stereocam.protocol import messages as m
from stereocam.protocol.config_rules import ConfigRejected, merge
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.params import BY_NAME, defaults
from tests.support.faults import FaultyTransport, PacketFilter, as_v1_2_info


def test_negotiated_capabilities_by_minor() -> None:
    caps = m.Capability.DISPARITY
    assert m.negotiated_capabilities(2, caps) == caps | m.Capability.SGM  # every 1.2 device has SGM
    assert m.negotiated_capabilities(3, caps) == caps  # from 1.3 on the bit says it
    assert m.negotiated_capabilities(1, caps) == caps  # a 1.1 device has no algorithm parameter


def test_a_1_2_host_reads_a_1_3_info_as_before() -> None:
    info = m.Info("STOC", "SN", "2.0.0", (1, 3), 0x3FF, 1280, 960, 1 << 20, 1280, 960, 7, 3,
                  ((m.Stage.SEMI_GLOBAL, 640, 480),))
    payload = info.pack()
    v12_fields = payload[:-(1 + 6)]  # what a 1.2 host knows of it: up to usb_speed
    assert m.Info.unpack(v12_fields) == dataclasses.replace(info, stage_limits=())
    assert info.stage_limit(m.Stage.SEMI_GLOBAL) == (640, 480)
    assert info.stage_limit(m.Stage.BLOCK_MATCHING) == (1280, 960)  # no entry: the device's maxima


@pytest.fixture
def v12_camera():
    sim = SimulatedCamera(seed=41)
    t = FaultyTransport(InProcessTransport(sim))
    t.set_manipulator(read=PacketFilter(as_v1_2_info))
    cam = Camera(t, timeout=2.0)
    yield cam
    cam.close()
    sim.close()


def test_a_1_3_host_uses_sgm_on_a_1_2_device(v12_camera) -> None:
    info = v12_camera.connection.info
    assert info.protocol_version == (1, 2) and not info.capabilities & m.Capability.SGM and not info.stage_limits
    assert info.effective_capabilities & m.Capability.SGM
    assert v12_camera.check_config(algorithm=1)["algorithm"] == 1
    v12_camera.configure(algorithm=1)
    assert v12_camera.config()["algorithm"] == 1


def test_a_1_3_device_without_sgm_is_refused_before_sending() -> None:
    info = m.Info("STOC", "SN", "2.0.0", (1, 3), m.Capability.DISPARITY, 1280, 960, 1 << 20, 1280, 960)
    with pytest.raises(ConfigRejected) as refused:
        merge(defaults(), {BY_NAME["algorithm"].pid: 1}, False, info.effective_capabilities)
    assert (refused.value.code, refused.value.param) == (ErrorCode.OUT_OF_RANGE, "algorithm")
