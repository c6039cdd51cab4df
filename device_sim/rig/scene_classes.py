"""The scene classes a matcher is measured on, each a named, seeded arrangement of primitives with
exact truth (the ray caster's hit depth) and its own photometry:

slanted      planes at steep angles: disparity changes across every support window
curved       spheres, a pillar and a pipe: no window is fronto-parallel
thin         a fence of slats, poles and wires a few pixels wide in front of a far wall
low-texture  large walls printed at 2 % contrast: the sensor noise is most of the signal
repetitive   a brick wall (a 22 px lattice) and a panel whose print repeats every 31 px
exposure     the right eye 30 % brighter with a 10 DN black-level offset
vignetting   60 % of the light lost in the image corners, in both eyes
noise        a dim scene with 2.5 times the sensor's noise
motion-blur  a panel and a sphere sweeping across a 16 ms exposure (up to ~9 px of blur at 640x480)

Depths keep every disparity below 64 at 640x480 on the ideal rig of ``stereo_pair`` (f = 480 px,
B = 8 cm). ``build(t, seed)`` gives the rows at scene time ``t``; ``moving`` names the rows that
change with ``t``; the placement drawn from ``seed`` never depends on ``t``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .photometry import PLAIN, Photometry
from .shapes import cylinder, rect, sphere

Rows = list[list[float]]
X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


@dataclass(frozen=True)
class SceneClass:
    """One class: its rows as a function of (time, seed), which of them move, and its photometry."""

    name: str
    summary: str
    rows: Callable[[float, np.random.Generator], Rows]
    moving: tuple[int, ...] = ()
    photometry: Photometry = field(default=PLAIN)

    def build(self, t: float, seed: int = 0) -> np.ndarray:
        """The primitive table at scene time ``t`` for placement ``seed``, (N, PRIM_FIELDS) float64."""
        return np.array(self.rows(t, np.random.default_rng([0x5CE7E, seed])), np.float64)


def _backdrop(rng: np.random.Generator, contrast: float = 0.45) -> Rows:
    """A far wall (4.5 m) and a floor 1 m below the cameras."""
    return [rect((0.0, 0.0, 4.5), X, Y, 12.0, 8.0, albedo=0.5, contrast=contrast, texscale=512.0,
                 texoff=rng.uniform(0, 512)),
            rect((0.0, 1.0, 3.5), X, Z, 8.0, 3.5, albedo=0.42, contrast=contrast, texscale=768.0,
                 texoff=rng.uniform(0, 512))]


def _slanted(t: float, rng: np.random.Generator) -> Rows:
    yaw = math.radians(rng.uniform(45, 60))
    pitch = math.radians(rng.uniform(35, 50))
    return _backdrop(rng) + [
        rect((-0.15, -0.05, 2.0), (math.cos(yaw), 0, math.sin(yaw)), Y, 0.9, 0.7, albedo=0.55,
             texoff=rng.uniform(0, 512)),
        rect((0.75, 0.05, 1.5), X, (0, math.cos(pitch), -math.sin(pitch)), 0.3, 0.4, albedo=0.6,
             texoff=rng.uniform(0, 512)),
    ]


def _curved(t: float, rng: np.random.Generator) -> Rows:
    return _backdrop(rng) + [
        sphere((-0.5 + rng.uniform(-0.1, 0.1), 0.0, 1.8), 0.45, texoff=rng.uniform(0, 512)),
        sphere((0.55, -0.1 + rng.uniform(-0.1, 0.1), 1.3), 0.3, albedo=0.6, texoff=rng.uniform(0, 512)),
        sphere((0.1, 0.3, 1.0), 0.14, albedo=0.5, texoff=rng.uniform(0, 512)),
        cylinder((1.15, 0.0, 2.2 + rng.uniform(-0.2, 0.2)), Y, 0.18, 1.2, albedo=0.5, texoff=rng.uniform(0, 512)),
        cylinder((0.0, -0.75, 2.6), (1.0, 0.0, rng.uniform(-0.4, 0.4)), 0.12, 1.8, albedo=0.6,
                 texoff=rng.uniform(0, 512)),  # a pipe across the view
    ]


def _thin(t: float, rng: np.random.Generator) -> Rows:
    rows = _backdrop(rng)
    for k in range(20):  # a fence: 2.5 cm slats every 9 cm at 1.4 m
        rows.append(rect((-0.9 + 0.09 * k, 0.2, 1.4), X, Y, 0.0125, 0.3, albedo=0.7, contrast=0.3,
                         texoff=rng.uniform(0, 512)))
    for _ in range(3):  # poles, 8-20 mm
        rows.append(rect((rng.uniform(-1.3, 1.3), 0.0, rng.uniform(1.0, 2.5)), X, Y, rng.uniform(0.004, 0.01),
                         2.0, albedo=0.3, contrast=0.2, texoff=rng.uniform(0, 512)))
    for _ in range(3):  # wires, 6-10 mm
        rows.append(rect((0.0, rng.uniform(-0.8, -0.2), rng.uniform(1.2, 2.2)), X, Y, 4.0,
                         rng.uniform(0.003, 0.005), albedo=0.2, contrast=0.1, texoff=rng.uniform(0, 512)))
    return rows


def _low_texture(t: float, rng: np.random.Generator) -> Rows:
    return _backdrop(rng, contrast=0.02) + [
        rect((0.0, -0.2, 2.5), X, Y, 1.1, 0.9, albedo=0.6, contrast=0.02, texoff=rng.uniform(0, 512)),
        rect((-0.55, 0.15, 1.5), X, Y, 0.3, 0.3, albedo=0.45, contrast=0.03, texoff=rng.uniform(0, 512)),
        rect((0.6, 0.2, 1.8), X, Y, 0.12, 0.1, albedo=0.5, contrast=0.5, texoff=rng.uniform(0, 512)),  # a poster
    ]


REPEAT_TEXSCALE = 6144.0  # the 512-texel print repeats every 8.3 cm: 31 px at 1.3 m
BRICK_M = (0.09, 0.04)  # brick length and height; 1 cm mortar joints: a 22 x 11 px lattice at 2.2 m
BRICKS = (12, 14)  # columns, rows


def _repetitive(t: float, rng: np.random.Generator) -> Rows:
    """A brick wall (bricks alike but for a faint print and a few % of albedo) and a panel whose
    print repeats exactly."""
    z, (bw, bh) = 2.2, BRICK_M
    rows = _backdrop(rng) + [rect((0.0, -0.3, z + 0.01), X, Y, 0.7, 0.4, albedo=0.25, contrast=0.1,
                                  texoff=rng.uniform(0, 512))]  # the mortar behind
    for j in range(BRICKS[1]):
        for i in range(BRICKS[0]):
            x = -0.6 + (i + 0.5 * (j % 2)) * (bw + 0.01)  # every other row offset by half a brick
            rows.append(rect((x, -0.62 + j * (bh + 0.01), z), X, Y, bw / 2, bh / 2,
                             albedo=0.6 * (1 + rng.uniform(-0.04, 0.04)), contrast=0.12, texoff=rng.uniform(0, 512)))
    rows.append(rect((0.35, 0.1, 1.3), X, Y, 0.3, 0.25, albedo=0.55, contrast=0.6, texscale=REPEAT_TEXSCALE,
                     texoff=rng.uniform(0, 512)))
    return rows


def _clutter(t: float, rng: np.random.Generator) -> Rows:
    """Everyday geometry for the photometric classes: boxes, a slanted board, a ball."""
    return _backdrop(rng) + [
        rect((-0.6, 0.0, 2.4), X, Y, 0.45, 0.6, albedo=0.55, texoff=rng.uniform(0, 512)),
        rect((0.6, 0.1, 1.7), (math.cos(0.6), 0, math.sin(0.6)), Y, 0.3, 0.35, albedo=0.6,
             texoff=rng.uniform(0, 512)),
        sphere((0.05, 0.25, 1.5), 0.2, texoff=rng.uniform(0, 512)),
    ]


SWEEP_PERIOD_S = 2.0


def _motion(t: float, rng: np.random.Generator) -> Rows:
    w = 2 * math.pi / SWEEP_PERIOD_S  # fastest (1.6 m/s across) at t = 0
    return _clutter(t, rng) + [
        rect((-0.2 + 0.5 * math.sin(w * t), -0.2, 1.3), X, Y, 0.2, 0.25, albedo=0.65, texoff=300.0),
        sphere((0.4 - 0.3 * math.sin(w * t), -0.35, 1.9), 0.15, texoff=400.0),
    ]


CLASSES: dict[str, SceneClass] = {c.name: c for c in (
    SceneClass("slanted", "planes at 35-60 degrees", _slanted),
    SceneClass("curved", "spheres, a pillar and a pipe", _curved),
    SceneClass("thin", "fence slats, poles and wires a few pixels wide", _thin),
    SceneClass("low-texture", "large walls at 2 % print contrast", _low_texture),
    SceneClass("repetitive", "a brick wall and a print repeating every 31 px", _repetitive),
    SceneClass("exposure", "right eye +30 % gain, +10 DN black level", _clutter,
               photometry=Photometry(right_gain=1.3, right_offset=10 / 255)),
    SceneClass("vignetting", "60 % light loss in the corners", _clutter, photometry=Photometry(vignetting=0.6)),
    SceneClass("noise", "dim light, 2.5x sensor noise", _clutter, photometry=Photometry(light=0.35, noise=2.5)),
    SceneClass("motion-blur", "a panel and a ball sweeping across a 16 ms exposure", _motion, moving=(5, 6),
               photometry=Photometry(blur_s=0.016)),
)}
"""name -> class; the simulator's ``Scene`` has one member per entry (scene.py)."""
