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


@pytest.mark.parametrize("argv, words", [
    (["--rerun-save", "{tmp}/missing/view.rrd"], "missing is not a folder"),
    (["--rerun-connect", "nope"], "expected a URL starting rerun://"),
    (["--rerun-connect", "http://127.0.0.1:9876/proxy"], "got 'http://127.0.0.1:9876/proxy'")])
def test_a_rerun_sink_that_cannot_work_is_a_usage_error_before_the_camera(monkeypatch, capsys, tmp_path, argv, words):
    from stereocam.tools import cli

    def opened(*args: object, **kwargs: object) -> None:
        raise AssertionError("the camera was opened")

    monkeypatch.setattr("stereocam.tools.viewer.command.stereocam.open", opened)
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    assert cli.main(["view", "--no-browser", "sim://?seed=5", *argv]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err


@pytest.mark.parametrize("where", ["save", "connect"])
def test_the_bridge_turns_rerun_refusing_its_sink_into_the_projects_error(tmp_path, where):
    from types import SimpleNamespace

    from stereocam.tools.viewer.rerun_bridge import RerunBridge, RerunSinkError

    (tmp_path / "a-file").write_text("")
    sink = ({"save": tmp_path / "a-file" / "view.rrd"} if where == "save"
            else {"connect": "rerun+http://127.0.0.1:9876"})  # no /proxy: rerun refuses the endpoint
    with pytest.raises(RerunSinkError, match="rerun: cannot (save|stream) to .*: ") as refused:
        RerunBridge(SimpleNamespace(newest=lambda after, wait: None), **sink)  # type: ignore[arg-type]
    assert isinstance(refused.value.__cause__, RuntimeError)


def test_view_exits_1_with_rerun_s_reason_when_it_refuses_the_endpoint(capsys):
    from stereocam.tools import cli
    from tests.support.hangs import returns_within

    rc = returns_within(120, cli.main, ["view", "--no-browser", "sim://?seed=5",
                                        "--rerun-connect", "rerun+http://127.0.0.1:9876"])
    err = capsys.readouterr().err
    assert rc == 1 and "stereocam view: error: rerun: cannot stream to rerun+http://127.0.0.1:9876" in err
    assert "Traceback" not in err
