"""Scenes in front of the rig, as functions of time (world frame = left camera frame, metres).

A scene is a list of primitives packed for ``render.render_radiance``. What the simulated unit
looks at is a simulator setting (``SimulatedCamera(scene=...)``, ``--scene``, ``sim://?scene=``),
never a device parameter:
"lab" — back wall, floor, a sliding panel, a slanted board and a sphere moving in depth;
"wall" — one fronto-parallel textured wall at ``WALL_DISTANCE_M`` filling the view;
"board" — a chessboard a fixture moves through varied poses (rendered by ``calibration.board``;
    ``sensor.BOARD*`` give its size, pose count and dwell time).
"""
from __future__ import annotations

import enum
import math

import numpy as np

from stereocam.protocol.errors import ConfigError

from . import render as R

WALL_DISTANCE_M = 1.0


class Scene(str, enum.Enum):
    """What the simulated rig looks at."""

    LAB = "lab"
    WALL = "wall"
    BOARD = "board"

    @classmethod
    def parse(cls, name: "str | Scene") -> "Scene":
        """The scene called ``name``; ConfigError naming the known ones otherwise."""
        try:
            return cls(name)
        except ValueError:
            raise ConfigError(f"unknown scene {name!r}; known: {', '.join(s.value for s in cls)}") from None


def _rect(center, a1, a2, h1, h2, albedo=0.5, contrast=0.45, texscale=1024.0, texoff=0.0) -> list[float]:
    row = [0.0] * R.PRIM_FIELDS
    row[R.KIND] = R.RECT
    row[R.CX:R.CZ + 1] = center
    a1 = np.asarray(a1, float) / np.linalg.norm(a1)
    a2 = np.asarray(a2, float) / np.linalg.norm(a2)
    row[R.A1X:R.A1Z + 1] = a1
    row[R.A2X:R.A2Z + 1] = a2
    row[R.NX:R.NZ + 1] = np.cross(a1, a2)
    row[R.H1], row[R.H2] = h1, h2
    row[R.ALBEDO], row[R.CONTRAST], row[R.TEXSCALE], row[R.TEXOFF] = albedo, contrast, texscale, texoff
    return row


def _sphere(center, radius, albedo=0.55, contrast=0.5, texscale=1024.0, texoff=0.0) -> list[float]:
    row = [0.0] * R.PRIM_FIELDS
    row[R.KIND] = R.SPHERE
    row[R.CX:R.CZ + 1] = center
    row[R.H1] = radius
    row[R.ALBEDO], row[R.CONTRAST], row[R.TEXSCALE], row[R.TEXOFF] = albedo, contrast, texscale, texoff
    return row


def moving_primitives(scene: Scene) -> np.ndarray:
    """Indices of the rows of ``primitives(scene, t)`` that change with ``t``; the renderer keeps
    the view of the others per format (it checks they really stayed the same, so a wrong entry
    here costs speed, never exactness)."""
    return np.array(_MOVING.get(scene, ()), np.int64)


def primitives(scene: Scene, t: float) -> np.ndarray:
    """The scene's primitives at time ``t`` seconds, as an (N, PRIM_FIELDS) float64 array (the
    board is rendered by ``calibration.board``, not from primitives)."""
    if scene == Scene.WALL:
        rows = [_rect((0.0, 0.0, WALL_DISTANCE_M), (1, 0, 0), (0, 1, 0), 20.0, 20.0)]
    elif scene == Scene.LAB:
        w = 2 * math.pi / 8.0  # slow, smooth motion: an 8 s cycle
        rows = [
            _rect((0.0, 0.0, 4.0), (1, 0, 0), (0, 1, 0), 6.0, 4.0, albedo=0.5, texscale=512.0),
            _rect((0.0, 0.9, 2.5), (1, 0, 0), (0, 0, 1), 6.0, 2.0, albedo=0.4, texoff=100.0, texscale=768.0),
            _rect((-0.45 + 0.25 * math.sin(w * t), -0.15, 2.2), (1, 0, 0), (0, 1, 0), 0.35, 0.45,
                  albedo=0.6, texoff=200.0),
            _rect((0.55, 0.1, 1.6), (math.cos(0.6), 0, math.sin(0.6)), (0, 1, 0), 0.25, 0.35,
                  albedo=0.55, texoff=300.0),
            _sphere((0.05, 0.2, 1.6 + 0.4 * math.sin(0.7 * w * t)), 0.22, texoff=400.0),
        ]
    else:
        raise ValueError(f"no primitives for scene {scene!r}")
    return np.array(rows, dtype=np.float64)


_MOVING: dict[Scene, tuple[int, ...]] = {Scene.LAB: (2, 4)}  # rows of primitives() that move
