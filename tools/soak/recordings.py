"""The hostile-recording stage of ``stereocam soak``: fuzzed recordings and compression bombs
through ``recording export``, ``recording repair``, replay and ``rematch``, each in this process.

Counted: crashes (a traceback, an exit code other than 0/1/2, an exception that is not the stack's
own), hangs (an operation over ``hang_s``), the peak memory of the process, and files changed
outside an operation's output folder (the input and everything beside it must stay as they were).
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import logging
import random
import shutil
import struct
import tempfile
import threading
from pathlib import Path
from typing import Any, Callable

import zstandard
from mcap.reader import make_reader
from mcap.records import Chunk, MessageIndex
from mcap.stream_reader import StreamReader

from stereocam.protocol.errors import StereoCamError
from stereocam.recording.mcapwriter import ChunkedWriter

from .parts import Report, mutate, peak_memory_mib, reset_peak_memory

BOMBS = ("declares 1 GiB", "zstd header claims 4 GiB", "zstd header claims 1 TiB")


def zeros_zstd(n: int) -> bytes:
    """``n`` zero bytes as one zstd frame, compressed as a stream (never held whole)."""
    cobj, out, block = zstandard.ZstdCompressor(level=1).compressobj(size=n), [], bytes(1 << 20)
    for done in range(0, n, len(block)):
        out.append(cobj.compress(block[:min(len(block), n - done)]))
    out.append(cobj.flush())
    return b"".join(out)


def claiming_zstd(content_size: int) -> bytes:
    """A small zstd frame whose header claims ``content_size`` bytes (single segment: its window too)."""
    frame = zstandard.ZstdCompressor(write_content_size=False, write_checksum=False).compress(b"\0" * 1000)
    fhd = frame[4]
    skip = 5 + (0 if fhd & 0x20 else 1) + (0, 1, 2, 4)[fhd & 3]  # window descriptor, dictionary id
    return frame[:4] + bytes([0xE0]) + struct.pack("<Q", content_size) + frame[skip:]


def bomb(name: str) -> tuple[bytes, int]:
    """The chunk data of bomb ``name`` (see BOMBS) and the size its chunk declares."""
    if name == BOMBS[0]:
        return zeros_zstd(1 << 30), 1 << 30
    return claiming_zstd(4 << 30 if name == BOMBS[1] else 1 << 40), 1000


def with_chunk_replaced(src: Path, dst: Path, data: bytes, declared: int, which: int = 1) -> Path:
    """``src`` written again with chunk ``which``'s data replaced by ``data`` declaring ``declared``
    bytes (its message indexes, the summary and the frame index as they were)."""
    with open(src, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is None:
            raise ValueError(f"{src}: no summary section to rebuild the file from")
        metadata, attachments = list(reader.iter_metadata()), list(reader.iter_attachments())
        f.seek(0)
        chunks: list[tuple[Chunk, list[MessageIndex]]] = []
        for record in StreamReader(f, emit_chunks=True).records:
            if isinstance(record, Chunk):
                chunks.append((record, []))
            elif isinstance(record, MessageIndex) and chunks:
                chunks[-1][1].append(record)
    w = ChunkedWriter(dst, exclusive=True)
    for sid in sorted(summary.schemas):
        s = summary.schemas[sid]
        w.register_schema(s.name, s.encoding, s.data)
    for cid in sorted(summary.channels):
        c = summary.channels[cid]
        w.register_channel(c.topic, c.message_encoding, c.schema_id, c.metadata)
    for i, (chunk, indexes) in enumerate(chunks):
        if i == which:
            chunk = Chunk(message_start_time=chunk.message_start_time, message_end_time=chunk.message_end_time,
                          uncompressed_size=declared, uncompressed_crc=0, compression="zstd", data=data)
        w.copy_chunk(chunk, indexes)
    for m in metadata:
        w.add_metadata(m.name, dict(m.metadata))
    for a in attachments:
        w.add_attachment(a.name, a.media_type, a.data, a.log_time)
    w.finish()
    return dst


def _digests(root: Path, skip: Path) -> dict[str, str]:
    """SHA-256 of every file under ``root`` except those under ``skip``."""
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*"))
            if p.is_file() and not p.is_relative_to(skip)}


def _within(seconds: float, fn: Callable[[], Any]) -> tuple[str, Any]:
    """("ok", result) / ("error", exception) / ("hang", None) of ``fn`` on a daemon thread."""
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["ok"] = fn()
        except BaseException as exc:  # noqa: BLE001 - judged by the caller
            box["error"] = exc

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(seconds)
    if t.is_alive():
        return "hang", None
    return ("ok", box["ok"]) if "ok" in box else ("error", box["error"])


def _cli(argv: list[str]) -> Callable[[], tuple[int, str]]:
    from stereocam.tools import cli

    def run() -> tuple[int, str]:
        err = io.StringIO()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            rc = cli.main(argv)
        return rc, err.getvalue()
    return run


def _base(folder: Path) -> Path:
    """A small recording of the simulator in several chunks: what the hostile files are made from."""
    import stereocam

    path = folder / "base.mcap"
    with stereocam.open("sim://?seed=1", timeout=3.0) as cam:
        cam.configure(width=320, height=240, num_disparities=32, block_size=11)
        cam.record(path, frames=4, chunk_bytes=200 << 10)
    return path


def fuzz_recordings(files: int, seed: int = 0, hang_s: float = 60.0) -> Report:
    """``files`` hostile recordings (the three bombs, then mutated copies of a small recording),
    each through export, repair, replay and rematch; see the module doc."""
    from dask.distributed import Client

    from stereocam.tools.recording.rematch import rematch

    rng = random.Random(seed)
    rep = Report("hostile recordings")
    reset_peak_memory()  # this stage's peak, not the process's history
    refused = changed = 0
    dask_log = logging.getLogger("distributed")
    level = dask_log.level
    dask_log.setLevel(logging.CRITICAL)  # every refused file would log its failed tasks: counted here instead
    with tempfile.TemporaryDirectory(prefix="stereocam-soak-") as tmp, \
            Client(processes=False, n_workers=1, threads_per_worker=1, dashboard_address=None) as client, \
            contextlib.ExitStack() as restore:
        restore.callback(dask_log.setLevel, level)
        root = Path(tmp)
        base = _base(root)
        clean = base.read_bytes()
        for i in range(files):
            case = root / f"case{i:05d}"
            case.mkdir()
            src = case / "in.mcap"
            if i < len(BOMBS):
                with_chunk_replaced(base, src, *bomb(BOMBS[i]))
            else:
                src.write_bytes(mutate(rng, clean))
            out = case / "out"
            operations: dict[str, Callable[[], Any]] = {
                "export": _cli(["recording", "export", str(src), "--out", str(out / "export")]),
                "repair": _cli(["recording", "repair", str(src), "--out", str(out / "repaired.mcap")]),
                "replay": _cli(["info", f"replay://{src}?speed=fast"]),
                "rematch": functools.partial(rematch, [src], out / "rematch", {}, client=client),
            }
            for name, run in operations.items():
                before = _digests(root, out)
                how, result = _within(hang_s, run)
                rep.inputs += 1
                if how == "hang":
                    rep.hangs += 1
                elif how == "error":
                    if isinstance(result, StereoCamError):
                        refused += 1
                    else:
                        rep.crashes += 1
                        rep.figures.setdefault("first crash", f"case {i} {name}: {type(result).__name__}: {result}")
                elif name != "rematch":
                    rc, err = result
                    refused += rc != 0
                    if rc not in (0, 1, 2) or "Traceback" in err:
                        rep.crashes += 1
                        rep.figures.setdefault("first crash", f"case {i} {name}: exit {rc}: {err[-300:]}")
                changed += sum(1 for k, v in _digests(root, out).items() if before.get(k) != v)
            shutil.rmtree(case)
    rep.figures["files"] = files
    rep.figures["operations refused (damaged, exit 1/2)"] = refused
    rep.figures["files changed outside the output"] = changed
    rep.figures["peak memory MiB"] = round(peak_memory_mib())
    return rep
