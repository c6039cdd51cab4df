"""Integration tests of host + firmware over every transport (see conftest.py)."""
from __future__ import annotations

import time

import numpy as np
import pytest

import stereocam
from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.framing import encode_frame


def test_info(cam):
    info = cam.info()
    assert info.model and info.serial
    assert info.protocol_version[0] == 1 and info.protocol_version >= (1, 1)
    assert info.firmware_version.count(".") == 2
    assert info.max_payload >= 64 * 1024


def test_configure_roundtrip(cam):
    new = cam.configure(num_disparities=48, block_size=9, fps=12)
    assert (new["num_disparities"], new["block_size"], new["fps"]) == (48, 9, 12)
    assert cam.config() == new


@pytest.mark.parametrize("params, param", [
    ({"block_size": 8}, "block_size"),
    ({"num_disparities": 40}, "num_disparities"),
    ({"width": 100000}, "width"),
    ({"fps": 10, "exposure_us": 200_000}, "exposure_us"),  # longer than the frame period
    ({"block_size": 9, "pre_filter_cap": 0}, "pre_filter_cap"),  # one bad value rejects the whole set
])
def test_rejected_config_names_param_and_changes_nothing(cam, params, param):
    before = cam.config()
    with pytest.raises(stereocam.DeviceError) as exc:
        cam.configure(**params)
    assert exc.value.code == ErrorCode.OUT_OF_RANGE
    assert exc.value.param == param
    assert param in str(exc.value)
    assert cam.config() == before


def test_unknown_parameter_name_is_a_local_config_error(cam):
    with pytest.raises(stereocam.ConfigError, match="no_such_thing"):
        cam.configure(no_such_thing=3)
    with pytest.raises(ValueError):  # ConfigError is also a ValueError
        cam.configure(fps="fast")


def test_resolution_cannot_change_while_streaming(cam):
    cam.start()
    with pytest.raises(stereocam.DeviceError) as exc:
        cam.configure(width=640)
    assert exc.value.code == ErrorCode.BAD_STATE and exc.value.param == "width"
    cam.configure(num_disparities=16)  # matching parameters may change live
    cam.stop()


def test_software_trigger_frames(cam):
    cam.set_trigger_mode("software")
    cam.start()
    ids = [cam.trigger()]
    f1 = cam.get_frame(timeout=10)
    ids.append(cam.trigger())
    f2 = cam.get_frame(timeout=10)
    assert [f1.trigger_id, f2.trigger_id] == ids
    assert f2.sequence > f1.sequence and f2.device_time_us > f1.device_time_us
    for f in (f1, f2):
        assert f.left.shape == f.right.shape == f.disparity.shape == (240, 320)
        assert f.left.dtype == np.uint8 and f.disparity.dtype == np.int16
        assert f.disparity_format.subpixel == 16 and f.disparity_format.invalid == -16
        assert f.disparity_format.num_disparities == 32
        valid = f.disparity != f.disparity_format.invalid
        assert valid.mean() > 0.3
        assert f.disparity[valid].min() >= 0 and f.disparity[valid].max() < 32 * 16
        assert f.left.std() > 10 and not np.array_equal(f.left, f.right)
    with pytest.raises(stereocam.CameraTimeoutError):
        cam.get_frame(timeout=0.3)  # no trigger, no frame
    assert isinstance(stereocam.CameraTimeoutError("x"), TimeoutError)


def test_trigger_refused_in_free_run(cam):
    cam.start()
    with pytest.raises(stereocam.DeviceError) as exc:
        cam.trigger()
    assert exc.value.code == ErrorCode.BAD_STATE


def test_free_run_streaming_and_clock_mapping(cam):
    cam.configure(fps=10)
    cam.start()
    frames = [cam.get_frame(timeout=10) for _ in range(5)]
    cam.stop()
    seqs = [f.sequence for f in frames]
    assert seqs == sorted(seqs) and len(set(seqs)) == 5
    assert all(f.trigger_id == 0 for f in frames)
    gaps = np.diff([f.device_time_us for f in frames]) / np.diff(seqs)
    assert np.allclose(gaps, 100_000, rtol=0.02)  # 10 fps on the device clock
    now = time.monotonic()
    for f in frames:
        assert now - 5.0 < f.host_time < now  # mapped onto this host's monotonic clock


def test_garbage_between_commands_is_survived(cam):
    before = cam.status().counters
    cam.connection.link.transport.write(b"\x00\xffSTOC garbage STO" + bytes(range(256)) + b"STOC\x01\x00\x14")
    good = encode_frame(m.MsgType.GET_INFO, 1, b"")
    cam.connection.link.transport.write(good[:-1] + bytes([good[-1] ^ 0xFF]))  # bad payload CRC
    assert cam.info().serial
    assert cam.configure(fps=11)["fps"] == 11
    after = cam.status().counters
    assert after["rx_garbage_bytes"] > before["rx_garbage_bytes"]
    assert after["rx_payload_crc_errors"] == before["rx_payload_crc_errors"] + 1


def test_oversize_length_is_not_trusted(cam):
    import binascii
    import struct

    head = struct.pack("<4sBBBBHHIH", b"STOC", 1, 0, 20, 0, m.MsgType.GET_INFO, 9, 50 << 20, 0)
    cam.connection.link.transport.write(head + struct.pack("<H", binascii.crc_hqx(head, 0xFFFF)))
    assert cam.config()["width"] == 320  # answered at once: the 50 MiB length was not waited for
    assert cam.status().counters["rx_oversize"] >= 1


class _Unknown(m.Message):
    TYPE = 0x0077


def test_unknown_message_type_gets_a_nack(cam):
    with pytest.raises(stereocam.DeviceError) as exc:
        cam.request(_Unknown())
    assert exc.value.code == ErrorCode.UNKNOWN_TYPE
    assert cam.info().serial  # still talking


def test_heartbeat_status_counters(cam):
    st = cam.status()
    assert st.uptime_us > 0 and st.streaming is False
    assert st.counters["rx_packets"] > 0 and "frames_dropped" in st.counters
