"""Every parameter in the protocol's table, just beyond its limits, against every device.

A refused value gets a NACK with OUT_OF_RANGE naming that parameter, and the device's
configuration is unchanged (SPEC §5). Values exactly at a limit are accepted unless a
cross-parameter rule forbids them in the test's configuration.

Every test here leaves the configuration as it found it (that is what each asserts), so one open
camera per transport serves the whole module; USB's stays per test, as its bus is each test's own.
"""
from __future__ import annotations

from collections.abc import Iterator

import pytest

import stereocam
from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.params import PARAMS, Param, defaults
from tests.support.device import SMALL, url_of


def _open(url: str) -> stereocam.Camera:
    camera = stereocam.open(url, timeout=2.0)
    camera.configure(**{**defaults(), **SMALL})
    return camera


@pytest.fixture(scope="module")
def opened() -> Iterator[dict[str, stereocam.Camera]]:
    cameras: dict[str, stereocam.Camera] = {}
    yield cameras
    for camera in cameras.values():
        camera.close()


@pytest.fixture
def cam(device_kind: str, request: pytest.FixtureRequest,
        opened: dict[str, stereocam.Camera]) -> Iterator[stereocam.Camera]:
    """An open camera in its default configuration at the small format, shared by the module's
    tests on this transport (USB: this test's own)."""
    if device_kind == "usb":
        camera = _open(url_of(device_kind, request))
        try:
            yield camera
        finally:
            camera.close()
        return
    camera = opened.get(device_kind)
    if camera is None or not camera.alive:
        camera = opened[device_kind] = _open(url_of(device_kind, request))
    yield camera


def _bad_values(p: Param) -> list[tuple[str, int]]:
    cases = [("below", p.lo - 1), ("above", p.hi + 1)]
    if p.odd:
        cases.append(("even", p.lo + 1))
    if p.step > 1:
        cases.append(("off_step", p.lo + 1))
    return cases


CASES = [pytest.param(p, value, id=f"{p.name}-{what}") for p in PARAMS for what, value in _bad_values(p)]


@pytest.mark.parametrize("param, value", CASES)
def test_a_value_beyond_the_table_is_refused_naming_the_parameter(cam, param: Param, value: int):
    before = cam.config()
    with pytest.raises(stereocam.DeviceError) as exc:
        cam.request(m.SetConfig({param.pid: value}))
    assert exc.value.code == ErrorCode.OUT_OF_RANGE
    assert exc.value.param == param.name
    assert cam.config() == before


@pytest.mark.parametrize("param", [pytest.param(p, id=p.name) for p in PARAMS])
def test_one_bad_value_refuses_the_whole_update(cam, param: Param):
    """All or nothing: a valid change beside a bad one is not applied either."""
    before = cam.config()
    other = "fps" if param.name != "fps" else "gain"
    new_other = before[other] - 1 if before[other] > 1 else before[other] + 1
    with pytest.raises(stereocam.DeviceError) as exc:
        cam.request(m.SetConfig({stereocam.protocol.params.BY_NAME[other].pid: new_other, param.pid: param.hi + 1}))
    assert exc.value.param == param.name
    assert cam.config() == before


def test_an_unknown_parameter_id_is_refused(cam):
    before = cam.config()
    unknown = max(p.pid for p in PARAMS) + 100
    with pytest.raises(stereocam.DeviceError) as exc:
        cam.request(m.SetConfig({unknown: 1}))
    assert exc.value.code == ErrorCode.UNKNOWN_PARAM
    assert cam.config() == before


def test_get_config_lists_every_parameter_of_the_table(cam):
    assert set(cam.config()) == {p.name for p in PARAMS}
