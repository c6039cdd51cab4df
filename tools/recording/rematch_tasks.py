"""The work of ``stereocam rematch``, as functions a Dask worker runs (plain arguments, files in
and out, nothing shared): plan a recording into frame ranges that follow its chunks, re-match one
range into a part file, join the parts into the output recording. Every output is written under a
temporary name and renamed into place, so a task killed half way leaves nothing that looks done,
and a retried task (or a re-run) writes the same file again."""
from __future__ import annotations

import os
import time
import uuid
from dataclasses import replace
from pathlib import Path

import numpy as np
from mcap.reader import make_reader
from mcap.records import Chunk, MessageIndex
from mcap.stream_reader import StreamReader

from stereocam.protocol.frame_messages import DISPARITY_SUBPIXEL, invalid_disparity
from stereocam.protocol.params import defaults
from stereocam.frames import DisparityFormat
from stereocam.recording import LinkCounters, Recorder
from stereocam.recording.mcapwriter import ChunkedWriter
from stereocam.recording.reader import Recording
from stereocam.stereo.engines import StereoMatcher, matcher_for, params_from_config
from stereocam.stereo.post import PostChain, post_params_from_config, postprocess
from stereocam.recording.recorder import FRAME_INDEX, FRAME_INDEX_TYPE, SUMMARY

def matching_config(recorded: dict[str, int], overrides: dict[str, int]) -> dict[str, int]:
    """The configuration to match under: the recorded one changed by ``overrides``; parameters the
    recording predates (a 1.1 unit has no SGM settings) take the protocol's defaults."""
    return defaults() | recorded | overrides


def plan(path: str, chunks_per_task: int) -> list[tuple[int, int]]:
    """Frame ranges [start, stop) of ``path``, each beginning where a chunk begins."""
    with Recording(path) as rec:
        starts = rec.chunk_frame_starts()[::max(1, chunks_per_task)] or [0]
        starts[0] = 0
        return list(zip(starts, starts[1:] + [len(rec)]))


def _atomic(out: Path) -> Path:
    return out.with_name(f".{out.name}.{uuid.uuid4().hex[:8]}.tmp")


def rematch_range(path: str, start: int, stop: int, overrides: dict[str, int], part: str) -> tuple[int, float]:
    """Frames ``start``..``stop - 1`` of ``path`` with their disparity matched again under the
    recorded configuration changed by ``overrides``, written to ``part``; (frames, seconds)."""
    t0 = time.perf_counter()
    out = Path(part)
    tmp = _atomic(out)
    with Recording(path) as rec:
        cfg = matching_config(rec.config, overrides)
        params_from_config(cfg)  # a configuration no engine takes fails before any file is written
        fmt = DisparityFormat(DISPARITY_SUBPIXEL, cfg["min_disparity"], cfg["num_disparities"],
                              invalid_disparity(cfg["min_disparity"]))
        matcher: StereoMatcher | None = None
        post = post_params_from_config(cfg)
        chain = PostChain(post, cfg["min_disparity"]) if post.active else None  # temporal state: this range's
        unit = replace(rec.unit, config=cfg)
        try:
            with Recorder(tmp, unit, clock_offset_ns=rec.clock_offset_ns) as writer:
                for cap in rec.captures(start, stop):
                    frame = cap.to_frame()
                    if frame.rectified and frame.left is not None and frame.right is not None:
                        matcher = matcher_for(cfg, frame.left.shape, matcher)
                        disp = matcher.match(frame.left, frame.right)
                        if chain is not None:
                            disp = postprocess(disp, frame.left, post, frame.right, matcher.params, chain)
                        frame.disparity, frame.disparity_format = disp, fmt
                    i = cap.info
                    writer.put_wait(frame, LinkCounters(i.link_lost, i.link_incomplete, i.host_queue_overflow,
                                                        i.device_dropped, i.recorder_dropped))
            os.replace(tmp, out)
        finally:
            tmp.unlink(missing_ok=True)
    return stop - start, time.perf_counter() - t0


def _copy_chunks(records, writer: ChunkedWriter) -> None:
    """Every chunk of a file with its message indexes, compressed bytes copied as they are."""
    chunk, indexes = None, []
    for record in records:
        if isinstance(record, MessageIndex) and chunk is not None:
            indexes.append(record)
            continue
        if chunk is not None:
            writer.copy_chunk(chunk, indexes)
            chunk, indexes = None, []
        if isinstance(record, Chunk):
            chunk = record
    if chunk is not None:
        writer.copy_chunk(chunk, indexes)


def join(source: str, parts: list[str], out: str, provenance: dict[str, str], replace: bool = False) -> int:
    """The parts, in order, as one recording ``out`` (their chunks copied as they are, not
    decompressed); its frame count. An existing ``out`` is FileExistsError unless ``replace``."""
    target = Path(out)
    tmp = _atomic(target)
    writer: ChunkedWriter | None = None
    times: list[np.ndarray] = []
    summary: dict[str, str] = {}
    try:
        for part in parts:
            with open(part, "rb") as f:
                reader = make_reader(f)
                s = reader.get_summary()
                if s is None:
                    raise ValueError(f"{part} has no MCAP summary (a part cut short)")
                if writer is None:
                    writer = ChunkedWriter(tmp, profile=reader.get_header().profile, library=reader.get_header().library,
                                           exclusive=True)
                    ids = {sid: writer.register_schema(x.name, x.encoding, x.data) for sid, x in s.schemas.items()}
                    chans = {cid: writer.register_channel(c.topic, c.message_encoding, ids[c.schema_id], c.metadata)
                             for cid, c in s.channels.items()}
                    for meta in reader.iter_metadata():
                        if meta.name != SUMMARY:
                            writer.add_metadata(meta.name, dict(meta.metadata))
                    writer.add_metadata("stereocam.rematch", {**provenance, "source": source})
                if any(chans.get(cid) != cid or writer.channels[cid].topic != c.topic for cid, c in s.channels.items()):
                    raise ValueError(f"{part} numbers its channels unlike the first part")
                f.seek(0)
                _copy_chunks(StreamReader(f, emit_chunks=True).records, writer)
                times += [np.frombuffer(a.data, "<i8") for a in reader.iter_attachments() if a.name == FRAME_INDEX]
                last = next((dict(m.metadata) for m in reader.iter_metadata() if m.name == SUMMARY), {})
                camera_bytes = int(summary.get("camera_bytes", 0)) + int(last.get("camera_bytes", 0))
                summary = {**last, "camera_bytes": str(camera_bytes)}
        assert writer is not None, "no parts to join"
        writer.flush()
        index = np.concatenate(times) if times else np.zeros(0, "<i8")
        writer.add_metadata(SUMMARY, {**summary, "frames": str(len(index))})
        writer.add_attachment(FRAME_INDEX, FRAME_INDEX_TYPE, index.astype("<i8").tobytes())
        writer.finish()
        if replace:
            os.replace(tmp, target)
        else:
            os.link(tmp, target)  # never over a file that appeared meanwhile
    finally:
        tmp.unlink(missing_ok=True)
    for joined in map(Path, parts):
        joined.unlink(missing_ok=True)
        for leftover in joined.parent.glob(f".{joined.name}.*.tmp"):  # of attempts whose worker was killed
            leftover.unlink(missing_ok=True)
    return len(index)
