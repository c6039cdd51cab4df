"""``--serve ... --flash PATH`` keeps a unit's flash across restarts; private flash folders never
pile up, even when the simulator is SIGKILLed (issue 9 item 9)."""
from __future__ import annotations

import dataclasses
import signal

import stereocam
from stereocam.device_sim.calibration.truth import true_calibration
from stereocam.device_sim.process import ServedSimulator

SEED = 7


def test_flash_file_survives_a_restart(tmp_path):
    flash = tmp_path / "unit.flash"
    calib = true_calibration(SEED)
    K = calib.K_left.copy()
    K[0, 0] += 5.0
    mine = dataclasses.replace(calib, K_left=K)
    with ServedSimulator("tcp:127.0.0.1:0", seed=SEED, flash=flash) as sim:
        with stereocam.open(sim.url) as cam:
            written = cam.write_calibration(mine)
    assert flash.exists()
    with ServedSimulator("tcp:127.0.0.1:0", seed=SEED, flash=flash) as sim:
        with stereocam.open(sim.url) as cam:
            active = cam.read_calibration()
    assert active.source == "user" and active.calibration_id == written.calibration_id
    assert active.calibration.K_left[0, 0] == mine.K_left[0, 0]


def folders(root):
    return sorted(p.name for p in root.iterdir()) if root.exists() else []


def test_private_flash_is_removed_on_sigterm_and_swept_after_sigkill(tmp_path):
    env = {"XDG_RUNTIME_DIR": str(tmp_path)}
    root = tmp_path / "stereocam-flash"
    killed = ServedSimulator("tcp:127.0.0.1:0", seed=SEED, env=env)
    assert len(folders(root)) == 1, "the private flash lives in the per-user state directory"
    killed.proc.send_signal(signal.SIGKILL)
    killed.proc.wait(timeout=10)
    leaked = folders(root)
    assert len(leaked) == 1  # nothing can run at SIGKILL ...
    with ServedSimulator("tcp:127.0.0.1:0", seed=SEED, env=env):
        live = folders(root)
        assert len(live) == 1 and live != leaked  # ... the next simulator sweeps it
        for i in range(3):  # live owners are never swept
            with ServedSimulator("tcp:127.0.0.1:0", seed=SEED + 1 + i, env=env):
                assert set(live) < set(folders(root))
    assert folders(root) == []
