"""``stereocam view URL --rerun``: the viewer's frames streamed to Rerun (rerun-sdk), beside the page.

Entities (timeline ``sequence``, the frame's sequence number): ``world`` (right-down-forward, the
left camera's frame), ``world/camera`` (the pinhole model of the frame, focal length and principal
point from the device's calibration), ``world/camera/left`` and ``/right`` (images),
``world/camera/depth`` (depth in metres), ``world/points`` (the point cloud, coloured by the left
image) and ``counters/...`` (frame rate, host and device counters). The newest frame is logged,
like the page shows it: a slow sink skips frames, never queues them."""
from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import numpy as np

from stereocam.protocol.errors import StereoCamError

from .cloud import sampled_points
from .session import ViewerSession

APPLICATION_ID = "stereocam_view"
POINT_STEP = 2  # every 2nd pixel's point in each direction (a quarter of the frame)


class RerunSinkError(StereoCamError):
    """Rerun refused the recording's sink: an .rrd file it cannot create, an endpoint it cannot use,
    a viewer it cannot start (the message says which, with Rerun's reason)."""


def rerun_available() -> bool:
    try:
        import rerun  # noqa: F401
    except ImportError:
        return False
    return True


class RerunBridge:
    """A thread that logs each newest frame of ``session`` to a Rerun recording: saved to
    ``save`` (an .rrd file), sent to the viewer at ``connect`` (a rerun+http:// URL) or to a
    Rerun viewer it spawns (neither given)."""

    def __init__(self, session: ViewerSession, save: Path | None = None, connect: str | None = None):
        import rerun as rr

        self._rr = rr
        self.session = session
        self.rec = rr.RecordingStream(APPLICATION_ID)
        try:
            if save is not None:
                self.rec.save(str(save))
            elif connect is not None:
                self.rec.connect_grpc(connect)
            else:
                self.rec.spawn()
        except RuntimeError as exc:  # rerun-sdk's errors from its Rust core
            sink = (f"save to {save}" if save is not None else f"stream to {connect}" if connect is not None
                    else "start a Rerun viewer")
            raise RerunSinkError(f"rerun: cannot {sink}: {exc}") from exc
        self.rec.log("world", rr.ViewCoordinates.RDF, static=True)
        self.frames = 0  # frames logged
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="stereocam-viewer-rerun", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        last = -1
        while not self._stop.is_set():
            frame = self.session.newest(after=last, wait=0.5)
            if frame is None or frame.sequence == last:
                continue
            last = frame.sequence
            self.log(frame)

    def log(self, frame: Any) -> None:
        """One frame: its images, pinhole model, depth, point cloud and the counters."""
        rr, rec = self._rr, self.rec
        rec.set_time("sequence", sequence=frame.sequence)
        g = frame.geometry
        rec.log("world/camera", rr.Pinhole(focal_length=g.focal_px, principal_point=[g.cx, g.cy],
                                           resolution=[frame.width, frame.height]))
        for plane in ("left", "right"):
            img = getattr(frame, plane)
            if img is not None:
                rec.log(f"world/camera/{plane}", rr.Image(img))
        if frame.disparity is not None:
            rec.log("world/camera/depth", rr.DepthImage(np.nan_to_num(frame.depth(), nan=0.0), meter=1.0))
            points, rgb = sampled_points(frame, POINT_STEP, "left", self.session.span(frame))
            rec.log("world/points", rr.Points3D(points, colors=rgb))
        rec.log("counters/fps", rr.Scalars(self.session.fps()))
        cam = self.session.cam
        for name, value in cam.stats.items():
            rec.log(f"counters/host/{name}", rr.Scalars(float(value)))
        status = cam.last_status
        for name, value in (status.counters.items() if status else ()):
            rec.log(f"counters/device/{name}", rr.Scalars(float(value)))
        self.frames += 1

    def close(self) -> None:
        """Stop logging and finish the recording (an .rrd file is complete after this)."""
        self._stop.set()
        self._thread.join(timeout=5)
        self.rec.flush()
        self.rec.disconnect()
