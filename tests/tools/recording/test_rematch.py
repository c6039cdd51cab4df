"""``stereocam rematch`` on a local Dask cluster: new disparity beside the original images, checked
frame by frame against the matching core; a worker killed mid-run loses no output."""
from __future__ import annotations

import os
import signal
import threading

import numpy as np
import pytest
from dask.distributed import Client, LocalCluster
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

import stereocam
from stereocam.stereo.engines import engine_named, matcher_for
from stereocam.recording.reader import Recording
from stereocam.tools import cli
from stereocam.tools.recording.rematch import rematch
from tests.support.waiting import wait_until

N = 16


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    path = tmp_path_factory.mktemp("in") / "run.mcap"
    with stereocam.open("sim://?seed=8", timeout=3.0) as cam:
        cam.configure(width=320, height=240, num_disparities=32, block_size=11)
        cam.record(path, frames=N, chunk_bytes=200 << 10)  # about one capture per chunk: many tasks
    return path


def _check(source, out, block_size, algorithm="bm"):
    with Recording(source) as a, Recording(out) as b:
        assert len(b) == len(a) == N and np.array_equal(a.log_times, b.log_times)
        assert b.config["block_size"] == block_size and b.metadata["stereocam.rematch"]["algorithm"] == algorithm
        assert b.config["algorithm"] == engine_named(algorithm).algorithm
        assert b.device == a.device and b.calibration.body == a.calibration.body
        matcher = matcher_for(b.config, (240, 320))  # the matching core, as the board would run it
        for ca, cb in zip(a.captures(), b.captures(), strict=True):
            assert cb.info.sequence == ca.info.sequence and cb.info.device_time_us == ca.info.device_time_us
            assert cb.left.tobytes() == ca.left.tobytes() and cb.right.tobytes() == ca.right.tobytes()
            assert np.array_equal(cb.disparity, matcher.match(ca.left, ca.right))
            assert not np.array_equal(cb.disparity, ca.disparity)
    assert [p.name for p in out.parent.iterdir()] == [out.name]  # no parts or temporary files left
    with open(out, "rb") as f:  # chunks copied from the parts: their CRCs and the summary agree
        reader = make_reader(f, validate_crcs=True)
        assert sum(1 for _ in reader.iter_messages()) == reader.get_summary().statistics.message_count == N * 6
    with AnyReader([out], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        disp = [c for c in reader.connections if c.topic == "/stereo/disparity"]
        assert sum(1 for _ in reader.messages(connections=disp)) == N


def test_rematch_cli_local_cluster(source, tmp_path, capfd):
    assert cli.main(["rematch", str(source), "--out", str(tmp_path / "out"), "--set", "block_size=21",
                     "--workers", "2"]) == 0
    err = capfd.readouterr().err  # the workers' processes too: Dask printed 33 INFO lines (issue 20)
    assert " INFO " not in err, err  # warnings may show (a worker killed at shutdown on a loaded machine)
    _check(source, tmp_path / "out" / "run.mcap", 21)


def test_rematch_with_sgm(source, tmp_path):
    """Block-matched recordings re-matched with the SGM engine: its disparity, its settings in the file."""
    assert cli.main(["rematch", str(source), "--out", str(tmp_path / "out"), "--algorithm", "sgm",
                     "--set", "sgm_paths=4", "--workers", "1"]) == 0
    _check(source, tmp_path / "out" / "run.mcap", 11, "sgm")
    with Recording(tmp_path / "out" / "run.mcap") as b:
        assert b.config["sgm_paths"] == 4


def test_killed_worker_loses_no_output(source, tmp_path):
    out = tmp_path / "out"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        pids = list(client.run(os.getpid).values())
        result: dict = {}
        run = threading.Thread(target=lambda: result.update(rematch([source], out, {"block_size": 17},
                                                                    client=client)))
        run.start()
        wait_until(lambda: any(out.glob(".run.*")), 60, "the run's first output")
        os.kill(pids[0], signal.SIGKILL)  # a worker dies with tasks on it
        run.join(timeout=240)
        assert not run.is_alive() and result["frames"] == N
    _check(source, out / "run.mcap", 17)


def test_bad_arguments(source, tmp_path):
    with pytest.raises(stereocam.ConfigError):
        rematch([source], tmp_path, {"block_size": 4})  # even block size: refused before any work
    with pytest.raises(stereocam.ConfigError):
        rematch([source], tmp_path, {}, algorithm="census")  # no such matcher
    assert cli.main(["rematch", str(source), "--out", str(source.parent)]) == 2  # usage: outputs would replace inputs


@pytest.mark.parametrize("args, what", [(["--workers", "0"], "workers"), (["--workers", "-1"], "workers"),
                                        (["--scheduler", "notaurl"], "notaurl"),
                                        (["--scheduler", "tcp://host:port"], "tcp://host:port"),
                                        (["--scheduler", "ftp://host:21"], "ftp")])
def test_bad_workers_and_scheduler_are_usage_errors_not_hangs(source, tmp_path, capsys, args, what):
    """No workers waited for ever; a malformed address gave a traceback. Both are refused at once."""
    done: dict = {}
    run = threading.Thread(target=lambda: done.update(rc=cli.main(["rematch", str(source), "--out",
                                                                   str(tmp_path / "out"), *args])), daemon=True)
    run.start()
    run.join(timeout=60)
    assert not run.is_alive() and done["rc"] == 2
    err = capsys.readouterr().err
    assert what in err and "Traceback" not in err and not (tmp_path / "out").exists()
    with pytest.raises(stereocam.ConfigError, match=what):
        rematch([source], tmp_path / "out", {}, **({"workers": int(args[1])} if args[0] == "--workers"
                                                  else {"scheduler": args[1]}))


def test_an_existing_output_is_refused_unless_force(source, tmp_path, capsys):
    """Issue 22 item 4: rematch --out DIR never replaces DIR/NAME.mcap silently."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.mcap").write_bytes(b"precious")
    assert cli.main(["rematch", str(source), "--out", str(out), "--workers", "1"]) == 2
    assert "already exists" in capsys.readouterr().err and (out / "run.mcap").read_bytes() == b"precious"
    with pytest.raises(stereocam.ConfigError, match="already exists"):
        rematch([source], out, {})
    assert (out / "run.mcap").read_bytes() == b"precious"
    with Client(processes=False, n_workers=1, threads_per_worker=1, dashboard_address=None) as client:
        assert rematch([source], out, {"block_size": 21}, client=client, force=True)["frames"] == N
    _check(source, out / "run.mcap", 21)


def test_rematch_two_inputs_of_one_name_are_refused_before_any_work(tmp_path, capsys):
    """Audit: A/run.mcap and A/sub/run.mcap both became OUT/run.mcap: worker tracebacks on the shared
    part files, exit 2 after the work, one result lost. Outputs keep their names (README), so refused."""
    a, b = tmp_path / "A" / "run.mcap", tmp_path / "A" / "sub" / "run.mcap"
    b.parent.mkdir(parents=True)
    a.write_bytes(b"first")  # never read: the names clash before any file is opened
    b.write_bytes(b"second")
    out = tmp_path / "out"
    assert cli.main(["rematch", str(a), str(b), "--out", str(out), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and str(a) in err and str(b) in err and "both be written to" in err
    assert not out.exists()
    assert cli.main(["rematch", str(a), str(tmp_path / "A" / "sub" / ".." / "run.mcap"), "--out", str(out)]) == 2
    assert "given twice" in capsys.readouterr().err and not out.exists()
    with pytest.raises(stereocam.ConfigError, match="both be written to"):
        rematch([a, b], out, {})
    assert not out.exists() and a.read_bytes() == b"first" and b.read_bytes() == b"second"


@pytest.mark.parametrize("settings, named", [(["width=64"], "width: not a matching parameter"),
                                             (["fps=5"], "fps: not a matching parameter"),
                                             (["block_size=21", "exposure_us=100", "gain=4"],
                                              "exposure_us, gain: not matching parameters"),
                                             (["no_such=1"], "no_such: not a matching parameter")])
def test_settings_that_made_the_recorded_frames_are_refused_naming_what_rematch_takes(tmp_path, capsys, settings,
                                                                                      named):
    """Audit: --set width=64 or fps=5 were accepted, though re-matching cannot change recorded frames."""
    from stereocam.stereo.post.params import POST_CONFIG
    from stereocam.tools.recording.rematch import matching_names

    run = tmp_path / "run.mcap"
    run.write_bytes(b"never read")  # refused with the options, before any file is opened
    out = tmp_path / "out"
    argv = ["rematch", str(run), "--out", str(out), "--workers", "1"]
    assert cli.main([*argv, *(a for s in settings for a in ("--set", s))]) == 2
    err = capsys.readouterr().err
    assert "'--set'" in err and named in err and "Traceback" not in err and not out.exists()
    assert "it takes num_disparities, block_size" in err and "sgm_paths" in err and "median_size" in err
    names = matching_names()
    assert {"width", "height", "fps", "gain", "outputs", "rectify"}.isdisjoint(names)
    assert {f.key for f in POST_CONFIG} | {"algorithm", "block_size", "sgm_p1", "census_width"} <= set(names)
    with pytest.raises(stereocam.ConfigError, match=named.split(":")[0]):  # the API refuses them too
        rematch([run], out, {k: int(v) for k, v in (s.split("=") for s in settings)})
    assert not out.exists()
