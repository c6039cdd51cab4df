"""CameraGroup as a user meets it: heads wired by ``sim://?line=``, unwired heads named, the first set
waited for, the cameras put back as found at close (issue 20 item 4)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

import stereocam
from stereocam.device_sim import SimulatedCamera
from stereocam.device_sim.trigger import named_line
from stereocam.tools.conformance.budget import budget

pytestmark = pytest.mark.sim_only("wires simulated heads")

README = Path(__file__).resolve().parents[2] / "README.md"
SMALL = dict(width=160, height=120, outputs=int(stereocam.Output.LEFT), fps=30)


def sets_until_silence(group: stereocam.CameraGroup, seconds: float) -> stereocam.SilentHeadsError:
    """get_set until it names silent heads; a test failure if it does not within ``seconds``."""
    with pytest.raises(stereocam.SilentHeadsError) as caught:
        for _ in range(int(seconds * 30) + 1):  # at most one set per pulse at 30 fps
            group.get_set(timeout=budget(seconds))
    return caught.value


def test_the_readme_group_example_runs_as_written(capsys):
    section = README.read_text().split("## Several heads on one trigger", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    exec(compile(code, str(README), "exec"), {})  # the default timeout: the first set waits for the settle
    assert re.match(r"(True \(\)|False \('SIM0001[12]',\)) ", capsys.readouterr().out)  # a set (complete unless
    # the machine is so loaded that a head's first frame came after the deadline)


def test_unwired_sim_heads_are_named_within_two_seconds():
    with stereocam.CameraGroup(["sim://?seed=41", "sim://?seed=42", "sim://?seed=43"], config=SMALL,
                               settle=0.2) as group:
        error = sets_until_silence(group, 2.0)
        assert error.heads == ("SIM00042", "SIM00043")
        assert "SIM00042 (sim://?seed=42)" in str(error) and "trigger" in str(error)
        assert group.silent_heads() == ("SIM00042", "SIM00043")
        s = group.get_set()  # told once: the sets go on, the silent heads missing
        assert s.missing == ("SIM00042", "SIM00043") and list(s.frames) == ["SIM00041"]


def test_a_head_whose_cable_is_out_is_named_and_the_wired_ones_match():
    urls = ["sim://?seed=51&line=wiring", "sim://?seed=52&line=wiring", "sim://?seed=53"]
    with stereocam.CameraGroup(urls, config=SMALL, settle=0.2) as group:
        assert sets_until_silence(group, 2.0).heads == ("SIM00053",)
        sets = [group.get_set() for _ in range(5)]
    assert all(set(s.frames) == {"SIM00051", "SIM00052"} and s.missing == ("SIM00053",) for s in sets)


@pytest.mark.parametrize("keep", [False, True])
def test_the_group_puts_each_cameras_configuration_back_unless_kept(keep):
    line = named_line("putback")
    sims = [SimulatedCamera(serial=f"PUT{i}{keep:d}", seed=60 + i, trigger_line=line) for i in range(2)]
    urls = [f"sim://?serial={sim.serial}" for sim in sims]
    try:
        before = []
        for url in urls:
            with stereocam.open(url) as cam:
                before.append(cam.config())
        with stereocam.CameraGroup(urls, config=SMALL, settle=0.2, keep_config=keep) as group:
            assert group.get_set().complete
        after = []
        for url in urls:
            with stereocam.open(url) as cam:
                after.append(cam.config())
    finally:
        for sim in sims:
            sim.close()
    if keep:
        assert [c["trigger_mode"] for c in after] == [stereocam.TriggerMode.EXTERNAL] * 2
        assert [c["trigger_output"] for c in after] == [1, 0] and after[0]["width"] == 160
    else:
        assert after == before
        assert before[0]["trigger_mode"] == stereocam.TriggerMode.FREE_RUN


def test_a_sim_url_line_name_is_checked():
    with pytest.raises(stereocam.ConfigError, match="trigger line name"):
        stereocam.open("sim://?seed=1&line=no/slash")
