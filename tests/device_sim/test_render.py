"""The renderer's static-layer path against the plain ray caster: the same pixels, bit for bit."""
from __future__ import annotations

import numpy as np
import pytest

from stereocam.device_sim.calibration.truth import true_calibration
from stereocam.device_sim.rig import render, scene
from stereocam.device_sim.rig.sensor import LIGHT, SensorRig


def full_render(rig: SensorRig, eye: int, prims: np.ndarray) -> np.ndarray:
    origin, rot = rig._poses[eye]
    rad = np.empty(rig._rays[eye].shape[:2], np.float32)
    render.render_radiance(rig._rays[eye], origin, rot, prims, rig.texture, rig.tex_offsets, rig.tex_side, LIGHT,
                           rad, np.empty_like(rad))
    return rad


def layered_render(rig: SensorRig, eye: int, view: scene.Scene, prims: np.ndarray) -> np.ndarray:
    origin, rot = rig._poses[eye]
    moving = scene.moving_primitives(view)
    layer = rig._static_layer(eye, view, prims, moving)
    rad = np.empty(layer.rad.shape, np.float32)
    render.render_over(rig._rays[eye], rig._cones[eye], origin, rot, prims, moving, layer.rad, layer.t, layer.hit,
                       rig.texture, rig.tex_offsets, rig.tex_side, LIGHT, rad)
    return rad


@pytest.mark.parametrize("width,height", [(320, 240), (203, 117)])  # 203x117: partial tiles at the edges
def test_static_layer_plus_moving_primitives_is_the_full_render(width, height):
    rig = SensorRig(5, true_calibration(5))
    rig.set_format(width, height)
    for t in (0.0, 0.8, 2.1, 3.3, 6.7):  # the panel slides, the sphere moves in depth
        prims = scene.primitives(scene.Scene.LAB, t)
        for eye in (0, 1):
            full = full_render(rig, eye, prims)
            assert np.array_equal(layered_render(rig, eye, scene.Scene.LAB, prims), full)
    assert len(rig._layers) == 2  # one static layer per eye, rendered once


def test_a_static_primitive_that_moves_after_all_rebuilds_the_layer():
    rig = SensorRig(6, true_calibration(6))
    rig.set_format(160, 120)
    prims = scene.primitives(scene.Scene.LAB, 0.0)
    layered_render(rig, 0, scene.Scene.LAB, prims)
    prims[3, render.CX] += 0.2  # the slanted board is declared static: move it anyway
    assert np.array_equal(layered_render(rig, 0, scene.Scene.LAB, prims), full_render(rig, 0, prims))


def test_ray_cones_hold_every_ray_of_their_tile():
    rig = SensorRig(7, true_calibration(7))
    rig.set_format(203, 117)
    rays = rig._rays[0].astype(np.float64)
    unit = rays / np.linalg.norm(rays, axis=2, keepdims=True)
    cones = render.ray_cones(rig._rays[0])
    ty, tx = (np.arange(117) // render.TILE)[:, None], (np.arange(203) // render.TILE)[None, :]
    axis = cones[ty, tx, :3]
    angle = np.arccos(np.clip((unit * axis).sum(axis=2), -1, 1))
    assert np.all(angle <= cones[ty, tx, 3] + 1e-12)
