"""The confidence plane recorded as a ROS 2 mono8 image on /stereo/confidence: read back by our reader
and by an independent one (rosbags); a recording without that plane has no such channel."""
from __future__ import annotations

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

import stereocam
from stereocam.protocol.params import Output
from stereocam.recording import schemas
from stereocam.recording.reader import Recording
from tests.support.device import SMALL

N = 3


def test_the_confidence_plane_is_recorded_as_a_mono8_image(tmp_path) -> None:
    path = tmp_path / "conf.mcap"
    with stereocam.open("sim://?seed=4", timeout=3.0) as cam:
        outputs = Output.LEFT | Output.DISPARITY | Output.CONFIDENCE
        cam.configure(**SMALL, algorithm=1, hole_fill=2, outputs=int(outputs))
        cam.record(path, frames=N)
    with Recording(path) as rec:
        assert rec.topics[schemas.CONFIDENCE_TOPIC] == N and rec.topics[schemas.RIGHT] == 0
        caps = list(rec.captures())
        assert all(c.confidence is not None and c.confidence.shape == c.disparity.shape for c in caps)
        frame = caps[0].to_frame()
        assert frame.confidence is not None and (frame.confidence == 16).any() and (frame.confidence == 255).any()
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        conns = [c for c in reader.connections if c.topic == schemas.CONFIDENCE_TOPIC]
        msgs = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections=conns)]
    assert len(msgs) == N and msgs[0].encoding == "mono8"
    assert np.array_equal(np.asarray(msgs[0].data).reshape(msgs[0].height, msgs[0].width), caps[0].confidence)


def test_a_recording_without_the_plane_has_no_confidence_channel(tmp_path) -> None:
    path = tmp_path / "plain.mcap"
    with stereocam.open("sim://?seed=4", timeout=3.0) as cam:
        cam.configure(**SMALL)
        cam.record(path, frames=1)
    with Recording(path) as rec:
        assert schemas.CONFIDENCE_TOPIC not in rec.topics and next(rec.captures()).confidence is None
