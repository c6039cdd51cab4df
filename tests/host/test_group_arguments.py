"""CameraGroup and a clumsy caller: arguments checked when the group is made, one open per group,
a refused call leaves a running group running."""
from __future__ import annotations

import math

import pytest

import stereocam
from stereocam.device_sim import SimulatedCamera, TriggerLine

pytestmark = pytest.mark.sim_only("builds heads on an in-process trigger line")

SMALL = dict(width=160, height=120, outputs=int(stereocam.Output.LEFT), fps=15)
URLS = ["sim://?serial=CLUMSY0", "sim://?serial=CLUMSY1"]


@pytest.mark.parametrize("kwargs, named", [
    (dict(urls="sim://?seed=1"), "list of camera URLs"), (dict(urls=5), "list of camera URLs"),
    (dict(config="x"), "config"), (dict(config=[1]), "config"),
    (dict(per_camera="ab"), "per_camera"), (dict(per_camera=[5, None]), "per_camera"),
    (dict(per_camera=5), "per_camera"),
    (dict(deadline=-1), "deadline"), (dict(deadline=math.nan), "deadline"), (dict(settle="x"), "settle"),
    (dict(timeout=math.nan), "timeout"),
])
def test_arguments_are_checked_when_the_group_is_made(kwargs, named):
    kwargs = {"urls": URLS, **kwargs}
    with pytest.raises(stereocam.ConfigError, match=named):
        stereocam.CameraGroup(kwargs.pop("urls"), **kwargs)


def test_a_second_open_is_refused_and_the_running_group_keeps_running():
    line = TriggerLine()
    sims = [SimulatedCamera(serial=f"CLUMSY{i}", seed=60 + i, trigger_line=line) for i in range(2)]
    try:
        group = stereocam.CameraGroup(URLS, config=SMALL, settle=0.1)
        with group:
            assert group.get_set(timeout=20).complete
            with pytest.raises(stereocam.StereoCamError, match="already opened"):
                group.open()
            for bad in (math.nan, "1", True, -1):
                with pytest.raises(stereocam.ConfigError, match="timeout"):
                    group.get_set(timeout=bad)
            assert group.get_set(timeout=20).complete and len(group.cameras) == 2
        with pytest.raises(stereocam.StereoCamError, match="new CameraGroup"):
            group.open()
    finally:
        for sim in sims:
            sim.close()
