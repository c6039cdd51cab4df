"""The overlapped capture pipeline: every exposure gets its sequence number, what the pipeline
cannot keep up with is dropped and counted, and replies never wait for it."""
from __future__ import annotations

import time

from stereocam.camera import Camera
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.links.inprocess import InProcessTransport
from tests.support.waiting import wait_until

SMALL = dict(width=320, height=240, num_disparities=32, block_size=11)


def slow_camera(sim: SimulatedCamera, per_message_s: float) -> Camera:
    """A camera whose link takes ``per_message_s`` per message: the delivery stage is the bottleneck."""
    transport = InProcessTransport(sim, owns=True)
    fifo_put = transport._fifo.put

    def slow_link(data: bytes) -> None:
        time.sleep(per_message_s)
        fifo_put(data)

    sim.attach(slow_link)
    return Camera(transport, timeout=2.0)


def capture_idle(sim: SimulatedCamera) -> bool:
    """No capture in flight: none being exposed, none being delivered (after a stop: the counters are final)."""
    return sim.engine.idle and sim.pipeline.idle


def test_a_slow_pipeline_drops_counts_and_numbers_every_exposure():
    sim = SimulatedCamera(seed=41)
    with slow_camera(sim, 0.01) as cam:  # 5 messages a capture: ~50 ms each, 60 fps asked
        cam.configure(**SMALL, fps=60)
        cam.start()
        cam.get_frame(timeout=30)
        seqs, replies = [], []
        t0 = time.monotonic()
        while time.monotonic() - t0 < 1.5:
            seqs.append(cam.get_frame(timeout=5).sequence)
            t = time.monotonic()
            cam.status()
            replies.append(time.monotonic() - t)
        cam.stop()
        wait_until(lambda: capture_idle(sim), what="the captures in flight finish (cut off)")
        c = cam.status().counters
    assert all(b > a for a, b in zip(seqs, seqs[1:]))
    assert c["frames_dropped"] > 0  # 60 fps asked of a ~20 fps link
    assert sim.engine.sequence == c["frames_captured"] + c["frames_dropped"]  # each number: made or dropped
    cut_off = c["frames_captured"] - c["frames_sent"]
    assert 0 <= cut_off <= 2  # at most one capture rendering and one being delivered at stop
    missing = seqs[-1] - seqs[0] + 1 - len(seqs)
    assert missing <= c["frames_dropped"] + cut_off  # every gap the host saw is a counted drop
    replies.sort()
    assert replies[len(replies) // 2] < 0.04 and replies[-1] < 0.2  # not behind a whole ~50 ms capture


def test_a_failing_delivery_counts_a_drop_and_the_stream_goes_on():
    sim = SimulatedCamera(seed=42)
    planes = sim.pipeline._stereo.planes
    calls = []

    def flaky(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("injected matcher fault")
        return planes(*args, **kwargs)

    sim.pipeline._stereo.planes = flaky
    with Camera(InProcessTransport(sim, owns=True)) as cam:
        cam.configure(**SMALL, fps=10)
        cam.start()
        seqs = [cam.get_frame(timeout=30).sequence for _ in range(4)]
        cam.stop()
        wait_until(lambda: capture_idle(sim), what="the captures in flight finish")
        c = cam.status().counters
    assert seqs[1] - seqs[0] >= 2  # the failed capture is a gap
    assert c["frames_dropped"] >= 1 and sim.engine.sequence == c["frames_captured"] + c["frames_dropped"] - 1
