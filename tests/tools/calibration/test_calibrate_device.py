"""The factory calibration tool against a simulated camera: pass, write, read back — or refuse."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.rig.sensor import BOARD
from stereocam.camera import Camera
from stereocam.device_sim.links.inprocess import InProcessTransport
from stereocam.protocol import messages as m
from stereocam.tools.bench.device_calibration import rectified_dy
from stereocam.tools.calibration.solve import SolveConfig
from stereocam.tools.calibration.calibrate import write_outputs
from stereocam.tools.calibration.device import (EXIT_GATE, EXIT_NO_SOLUTION, EXIT_OK, EXIT_WRITE, calibrate_device)

from tests.support.faults import FaultyTransport, PacketFilter

pytestmark = pytest.mark.sim_only("calibrates simulated units against their true calibration")


FAST = dict(size=(640, 480), fps=20)
WRITE_PATH = SolveConfig(max_views=12, lens_model="plumb_bob")
"""For tests of what follows the solve (gate, write, read-back): the simulated lenses are plumb_bob,
which the model race picks anyway; one model instead of three is a third of the solving."""


def run(cam, tmp_path, config=SolveConfig(), **kw):
    return calibrate_device(cam, BOARD, config, tmp_path, write_outputs=write_outputs, **{**FAST, **kw})


@pytest.fixture
def fresh(tmp_path):
    """A unit fresh from assembly: no calibration stored."""
    sim = SimulatedCamera(serial="LINE-1", seed=71, flash_path=tmp_path / "u.flash", factory_calibrated=False,
                          scene="board")
    cam = Camera(InProcessTransport(sim), timeout=2.0)
    yield cam, sim
    cam.close()


def test_calibrates_writes_verifies_and_the_device_uses_it(fresh, tmp_path):
    cam, sim = fresh
    config_before = cam.config()
    # 40 views for the accuracy below, one lens model: the race of three runs in device mode in
    # test_calibrate_wire and test_calib_export (it took this test past its timeout on a loaded host)
    code, result, verdict = run(cam, tmp_path, SolveConfig(lens_model="plumb_bob"), target="factory")
    assert code == EXIT_OK, verdict
    assert "verified by read-back" in verdict
    stored = cam.read_calibration()
    assert stored.source == "factory" and stored.body == result.calibration.to_bytes()
    truth = sim.true_calibration().scaled(640, 480)
    assert abs(stored.calibration.K_left[0, 0] / truth.K_left[0, 0] - 1) < 0.005
    assert abs(stored.calibration.baseline_m / truth.baseline_m - 1) < 0.005
    doc = json.loads((tmp_path / "calibration.json").read_text())
    assert doc["passed"] and doc["written"] and doc["verified"] and doc["image_size"] == [640, 480]
    assert {"K_left", "D_left", "K_right", "D_right", "R", "T", "rms_stereo", "epipolar_rms_px",
            "views_used"} <= set(doc)
    assert cam.config() == config_before  # the tool put the camera back as it found it
    cam.configure(width=320, height=240, num_disparities=32, block_size=11, trigger_mode=1)
    cam.start()
    cam.trigger()
    f = cam.get_frame(timeout=30)
    assert f.rectified and f.geometry.calibration_id == stored.calibration_id  # rectified from it


def test_board_never_found(fresh, tmp_path):
    cam, sim = fresh
    sim.scene = "wall"  # the fixture shows no board
    code, result, verdict = run(cam, tmp_path, pairs=4)
    assert code == EXIT_NO_SOLUTION and result is None
    assert "board" in verdict and "nothing was written" in verdict
    assert cam.read_calibration() is None and cam.info().calibration_id == 0


def test_too_few_views(fresh, tmp_path):
    cam, _ = fresh
    code, _, verdict = run(cam, tmp_path, pairs=3)
    assert code == EXIT_NO_SOLUTION and "views" in verdict
    assert cam.read_calibration() is None


def test_failing_gate_writes_nothing(fresh, tmp_path):
    cam, _ = fresh
    code, result, verdict = run(cam, tmp_path, SolveConfig(max_stereo_rms_px=0.001, max_views=12, lens_model="plumb_bob"))
    assert code == EXIT_GATE and "FAILED the gate" in verdict and "stereo" in verdict
    assert cam.read_calibration() is None
    doc = json.loads((tmp_path / "calibration.json").read_text())
    assert doc["passed"] is False and not doc.get("written")
    assert not (tmp_path / "left.yaml").exists()


def test_failed_flash_write_keeps_the_previous_calibration(tmp_path):
    sim = SimulatedCamera(seed=72, flash_path=tmp_path / "f.flash", scene="board")  # factory calibrated
    with Camera(InProcessTransport(sim), timeout=2.0) as cam:
        before = cam.read_calibration()
        sim.calibration.flash.power_loss_after(1)
        code, result, verdict = run(cam, tmp_path, WRITE_PATH)
        assert code == EXIT_WRITE and "STORAGE" in verdict and f"{before.calibration_id:08x}" in verdict
        sim.calibration.flash.power_loss_after(None)
        assert cam.read_calibration().body == before.body
        assert json.loads((tmp_path / "calibration.json").read_text())["written"] is False


def test_read_back_that_differs_is_not_success(tmp_path):
    sim = SimulatedCamera(seed=73, flash_path=tmp_path / "r.flash", factory_calibrated=False, scene="board")
    link = FaultyTransport(InProcessTransport(sim))

    def corrupt(p):
        if p.msg_type == m.MsgType.CALIB_DATA and len(p.payload) > 100:
            from stereocam.protocol.framing import encode_frame
            bad = bytearray(p.payload)
            bad[50] ^= 0x01
            return encode_frame(p.msg_type, p.request_id, bytes(bad), p.flags)
        return None

    with Camera(link, timeout=2.0) as cam:
        link.set_manipulator(read=PacketFilter(corrupt))
        code, _, verdict = run(cam, tmp_path, WRITE_PATH)
    assert code == EXIT_WRITE and "read back" in verdict
    assert json.loads((tmp_path / "calibration.json").read_text())["verified"] is False


def test_cli_device_mode(tmp_path):
    r = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "calibrate", "sim://?seed=74&scene=board", "--out", str(tmp_path),
                        "--size", "640x480", "--max-views", "15", "--lens-model", "plumb_bob", "-q"], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    assert "PASSED" in r.stdout and "verified by read-back" in r.stdout
    assert {p.name for p in tmp_path.iterdir()} >= {"calibration.json", "calibration.yaml", "left.yaml",
                                                    "right.yaml", "report.png"}


def test_cli_needs_a_url_or_images(tmp_path):
    r = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "calibrate", "--out", str(tmp_path)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "nothing to calibrate" in r.stderr and "not both" not in r.stderr
    both = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "calibrate", "sim://?seed=1", "--images",
                           str(tmp_path), "--out", str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert both.returncode == 2 and "not both" in both.stderr


def test_an_out_folder_that_cannot_be_written_stops_before_the_camera(tmp_path):
    """/proc refuses new folders even to root (whose permission bits always say yes): exit 2 at once."""
    r = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "calibrate", "sim://?seed=75&scene=board",
                        "--out", "/proc/stereocam-nope/out", "--db", str(tmp_path / "f.sqlite")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "cannot write into directory" in r.stderr and "nothing was done" in r.stderr
    assert not (tmp_path / "f.sqlite").exists()  # not even the factory record was opened


@pytest.mark.parametrize("replug", [True, False])
def test_an_unplug_during_the_write_is_followed_by_a_read_back_that_says_what_the_unit_holds(tmp_path, replug):
    """Issue 22.15: the USB plug is pulled just after CALIB_COMMIT ran on the unit (the new record is
    stored, the host sees DisconnectedError). The tool reconnects, reads back and reports what the
    unit holds: the new calibration (exit 0, verified); or, when the unit does not come back, exit 5
    saying that what it holds is unknown, never that it keeps its previous calibration."""
    import threading
    import time

    import stereocam
    import stereocam.device_sim.usb as simusb

    sim = SimulatedCamera(serial="UNPLUG-15", seed=75, flash_path=tmp_path / "p.flash", scene="board")
    handles = [simusb.plug(sim)]
    real = sim.dispatcher.handlers[m.MsgType.CALIB_COMMIT]

    def commit_then_unplug(msg):
        reply = real(msg)

        def pull():
            handles[-1].unplug()
            if replug:
                time.sleep(0.3)
                handles.append(simusb.plug(sim))
        threading.Thread(target=pull, daemon=True).start()
        return reply

    sim.dispatcher.handlers[m.MsgType.CALIB_COMMIT] = commit_then_unplug
    # a request timeout of 2 s as the other device tests: three tries of 1 s without a reply to a
    # CALIB_WRITE chunk on a loaded host failed the write before the commit ran (nothing to unplug after)
    cam = stereocam.open("usb://?serial=UNPLUG-15", timeout=2.0)
    try:
        before = cam.read_calibration()
        code, result, verdict = run(cam, tmp_path, WRITE_PATH, reconnect_timeout=3.0)
        stored = sim.calibration.store.read()
        assert stored.body == result.calibration.to_bytes() != before.body, verdict  # the unit did store it
        doc = json.loads((tmp_path / "calibration.json").read_text())
        if replug:
            assert code == EXIT_OK and "reconnect" in verdict and f"{m.calib_id(stored.body):08x}" in verdict, verdict
            assert doc["written"] and doc["verified"]
        else:
            assert code == EXIT_WRITE and "unknown" in verdict and "keeps its previous" not in verdict, verdict
            assert doc["verified"] is False
    finally:
        cam.close()
        for h in handles:
            h.unplug()


@pytest.mark.slow
@pytest.mark.measurement  # `make measure`: see the docstring
@pytest.mark.timeout(600)
@pytest.mark.parametrize("lens, model, seed", [("wide", "rational_polynomial", 73), ("fisheye", "equidistant", 73)])
def test_wide_angle_units_calibrate_to_their_truth_and_rectify_on_board(tmp_path, lens, model, seed):
    """Issue 19 on a 120° and a 180° unit: the whole device flow (capture, calibrate, write, rectify on
    board) within 0.2 % of the truth, held-out epipolar < 0.1 px, rectified board corners < 0.1 px
    apart vertically. Small: 640x480, the lens model named (cheaper than the automatic choice).
    Other seeds: ``stereocam bench device-calibration --size 640x480 --lens wide --lens fisheye``.
    A measurement, out of `make test`: on a loaded 2-core host the fisheye case takes ~5 minutes.
    The wide case's earlier failures ("rectification gives no usable view (focal -inf px)", 2 of 4
    runs) came from frame sets where one camera's rational fit fell into a false minimum (1.5 px
    against the other's 0.06 px) and the screening fits, which had to rectify, could not drop the
    pair that spoilt them; both are fixed (tools/calibration/fit.py): the frame sets of seed 73 that
    failed, solved offline, now meet the targets (seed 73 caught at strides 1-4: six sets, at worst
    0.097 % / 0.068 px), and the wide case here passed 3 of 3 runs; it stays out of `make test` as
    those runs took 120-230 s on a 2-core host at load ~12 (the suite's budget: ~60 s). The rectified
    frames are the bench's (rectified_dy): the first 3 of up to 60 that show the board in both views,
    standing still (a fisheye run once found it in 2 of the 40 frames this test scanned before)."""
    sim = SimulatedCamera(serial=f"LENS-{lens}", seed=seed, flash_path=tmp_path / "u.flash", factory_calibrated=False,
                          scene="board", lens=lens)
    with Camera(InProcessTransport(sim), timeout=2.0) as cam:
        code, result, verdict = run(cam, tmp_path, SolveConfig(lens_model=model), target="factory")
        assert code == EXIT_OK, verdict
        assert result.calibration.lens_model == model and result.quality.epipolar_rms_px < 0.1
        stored = cam.read_calibration().calibration
        truth = sim.true_calibration().scaled(640, 480)
        for K, T in ((stored.K_left, truth.K_left), (stored.K_right, truth.K_right)):
            np.testing.assert_allclose(K[[0, 1, 0, 1], [0, 1, 2, 2]], T[[0, 1, 0, 1], [0, 1, 2, 2]], rtol=0.002)
        assert abs(stored.baseline_m / truth.baseline_m - 1) < 0.002
        dy, frames = rectified_dy(cam, 3, (640, 480))  # the bench's measure (stereocam bench device-calibration)
    assert frames == 3 and dy < 0.1
