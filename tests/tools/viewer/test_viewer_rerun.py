"""Issue 20 item 2: ``stereocam view URL --rerun-save FILE.rrd``, read back with Rerun's own reader."""
from __future__ import annotations

import json
import subprocess
import sys
import urllib.request

import numpy as np
import pytest

from tests.support.hangs import terminated
from tests.support.waiting import wait_until

rerun = pytest.importorskip("rerun", reason="rerun-sdk is not installed (pip install 'stereocam[viewer]')")


def _frame(url: str) -> dict | None:
    with urllib.request.urlopen(url + "api/frame", timeout=30) as r:
        return json.loads(r.read())


def test_view_streams_images_depth_pinhole_points_and_counters_to_a_rerun_recording(tmp_path):
    from rerun.chunk import RrdReader

    rrd = tmp_path / "view.rrd"
    proc = subprocess.Popen([sys.executable, "-m", "stereocam.tools.cli", "view", "sim://?seed=5", "--no-browser",
                             "--set", "width=320", "--set", "height=240", "--set", "num_disparities=32",
                             "--set", "fps=5", "--rerun-save", str(rrd)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        url = proc.stdout.readline().strip()
        assert url.startswith("http://127.0.0.1:"), proc.stderr.read()
        first = wait_until(lambda: _frame(url), timeout=60, what="a frame")
        assert first["width"] == 320  # --set reached the camera
        wait_until(lambda: (_frame(url) or {}).get("sequence", -1) >= first["sequence"] + 3, timeout=60,
                   what="3 more frames")
    finally:
        assert (rc := terminated(proc)) == 0, (rc, proc.stderr.read())
    store = RrdReader(rrd).store()
    paths = set(store.schema().entity_paths())
    assert {"/world/camera", "/world/camera/left", "/world/camera/right", "/world/camera/depth", "/world/points",
            "/counters/fps", "/counters/host/frames", "/counters/device/frames_captured"} <= paths
    summary = str(store.summary())
    assert "Pinhole:image_from_camera" in summary and "DepthImage:meter" in summary and "Points3D:colors" in summary
    clouds = [c.to_record_batch() for c in store.stream().to_chunks() if c.entity_path == "/world/points"]
    cloud = np.array(clouds[0].column("Points3D:positions")[0].as_py())
    assert len(cloud) > 1000 and (cloud[:, 2] > 0).all()  # a point cloud in front of the camera, in metres
    assert sum(c.num_rows for c in clouds) >= 2  # one per frame logged
