"""One capture as messages and back: the device's segmentation and the host's assembly share
protocol/segmentation.py (SPEC §8.1–§8.2)."""
from __future__ import annotations

import numpy as np
import pytest

from stereocam.clock import ClockMap
from stereocam.frames import FrameAssembler, FrameStatus
from stereocam.protocol import messages as m
from stereocam.protocol.framing import Decoder
from stereocam.protocol.params import Output
from stereocam.protocol.segmentation import PLANE_ORDER, capture_messages, plane_size

W, H = 96, 40


def assembler(**kw) -> tuple[FrameAssembler, list]:
    """A host assembler that negotiated limits this test's format fits in (INFO max_width/max_height),
    and the list it delivers frames to."""
    delivered: list = []
    asm = FrameAssembler(ClockMap(), delivered.append, **kw)
    asm.set_limits(1280, 960)
    return asm, delivered


def begin(planes: Output, sequence: int = 5) -> m.FrameBegin:
    return m.FrameBegin(sequence, 0, 1000, 4000, 0, W, H, int(planes), m.FRAME_RECTIFIED, m.DISPARITY_S16_Q4, 16, 0,
                        32, -16, 0xABCD, 100.0, 48.0, 20.0, 0.1)


def images(seed: int = 0) -> dict[Output, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {Output.LEFT: rng.integers(0, 256, (H, W), np.uint8), Output.RIGHT: rng.integers(0, 256, (H, W), np.uint8),
            Output.DISPARITY: rng.integers(-16, 512, (H, W)).astype(np.int16),
            Output.CONFIDENCE: rng.integers(0, 256, (H, W), np.uint8)}


@pytest.mark.parametrize("chunk", [1000, plane_size(Output.LEFT, W, H), 7 * 1024, 1 << 17])
@pytest.mark.parametrize("planes", [Output.LEFT | Output.RIGHT | Output.DISPARITY, Output.RIGHT, Output.DISPARITY,
                                    Output(0), Output.LEFT | Output.RIGHT | Output.DISPARITY | Output.CONFIDENCE])
def test_segmented_capture_reassembles_byte_for_byte(chunk: int, planes: Output) -> None:
    imgs = images()
    msgs = list(capture_messages(begin(planes), imgs, chunk))
    assert isinstance(msgs[0], m.FrameBegin) and isinstance(msgs[-1], m.FrameEnd)
    data = [x for x in msgs[1:-1] if isinstance(x, m.FrameData)]
    assert len(data) == len(msgs) - 2 and all(len(d.data) <= chunk for d in data)
    assert [d.plane for d in data] == sorted((d.plane for d in data), key=lambda p: PLANE_ORDER.index(p))
    end = msgs[-1]
    assert (end.left_bytes, end.right_bytes, end.disparity_bytes, end.confidence_bytes) == tuple(
        plane_size(p, W, H) if p in planes else 0 for p in PLANE_ORDER)
    asm, delivered = assembler()
    for msg in Decoder().feed(b"".join(m.encode(x) for x in msgs)):  # through the real codec
        asm.on_message(m.decode_packet(msg))
    frame, = delivered
    assert frame.status is FrameStatus.COMPLETE and asm.stats.frames == 1
    for plane, got in ((Output.LEFT, frame.left), (Output.RIGHT, frame.right), (Output.DISPARITY, frame.disparity),
                       (Output.CONFIDENCE, frame.confidence)):
        if plane in planes:
            assert np.array_equal(got, imgs[plane])
        else:
            assert got is None


def test_a_plane_given_as_a_function_is_computed_when_its_turn_comes() -> None:
    """A device sends its images and matches meanwhile: the disparity function runs only after
    FRAME_BEGIN and every left and right chunk were taken, and the bytes are those it returned."""
    imgs = images(2)
    taken: list[str] = []

    def disparity() -> np.ndarray:
        taken.append("computed")
        return imgs[Output.DISPARITY]

    seen: dict[Output, bytes] = {}
    stream = capture_messages(begin(Output.LEFT | Output.RIGHT | Output.DISPARITY),
                              {**imgs, Output.DISPARITY: disparity}, 1000, lambda p, d: seen.__setitem__(p, bytes(d)))
    msgs = []
    for x in stream:
        msgs.append(x)
        taken.append(type(x).__name__ if not isinstance(x, m.FrameData) else Output(x.plane).name)
    first = taken.index("computed")
    assert set(taken[:first]) == {"FrameBegin", "LEFT", "RIGHT"} and taken.count("computed") == 1
    assert set(taken[first + 1:]) == {"DISPARITY", "FrameEnd"}
    assert seen[Output.DISPARITY] == imgs[Output.DISPARITY].tobytes() and list(seen) == list(PLANE_ORDER[:3])
    assert msgs == list(capture_messages(begin(Output.LEFT | Output.RIGHT | Output.DISPARITY), imgs, 1000))


def test_a_chunk_lost_on_the_way_is_missing_data() -> None:
    msgs = list(capture_messages(begin(Output.LEFT | Output.RIGHT), images(1), 1024))
    asm, delivered = assembler(deliver_incomplete=True)
    for x in msgs[:3] + msgs[4:]:
        asm.on_message(x)
    assert delivered[0].status is FrameStatus.MISSING_DATA and asm.stats.incomplete == 1


def test_images_that_do_not_fit_the_capture_are_refused() -> None:
    imgs = images()
    imgs[Output.RIGHT] = imgs[Output.RIGHT][:, :-16]
    with pytest.raises(ValueError, match="RIGHT"):
        list(capture_messages(begin(Output.LEFT | Output.RIGHT), imgs))
    with pytest.raises(ValueError, match="DISPARITY"):
        list(capture_messages(begin(Output.DISPARITY), {Output.LEFT: imgs[Output.LEFT]}))
    with pytest.raises(ValueError, match="chunk"):
        list(capture_messages(begin(Output.LEFT), imgs, 0))


def test_plane_sizes() -> None:
    assert plane_size(Output.LEFT, 640, 480) == plane_size(Output.RIGHT, 640, 480) == 640 * 480
    assert plane_size(Output.DISPARITY, 640, 480) == 2 * 640 * 480
