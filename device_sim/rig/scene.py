"""Scenes in front of the rig, as functions of time (world frame = left camera frame, metres).

A scene is a list of primitives packed for ``render.render_radiance``. What the simulated unit
looks at is a simulator setting (``SimulatedCamera(scene=...)``, ``--scene``, ``sim://?scene=``),
never a device parameter:
"lab" — back wall, floor, a sliding panel, a slanted board and a sphere moving in depth;
"wall" — one fronto-parallel textured wall at ``WALL_DISTANCE_M`` filling the view;
"board" — a chessboard a fixture moves through varied poses (rendered by ``calibration.board``;
    ``sensor.BOARD*`` give its size, pose count and dwell time);
and the scene classes of ``scene_classes`` (slanted, curved, thin, low-texture, repetitive, exposure,
vignetting, noise, motion-blur, driving, clutter, misaligned), each with its own photometry (and the
misaligned one with its right imager turned off the pose its calibration holds), at placement seed 0.
"""
from __future__ import annotations

import enum
import math

import numpy as np

from stereocam.protocol.errors import ConfigError

from .photometry import PLAIN, Photometry
from .scene_classes import CLASSES
from .shapes import rect, sphere

WALL_DISTANCE_M = 1.0


class Scene(str, enum.Enum):
    """What the simulated rig looks at."""

    LAB = "lab"
    WALL = "wall"
    BOARD = "board"
    SLANTED = "slanted"
    CURVED = "curved"
    THIN = "thin"
    LOW_TEXTURE = "low-texture"
    REPETITIVE = "repetitive"
    EXPOSURE = "exposure"
    VIGNETTING = "vignetting"
    NOISE = "noise"
    MOTION_BLUR = "motion-blur"
    DRIVING = "driving"
    CLUTTER = "clutter"
    MISALIGNED = "misaligned"

    @classmethod
    def parse(cls, name: "str | Scene") -> "Scene":
        """The scene called ``name``; ConfigError naming the known ones otherwise."""
        try:
            return cls(name)
        except ValueError:
            raise ConfigError(f"unknown scene {name!r}; known: {', '.join(s.value for s in cls)}") from None


if {s.value for s in Scene} != {"lab", "wall", "board", *CLASSES}:
    raise ImportError("Scene's members and scene_classes.CLASSES disagree")  # one member per class


def moving_primitives(scene: Scene) -> np.ndarray:
    """Indices of the rows of ``primitives(scene, t)`` that change with ``t``; the renderer keeps
    the view of the others per format (it checks they really stayed the same, so a wrong entry
    here costs speed, never exactness)."""
    moving = CLASSES[scene.value].moving if scene.value in CLASSES else _MOVING.get(scene, ())
    return np.array(moving, np.int64)


def photometry(scene: Scene) -> Photometry:
    """The scene's light beyond the shared exposure (the plain one for lab, wall and board)."""
    return CLASSES[scene.value].photometry if scene.value in CLASSES else PLAIN


def right_turn(scene: Scene) -> np.ndarray:
    """How far the right imager is turned off the pose its calibration holds (3x3; the identity
    but for a misaligned class)."""
    return CLASSES[scene.value].right_turn() if scene.value in CLASSES else np.eye(3)


def primitives(scene: Scene, t: float) -> np.ndarray:
    """The scene's primitives at time ``t`` seconds, as an (N, PRIM_FIELDS) float64 array (the
    board is rendered by ``calibration.board``, not from primitives)."""
    if scene.value in CLASSES:
        return CLASSES[scene.value].build(t)
    if scene == Scene.WALL:
        rows = [rect((0.0, 0.0, WALL_DISTANCE_M), (1, 0, 0), (0, 1, 0), 20.0, 20.0)]
    elif scene == Scene.LAB:
        w = 2 * math.pi / 8.0  # slow, smooth motion: an 8 s cycle
        rows = [
            rect((0.0, 0.0, 4.0), (1, 0, 0), (0, 1, 0), 6.0, 4.0, albedo=0.5, texscale=512.0),
            rect((0.0, 0.9, 2.5), (1, 0, 0), (0, 0, 1), 6.0, 2.0, albedo=0.4, texoff=100.0, texscale=768.0),
            rect((-0.45 + 0.25 * math.sin(w * t), -0.15, 2.2), (1, 0, 0), (0, 1, 0), 0.35, 0.45,
                  albedo=0.6, texoff=200.0),
            rect((0.55, 0.1, 1.6), (math.cos(0.6), 0, math.sin(0.6)), (0, 1, 0), 0.25, 0.35,
                  albedo=0.55, texoff=300.0),
            sphere((0.05, 0.2, 1.6 + 0.4 * math.sin(0.7 * w * t)), 0.22, texoff=400.0),
        ]
    else:
        raise ValueError(f"no primitives for scene {scene!r}")
    return np.array(rows, dtype=np.float64)


_MOVING: dict[Scene, tuple[int, ...]] = {Scene.LAB: (2, 4)}  # rows of primitives() that move
