"""The configuration rules (SPEC §4.3, §5.2) live in protocol/config_rules.py; the device's store
and the host's ``Camera.check_config`` use the same function and agree on every verdict."""
from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import stereocam
from stereocam.camera import Camera
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.links.inprocess import InProcessTransport
from stereocam.protocol.config_rules import ConfigRejected, merge
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.params import BY_NAME, defaults


def pid(name: str) -> int:
    return BY_NAME[name].pid


@pytest.mark.parametrize("update, code, blamed", [
    ({99: 1}, ErrorCode.UNKNOWN_PARAM, "param_99"),
    ({pid("fps"): 0}, ErrorCode.OUT_OF_RANGE, "fps"),
    ({pid("block_size"): 16}, ErrorCode.OUT_OF_RANGE, "block_size"),  # even
    ({pid("width"): 64, pid("height"): 48}, ErrorCode.OUT_OF_RANGE, "width"),  # rule 3 blames width of the three
    ({pid("height"): 48, pid("block_size"): 51}, ErrorCode.OUT_OF_RANGE, "block_size"),  # rule 1
    ({pid("height"): 48, pid("pre_filter_size"): 49}, ErrorCode.OUT_OF_RANGE, "pre_filter_size"),  # rule 2
    ({pid("num_disparities"): 256, pid("width"): 256}, ErrorCode.OUT_OF_RANGE, "num_disparities"),  # rule 3
    ({pid("fps"): 120, pid("exposure_us"): 9000}, ErrorCode.OUT_OF_RANGE, "exposure_us"),  # rule 4
    ({pid("fps"): 120}, ErrorCode.OUT_OF_RANGE, "fps"),  # rule 4, only fps in the request
])
def test_rules_name_the_parameter(update, code, blamed) -> None:
    current = {**defaults(), "exposure_us": 9000} if update == {pid("fps"): 120} else defaults()
    with pytest.raises(ConfigRejected) as err:
        merge(current, update, streaming=False)
    assert err.value.code == code and err.value.param == blamed
    assert isinstance(err.value, stereocam.ConfigError)


def test_non_live_parameters_only_while_stopped() -> None:
    with pytest.raises(ConfigRejected) as err:
        merge(defaults(), {pid("width"): 320}, streaming=True)
    assert err.value.code == ErrorCode.BAD_STATE and err.value.param == "width"
    # an unchanged width is fine
    assert merge(defaults(), {pid("width"): 640, pid("fps"): 10}, streaming=True)["fps"] == 10


@pytest.fixture(scope="module")
def cam():
    with Camera(InProcessTransport(SimulatedCamera(seed=41)), timeout=2.0) as camera:
        yield camera


def test_check_config_refuses_locally_and_changes_nothing(cam) -> None:
    cam.configure(width=320, height=240, num_disparities=32, block_size=11)
    before = cam.config()
    with pytest.raises(ConfigRejected, match="larger than the image") as err:
        cam.check_config(block_size=241)
    assert err.value.param == "block_size"
    assert cam.config() == before
    assert cam.check_config(block_size=21)["block_size"] == 21 and cam.config() == before


names = sorted(set(defaults()) - {"trigger_mode"})


@given(st.dictionaries(st.sampled_from(names), st.integers(-300, 2000), max_size=4))
@settings(max_examples=60, deadline=None)
def test_host_check_and_device_agree(cam, params) -> None:
    """Whatever the host's check says, the device answers the same (accept, or the same code and parameter)."""
    cam.configure(**{**defaults(), "width": 320, "height": 240, "num_disparities": 32, "block_size": 11})
    try:
        expected = cam.check_config(**params)
    except ConfigRejected as exc:
        with pytest.raises(stereocam.ConfigRefused) as err:  # a DeviceError and a ConfigError, as exc is
            cam.configure(**params)
        assert isinstance(err.value, stereocam.DeviceError) and isinstance(err.value, stereocam.ConfigError)
        assert (err.value.code, err.value.param) == (exc.code, exc.param)
    else:
        assert cam.configure(**params) == expected
