"""The ROS 2 message definitions a recording uses, and the topics it writes them on.

Standard types (sensor_msgs, stereo_msgs) so ROS 2 tools and Foxglove open a recording as it is,
plus ``stereocam_msgs/msg/CaptureInfo`` for what only this camera knows about each capture.
Definitions are stored in the file the way rosbag2 stores them: the type's own text, then each
dependency after a line of 80 ``=`` and ``MSG: pkg/Name``.

Disparity goes out as ``stereo_msgs/msg/DisparityImage``: a 32FC1 image in pixels with
``delta_d = 1/16``. The camera's int16 Q4 values are exactly representable as float32, so
``round(value * 16)`` gives back the camera's plane bit for bit; the camera's "invalid" code
(``(min_disparity - 1) * 16``) becomes ``min_disparity - 1``, below ``min_disparity`` as ROS
expects of an invalid disparity.
"""
from __future__ import annotations

from mcap_ros2._dynamic import EncoderFunction, serialize_dynamic

SEPARATOR = "=" * 80

_TIME = "int32 sec\nuint32 nanosec\n"
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
_ROI = "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"
_IMAGE = ("std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n"
          "uint32 step\nuint8[] data\n")
_CAMERA_INFO = ("std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\n"
                "float64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\n"
                "sensor_msgs/RegionOfInterest roi\n")
_DISPARITY = ("std_msgs/Header header\nsensor_msgs/Image image\nfloat32 f\nfloat32 t\n"
              "sensor_msgs/RegionOfInterest valid_window\nfloat32 min_disparity\nfloat32 max_disparity\n"
              "float32 delta_d\n")
_CAPTURE_INFO = """\
# One capture of a stereocam unit: what the camera and the host knew about it.
std_msgs/Header header
uint32 sequence
uint32 trigger_id
uint64 device_time_us
float64 host_time            # device time mapped to the host's monotonic clock, seconds
string status                # complete, missing data, size mismatch, device error
uint32 exposure_us
int32 gain
uint16 width
uint16 height
uint8 planes                 # 1 left, 2 right, 4 disparity, 8 confidence
bool rectified
int32 subpixel
int32 min_disparity
int32 num_disparities
int32 invalid_disparity
uint32 calibration_id
float64 focal_px
float64 cx
float64 cy
float64 baseline_m
uint64 link_lost             # sequence numbers never seen (device or link), so far
uint64 link_incomplete       # captures cut short on the link, so far
uint64 host_queue_overflow   # captures the SDK discarded because its reader fell behind, so far
uint64 device_dropped        # exposures the device skipped (its last status report), so far
uint64 recorder_dropped      # captures this recorder could not write (queue full), so far
"""

CAPTURE_INFO_FIELDS = tuple(line.split()[1] for line in _CAPTURE_INFO.splitlines()
                            if line.strip() and not line.startswith("#"))  # what a reader may rely on
_DEPS = {"std_msgs/Header": _HEADER, "builtin_interfaces/Time": _TIME,
         "sensor_msgs/RegionOfInterest": _ROI, "sensor_msgs/Image": _IMAGE}
_USES = {"sensor_msgs/msg/Image": ["std_msgs/Header", "builtin_interfaces/Time"],
         "sensor_msgs/msg/CameraInfo": ["std_msgs/Header", "builtin_interfaces/Time", "sensor_msgs/RegionOfInterest"],
         "stereo_msgs/msg/DisparityImage": ["std_msgs/Header", "builtin_interfaces/Time", "sensor_msgs/Image",
                                            "sensor_msgs/RegionOfInterest"],
         "stereocam_msgs/msg/CaptureInfo": ["std_msgs/Header", "builtin_interfaces/Time"]}
_OWN = {"sensor_msgs/msg/Image": _IMAGE, "sensor_msgs/msg/CameraInfo": _CAMERA_INFO,
        "stereo_msgs/msg/DisparityImage": _DISPARITY, "stereocam_msgs/msg/CaptureInfo": _CAPTURE_INFO}

IMAGE, CAMERA_INFO, DISPARITY, CAPTURE_INFO = _OWN  # the four schema names


def msgdef(type_name: str) -> str:
    """The full ros2msg text of ``type_name`` with its dependencies, as rosbag2 writes it."""
    parts = [_OWN[type_name]]
    parts += [f"{SEPARATOR}\nMSG: {dep}\n{_DEPS[dep]}" for dep in _USES[type_name]]
    return "".join(p if p.endswith("\n") else p + "\n" for p in parts)


def encoder(type_name: str) -> EncoderFunction:
    """A CDR encoder for ``type_name`` (mcap-ros2-support's dynamic serializer)."""
    return serialize_dynamic(type_name, msgdef(type_name))[type_name]


# topic -> schema name; one capture writes one message on each topic its planes allow
TOPICS: dict[str, str] = {
    "/stereo/left/image_rect": IMAGE,
    "/stereo/right/image_rect": IMAGE,
    "/stereo/left/camera_info": CAMERA_INFO,
    "/stereo/right/camera_info": CAMERA_INFO,
    "/stereo/disparity": DISPARITY,
    "/stereocam/capture": CAPTURE_INFO,
}
LEFT, RIGHT, LEFT_INFO, RIGHT_INFO, DISPARITY_TOPIC, CAPTURE = TOPICS
CONFIDENCE_TOPIC = "/stereo/confidence"
"""The confidence plane (outputs bit 8, SPEC §5.3) as a mono8 IMAGE; its channel is added with the first
capture that carries one, so a recording without that plane has exactly the TOPICS."""
FRAME_IDS = {"left": "stereocam_left", "right": "stereocam_right"}


def encode_with_blob(encode: EncoderFunction, body: dict, slot: dict, blob: memoryview) -> list:
    """CDR of ``body`` whose ``slot["data"]`` (a uint8[]) is the large ``blob``, as buffers, without
    copying the blob: the library's encoder writes the message with an empty array and the blob is
    spliced in where the array's length went. Checked against a 4-byte array so the splice is only
    taken where it is exact (the array last, or followed by fields aligned to at most 4 bytes and a
    blob whose length is a multiple of 4); otherwise the message is encoded whole."""
    slot["data"] = b""
    empty = encode(body)
    slot["data"] = b"\0\0\0\0"
    four = encode(body)
    pos = next((i for i, (a, b) in enumerate(zip(empty, four)) if a != b), None)
    tail = empty[pos + 4:] if pos is not None else b""
    if pos is None or four[pos + 4:pos + 8] != b"\0\0\0\0" or four[pos + 8:] != tail or (tail and len(blob) % 4):
        slot["data"] = bytes(blob)
        return [encode(body)]
    return [empty[:pos], len(blob).to_bytes(4, "little"), blob, tail]
