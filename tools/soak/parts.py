"""The three runs of ``stereocam soak``: decoder fuzz, device fuzz, streaming through a faulty link."""
from __future__ import annotations

import random
import resource
import sys
import time
import zlib
from dataclasses import dataclass, field

from stereocam.protocol import messages as m
from stereocam.protocol.errors import CameraTimeoutError, StereoCamError
from stereocam.protocol.framing import HEADER_LEN, MAX_HEADER_LEN, TRAILER_LEN, Decoder, encode_frame

from stereocam.tools.bench.decoder import valid_header
from .fault_link import FaultyTransport, LineNoise


def reset_peak_memory() -> None:
    """Start a new peak-memory measurement: on Linux the process's peak resident size (VmHWM) is
    reset, so a stage's figure is its own and not that of whatever ran before it in this process."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:  # not Linux: peak_memory_mib() is then the process's peak so far
        pass


def peak_memory_mib() -> float:
    """Peak resident memory since reset_peak_memory() (Linux VmHWM), else the process's peak so far."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 1024


def resident_mib() -> float:
    """Resident memory now (Linux VmRSS), else the process's peak so far."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return peak_memory_mib()

SAMPLES: list[m.Message] = [
    m.GetInfo(), m.SetConfig({1: 640, 2: 480, 14: 5}), m.Trigger(), m.Heartbeat(), m.TimeSync(), m.GetConfig(),
    m.Nack(3, 4, 3, "fps=0 outside 1..120"), m.FrameData(7, 1, 1024, bytes(range(60))), m.FrameEnd(7, 0, 1, 2, 3),
    m.CalibRead(m.CalibSource.ACTIVE, 0, 248), m.CalibWrite(0, 248, bytes(40)), m.CalibCommit(2, 248, 1234),
    m.SetFrameLink(1024), m.FrameResend(7, ((1, 0, 4096), (4, 100, 50))), m.Stop(),
]


@dataclass
class Report:
    name: str
    inputs: int = 0
    crashes: int = 0
    hangs: int = 0
    figures: dict[str, object] = field(default_factory=dict)


def mutate(rng: random.Random, data: bytes) -> bytes:
    """One to four mutations: bit flips, inserted magics or CRC-valid headers, deletions, duplications."""
    b = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        if not b:
            b += rng.randbytes(8)
        pos = rng.randrange(len(b))
        op = rng.randrange(6)
        if op == 0:
            b[pos] ^= 1 << rng.randrange(8)
        elif op == 1:
            b[pos:pos] = b"STOC"
        elif op == 2:
            b[pos:pos] = valid_header(rng.choice([0, 4, 255, 256, 1 << 20, rng.randrange(1 << 32)]))
        elif op == 3:
            del b[pos:pos + rng.randint(1, 16)]
        elif op == 4:
            b[pos:pos] = b[rng.randrange(len(b)):][:rng.randint(1, 40)]
        else:
            b[pos] = rng.randrange(256)
    return bytes(b)


def fuzz_decoder(inputs: int, seed: int = 0, hang_s: float = 1.0) -> Report:
    """Mutated streams of valid frames into fresh decoders (max_payload 256), fed in random pieces;
    checks the SPEC §3 invariants (every byte accounted for, bounded buffer) on each."""
    rng = random.Random(seed)
    frames = [m.encode(msg, i + 1) for i, msg in enumerate(SAMPLES)]
    rep = Report("decoder fuzz")
    violations = 0
    for _ in range(inputs):
        stream = mutate(rng, b"".join(rng.sample(frames, rng.randint(1, 4))))
        t0 = time.perf_counter()
        try:
            dec = Decoder(max_payload=256, message_timeout=1.0)
            out = []
            pos, now = 0, 0.0
            while pos < len(stream):
                n = rng.randint(1, 64)
                out += dec.feed(stream[pos:pos + n], now=now)
                pos, now = pos + n, now + rng.choice([0.0, 0.0, 0.4])
                if dec.buffered > MAX_HEADER_LEN + 256 + TRAILER_LEN + 64:
                    violations += 1
            s = dec.stats
            delivered = sum(HEADER_LEN + len(p.payload) + TRAILER_LEN for p in out)
            if s.bytes_in != delivered + s.garbage_bytes + s.dropped + dec.buffered:
                violations += 1
            for p in out:
                try:
                    m.decode_packet(p)
                except StereoCamError:
                    pass
        except Exception:  # noqa: BLE001 - counted, that is the point
            rep.crashes += 1
        rep.hangs += time.perf_counter() - t0 > hang_s
        rep.inputs += 1
    rep.figures["invariant violations"] = violations
    return rep


def fuzz_device(url: str, inputs: int, seed: int = 0, reply_timeout: float = 3.0) -> Report:
    """CRC-valid requests with mutated payloads (and types) to the device at ``url``: every one
    must be answered (reply or NACK) within ``reply_timeout``; a dead link is a crash."""
    from stereocam.transports import open_transport

    rng = random.Random(seed)
    rep = Report("device fuzz")
    answered = nacks = 0
    transport = open_transport(url, 1.0)
    dec = Decoder()
    try:
        for i in range(inputs):
            msg = rng.choice([s for s in SAMPLES if s.TYPE < m.EVENT_BIT])
            mtype = msg.TYPE if rng.random() < 0.9 else rng.randrange(1, m.EVENT_BIT)
            rid = i % 0xFFFF + 1
            try:
                transport.write(encode_frame(mtype, rid, mutate(rng, msg.pack())[:4096]))
                deadline = time.monotonic() + reply_timeout
                got = None
                while got is None and time.monotonic() < deadline:
                    for p in dec.feed(transport.read(1 << 20, 0.05)):
                        if p.request_id == rid and p.msg_type & m.REPLY_BIT:
                            got = p
            except StereoCamError:
                rep.crashes += 1
                break
            rep.inputs += 1
            if got is None:
                rep.hangs += 1
            else:
                answered += 1
                nacks += got.msg_type == m.MsgType.NACK
        transport.write(encode_frame(m.MsgType.STOP, 0xFFFF, b""))
        deadline = time.monotonic() + reply_timeout  # leave nothing in flight for the next session
        while time.monotonic() < deadline and not any(
                p.request_id == 0xFFFF and p.msg_type & m.REPLY_BIT for p in dec.feed(transport.read(1 << 20, 0.05))):
            pass
    finally:
        transport.close()
    rep.figures.update(answered=answered, nacks=nacks)
    return rep


class PlaneTruth:
    """What an in-process simulator sent: plane CRCs by sequence (corruption check)."""

    def __init__(self, sim):
        self.sent: dict[int, dict[int, int]] = {}
        real = sim.repair.remember

        def remember(sequence, planes):
            self.sent[sequence] = {p: zlib.crc32(v) for p, v in planes.items()}
            real(sequence, planes)
        sim.repair.remember = remember

    def intact(self, frame) -> bool:
        got = {1: frame.left, 2: frame.right, 4: frame.disparity}
        return all(zlib.crc32(got[p].tobytes()) == c for p, c in self.sent.get(frame.sequence, {}).items())


def stream_with_faults(url: str, seconds: float, flip: float, drop: float = 0.0, latency: float = 0.0,
                       split: int = 0, chunk: int | None = 1024, size: tuple[int, int] = (640, 480),
                       fps: int = 4, seed: int = 0) -> Report:
    """Stream through a faulty link; count frames sent (device), delivered, corrupted, dropped, and
    check that the device's and the host's counters add up."""
    from stereocam.camera import Camera
    from stereocam.transports import open_transport

    inner = open_transport(url, 2.0)
    link = FaultyTransport(inner)
    if chunk is not None:
        link.frame_chunk = chunk
    sim = getattr(inner, "sim", None)
    truth = PlaneTruth(sim) if sim is not None else None
    rep = Report(f"stream, flip {flip:g}/byte")
    cam = Camera(link, timeout=1.0, retries=3)
    delivered = corrupted = 0
    try:
        cam.configure(width=size[0], height=size[1], fps=fps, num_disparities=64, block_size=15)
        before = cam.status().counters
        link.max_write = split or None
        link.set_manipulator(read=LineNoise(flip, drop, latency, seed), write=LineNoise(flip, drop, latency, seed + 1))
        cam.start()
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            t0 = time.monotonic()
            try:
                frame = cam.get_frame(timeout=2.0)
            except CameraTimeoutError:
                continue
            except StereoCamError:
                rep.crashes += 1
                break
            finally:
                rep.hangs += time.monotonic() - t0 > 5.0
            delivered += 1
            corrupted += truth is not None and not truth.intact(frame)
        link.set_manipulator(read=lambda b: b, write=lambda b: b)
        link.max_write = None
        cam.stop()
        time.sleep(3.5)  # repairs in flight settle (REPAIR_WINDOW)
        while (late := cam.try_get_frame()) is not None:
            delivered += 1
            corrupted += truth is not None and not truth.intact(late)
        after = cam.status().counters
    finally:
        cam.close()
    st = cam.stats
    sent = after["frames_sent"] - before["frames_sent"]
    device_dropped = after["frames_dropped"] - before["frames_dropped"]  # exposures the busy pipeline missed
    host_dropped = st["incomplete"] + st["size_mismatch"] + st["device_errors"] + st["bad_leaders"] + st["lost"]
    device_side, host_side = sent + device_dropped, st["frames"] + host_dropped
    rep.inputs = sent
    rep.figures.update({
        "frames sent": sent, "delivered": delivered, "corrupted": corrupted if truth else "n/a (not a sim:// URL)",
        "dropped": f"{max(host_dropped - device_dropped, 0)} on the link, {device_dropped} exposures missed on the device",
        "repaired": st["repaired"], "delivery": f"{delivered / max(sent, 1):.1%} of frames sent",
        "counters add up": f"{'yes' if abs(device_side - host_side) <= 2 else 'NO'} (device sent+dropped "
                           f"{device_side}, host delivered+dropped+lost {host_side})"})
    return rep
