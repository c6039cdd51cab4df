"""A clumsy caller gets a typed error naming what was wrong, never a hang or a raw exception (issue 9, 7 and 10)."""
from __future__ import annotations

import math
from decimal import Decimal
from fractions import Fraction

import numpy as np
import pytest

import stereocam
from tests.support.hangs import returns_within


@pytest.fixture(scope="module")
def cam():
    camera = stereocam.open("sim://?seed=5", timeout=1.0)
    yield camera
    camera.close()


@pytest.mark.parametrize("bad", [math.nan, math.inf, -1, -0.5, "x", None.__class__, True])
def test_get_frame_timeout_must_be_a_finite_non_negative_number(cam, bad):
    with pytest.raises(stereocam.ConfigError, match="timeout") as err:
        returns_within(5, cam.get_frame, timeout=bad)
    assert isinstance(err.value, ValueError)


def test_get_frame_zero_timeout_polls(cam):
    with pytest.raises(stereocam.CameraTimeoutError):
        returns_within(5, cam.get_frame, timeout=0)


@pytest.mark.parametrize("call", ["open", "request", "reconnect"])
def test_other_timeouts_are_checked_too(cam, call):
    from stereocam.protocol import messages as m

    fns = {"open": lambda: stereocam.open("sim://?seed=5", timeout=math.nan),
           "request": lambda: cam.request(m.GetInfo(), timeout=-1),
           "reconnect": lambda: cam.reconnect(timeout=math.inf)}
    with pytest.raises(stereocam.ConfigError, match="timeout"):
        returns_within(5, fns[call])
    assert cam.alive


@pytest.mark.parametrize("value", [2**31, -2**31 - 1, 10**20])
def test_configure_value_beyond_the_wire_names_the_parameter(cam, value):
    with pytest.raises(stereocam.ConfigError, match="width"):
        cam.configure(width=value)


def test_configure_accepts_numpy_integers(cam):
    assert cam.configure(width=np.int64(320), height=np.uint16(240))["width"] == 320


def test_configure_takes_whole_fractions_and_decimals_alike(cam):
    """Fraction(30) was taken and Decimal('30') refused (Decimal is not a numbers.Real)."""
    assert cam.configure(fps=Fraction(30), exposure_us=Decimal("5000"))["fps"] == 30
    assert cam.config()["exposure_us"] == 5000


@pytest.mark.parametrize("value", [np.float64(1.5), "640", None, True, 640.5, Fraction(1, 2), Decimal("640.5"),
                                   Decimal("NaN"), Decimal("sNaN"), Decimal("Infinity")])
def test_configure_refuses_non_integers_naming_the_parameter(cam, value):
    with pytest.raises(stereocam.ConfigError, match="width"):
        cam.configure(width=value)


@pytest.mark.parametrize("url,problem", [
    ("sim://?seed=-1", "seed"), ("sim://?seed=12345678901234567890", "seed"), ("sim://?seed=", "seed"),
    ("sim://?seed=1&seed=2", "seed"), ("sim://?seed=x", "seed"),
    ("socket://127.0.0.1", "port"), ("socket://127.0.0.1:99999", "port"), ("socket://127.0.0.1:x", "port"),
    ("socket://:80x", "port"), ("rfc2217://host", "port"),
])
def test_malformed_urls_get_a_typed_error_naming_the_problem(url, problem):
    with pytest.raises(stereocam.ConfigError, match=problem):
        returns_within(30, stereocam.open, url, timeout=0.5)


def test_a_url_pyserial_chokes_on_stays_in_the_error_tree():
    with pytest.raises(stereocam.StereoCamError, match="loop://"):
        stereocam.open("loop://?logging=nonsense", timeout=0.5)


@pytest.mark.parametrize("source", ["bogus", None, 3])
def test_read_calibration_source_is_checked(cam, source):
    with pytest.raises(stereocam.ConfigError, match="source"):
        cam.read_calibration(source)


@pytest.mark.parametrize("calibration", [None, "cal", b"\x00" * 248])
def test_write_calibration_needs_a_calibration(cam, calibration):
    with pytest.raises(stereocam.ConfigError, match="StereoCalibration"):
        cam.write_calibration(calibration)


def test_write_calibration_target_is_checked(cam):
    with pytest.raises(stereocam.ConfigError, match="target"):
        cam.write_calibration(cam.read_calibration().calibration, target="bogus")


@pytest.mark.parametrize("option, value", [
    ("heartbeat_interval", 0), ("heartbeat_interval", -1), ("queue_depth", 0), ("queue_depth", "x"),
    ("queue_depth", 1.5), ("retries", -1), ("retries", "x"), ("deliver_incomplete", "yes"),
    ("auto_reconnect", "no"), ("bogus", 1),
])
def test_open_options_are_checked_before_anything_runs(option, value):
    with pytest.raises(stereocam.ConfigError, match=option):
        stereocam.open("sim://?seed=5", **{option: value})


def test_a_wait_longer_than_the_os_allows_is_cut_not_an_overflow():
    with stereocam.open("sim://?seed=6", timeout=1e10) as camera:
        assert camera.timeout == pytest.approx(1e9) and camera.info().serial == "SIM00006"


def test_a_closed_camera_stays_closed(tmp_path):
    camera = stereocam.open("sim://?seed=7")
    camera.close()
    with pytest.raises(stereocam.TransportError, match="closed"):
        camera.reconnect(timeout=1)
    with pytest.raises(stereocam.TransportError, match="closed"):
        camera.on_frame(print)
    with stereocam.open("sim://?seed=7") as again:  # the unit itself was let go
        assert again.info().serial == "SIM00007"


@pytest.mark.parametrize("call, args", [
    ("on_frame", (None,)), ("on_frame", (5,)), ("set_trigger_mode", (None,)), ("set_trigger_mode", (True,)),
    ("set_trigger_mode", (1.0,)), ("update_firmware", (None,)), ("update_firmware", ("x" * 200,)),
    ("sync_clock", (0,)), ("sync_clock", ("x",)),
])
def test_wrong_kinds_of_argument_are_config_errors_and_change_nothing(cam, call, args):
    before = cam.config()
    with pytest.raises(stereocam.ConfigError):
        getattr(cam, call)(*args)
    assert cam.config() == before


@pytest.mark.parametrize("limits", [dict(frames=0), dict(frames=-1), dict(frames="x"), dict(seconds=math.nan),
                                    dict(seconds=-1), dict(seconds=0), dict(frames=1, bogus=1)])
def test_record_limits_are_checked_before_a_file_is_made(cam, tmp_path, limits):
    with pytest.raises(stereocam.ConfigError):
        cam.record(tmp_path / "r.mcap", **limits)
    with pytest.raises(stereocam.ConfigError, match="path"):
        cam.record(None, frames=1)
    assert list(tmp_path.iterdir()) == []


def test_save_preset_where_it_cannot_be_written_is_a_config_error(cam, tmp_path):
    for where in (tmp_path, tmp_path / "missing" / "p.json"):
        with pytest.raises(stereocam.ConfigError, match="cannot write preset"):
            cam.save_preset(where)


@pytest.mark.parametrize("points, grey, named", [
    (np.zeros((5, 2)), None, "points"), ("abc", None, "points"), (None, None, "points"),
    (np.zeros((5, 3)), np.zeros(4), "grey"), (np.zeros((2, 3)), [300.0, -1.0], "grey"),
])
def test_write_ply_names_the_bad_argument(tmp_path, points, grey, named):
    with pytest.raises(stereocam.ConfigError, match=named):
        stereocam.write_ply(tmp_path / "x.ply", points, grey)
    assert not (tmp_path / "x.ply").exists()


def test_write_ply_to_a_place_that_cannot_be_written(tmp_path):
    for where in (tmp_path, tmp_path / "missing" / "x.ply", None):
        with pytest.raises(stereocam.ConfigError):
            stereocam.write_ply(where, np.zeros((2, 3)))
    assert stereocam.write_ply(tmp_path / "ok.ply", np.zeros((2, 3)), [0, 255]) == 2


def test_depth_of_a_frame_without_disparity_is_a_typed_error():
    with stereocam.open("sim://?seed=8") as camera:
        camera.configure(width=160, height=120, outputs=int(stereocam.Output.LEFT))
        camera.start()
        frame = camera.get_frame(timeout=20)
    for method in (frame.depth, frame.points, frame.disparity_px, frame.disparity_plane):
        with pytest.raises(stereocam.MissingPlaneError, match="no disparity"):
            method()
    assert issubclass(stereocam.MissingPlaneError, ValueError)


@pytest.mark.parametrize("url", [None, 5, b"sim://", ""])
def test_a_url_that_is_not_a_non_empty_string_is_a_config_error(url):
    with pytest.raises(stereocam.ConfigError, match="non-empty string"):
        stereocam.open(url)


@pytest.mark.parametrize("url", ["sim://\x00", "sim://?seed=3\n", "sim://\x7f"])
def test_a_url_with_a_control_character_is_refused_naming_it(url):
    with pytest.raises(stereocam.ConfigError, match="control character") as err:
        returns_within(5, stereocam.open, url)
    assert repr(url) in str(err.value)


@pytest.mark.parametrize("option, value", [("timeout", 0), ("timeout", 0.0), ("retries", 10**20), ("retries", 101)])
def test_open_refuses_a_zero_request_timeout_and_absurd_retries(option, value):
    with pytest.raises(stereocam.ConfigError, match=option):
        returns_within(5, stereocam.open, "sim://?seed=5", **{option: value})


def test_a_camera_on_a_transport_checks_its_request_timeout_and_closes_the_transport():
    from stereocam.camera import Camera
    from stereocam.device_sim import SimulatedCamera
    from stereocam.device_sim.links.inprocess import InProcessTransport

    for kw in (dict(timeout=0), dict(retries=1000)):
        transport = InProcessTransport(SimulatedCamera(seed=8))
        with pytest.raises(stereocam.ConfigError, match=next(iter(kw))):
            Camera(transport, **kw)
        with pytest.raises(stereocam.DisconnectedError, match="is closed"):  # not left open
            transport.write(b"x")
    with stereocam.open("sim://?seed=8", retries=100, timeout=0.5) as camera:  # the limits themselves are fine
        assert camera.info().serial == "SIM00008"
