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
driving      a street at 1:8 scale (the rig 20 cm above the road, as a car's 1.65 m is to its 0.54 m
             baseline): asphalt seen at a grazing angle, disparity growing downwards to ~100 px,
             lane marks, kerbs, facades along the street, cars, poles, far trees, a bright sky
clutter      forty boxes, boards, balls and tubes at 0.7-3.5 m in front of each other
misaligned   the everyday scene with the right imager turned off its rectified pose (pitch and roll, as
             a unit whose calibration drifted): its rows 0.2-1.0 px off the left's at 640x480

Depths keep every disparity below ``SceneClass.disparities`` (64 but for driving's 128) at 640x480
on the ideal rig of ``stereo_pair`` (f = 480 px, B = 8 cm). ``build(t, seed)`` gives the rows at
scene time ``t``; ``moving`` names the rows that change with ``t``; the placement drawn from ``seed``
never depends on ``t``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .photometry import PLAIN, Photometry
from .shapes import cylinder, rect, sphere

Rows = list[list[float]]
DISPARITIES_WIDTH = 640  # the image width SceneClass.disparities is given for
X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


@dataclass(frozen=True)
class SceneClass:
    """One class: its rows as a function of (time, seed), which of them move, its photometry, and
    how far the right imager is turned off its rectified pose."""

    name: str
    summary: str
    rows: Callable[[float, np.random.Generator], Rows]
    moving: tuple[int, ...] = ()
    photometry: Photometry = field(default=PLAIN)
    disparities: int = 64  # a matcher's disparity range for the class at DISPARITIES_WIDTH (scales with the width)
    right_turn_rad: tuple[float, float] = (0.0, 0.0)  # the right imager's pitch (about x) and roll (about z)

    def right_turn(self) -> np.ndarray:
        """The right imager's rotation off its rectified pose (its camera frame -> the rectified
        one), 3x3 float64: the identity for every class but a misaligned one."""
        pitch, roll = self.right_turn_rad
        cp, sp, cr, sr = math.cos(pitch), math.sin(pitch), math.cos(roll), math.sin(roll)
        return np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]]) @ np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])

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


def _everyday(t: float, rng: np.random.Generator) -> Rows:
    """Everyday geometry for the photometric classes: boxes, a slanted board, a ball."""
    return _backdrop(rng) + [
        rect((-0.6, 0.0, 2.4), X, Y, 0.45, 0.6, albedo=0.55, texoff=rng.uniform(0, 512)),
        rect((0.6, 0.1, 1.7), (math.cos(0.6), 0, math.sin(0.6)), Y, 0.3, 0.35, albedo=0.6,
             texoff=rng.uniform(0, 512)),
        sphere((0.05, 0.25, 1.5), 0.2, texoff=rng.uniform(0, 512)),
    ]


SCALE = 0.12  # driving: model metres per street metre (camera height 1.65 m -> 0.2 m)
ROAD_Y = 1.65 * SCALE  # the road plane, below the cameras (y down)
KERB_Y = ROAD_Y - 0.15 * SCALE  # the pavements' top
STREET_HALF = 7.0 * SCALE  # road edge: two lanes each way
FACADE_X = 9.5 * SCALE
STREET_END = 75.0 * SCALE  # where the road meets the far trees
SKY_Z = 1000.0  # the sky: a bright, nearly blank plane at ~0.04 px


def _driving(t: float, rng: np.random.Generator) -> Rows:
    """A street seen from a car: the road at a grazing angle, marks, kerbs, facades, parked and
    moving cars (boxes), poles and a far tree line under a bright sky; street metres * SCALE."""
    s, end = SCALE, STREET_END
    rows = [rect((0.0, -30.0, SKY_Z), X, Y, 2000.0, 1000.0, albedo=0.95, contrast=0.03, texscale=2.0,
                 texoff=rng.uniform(0, 512)),
            rect((0.0, ROAD_Y, end / 2), X, Z, FACADE_X + 1.0, end / 2, albedo=0.32, contrast=0.35,
                 texscale=4096.0, texoff=rng.uniform(0, 512)),  # asphalt: fine grain
            rect((0.0, ROAD_Y - 12 * s, end), X, Y, 80 * s, 12 * s, albedo=0.3, contrast=0.5, texscale=48.0,
                 texoff=rng.uniform(0, 512))]  # the tree line at the street's end
    for side in (-1, 1):
        rows.append(rect((side * (STREET_HALF + FACADE_X) / 2, KERB_Y, end / 2), X, Z, (FACADE_X - STREET_HALF) / 2,
                         end / 2, albedo=0.5, contrast=0.3, texscale=1024.0, texoff=rng.uniform(0, 512)))
        rows.append(rect((side * STREET_HALF, (ROAD_Y + KERB_Y) / 2, end / 2), Z, Y, end / 2, (ROAD_Y - KERB_Y) / 2,
                         albedo=0.6, contrast=0.2, texscale=1024.0, texoff=rng.uniform(0, 512)))  # the kerb
        rows.append(rect((side * (STREET_HALF - 0.3 * s), ROAD_Y - 1e-4, end / 2), X, Z, 0.075 * s, end / 2,
                         albedo=0.85, contrast=0.1, texoff=rng.uniform(0, 512)))  # the edge line
        z = 0.0
        while z < end:  # facades of 6-20 m, their height and setback varying
            length, height = rng.uniform(6, 20) * s, rng.uniform(8, 20) * s
            x = side * (FACADE_X + rng.uniform(0, 1.5) * s)
            rows.append(rect((x, KERB_Y - height / 2, z + length / 2), Z, Y, length / 2, height / 2,
                             albedo=rng.uniform(0.3, 0.7), contrast=rng.uniform(0.2, 0.5),
                             texscale=rng.choice([256.0, 1024.0]), texoff=rng.uniform(0, 512)))
            z += length
    for k in range(int(end / (9 * s))):  # the centre line: 3 m dashes every 9 m
        rows.append(rect((0.0, ROAD_Y - 1e-4, (9 * k + 3) * s), X, Z, 0.075 * s, 1.5 * s, albedo=0.85,
                         contrast=0.1, texoff=rng.uniform(0, 512)))
    for _ in range(5):  # cars: back, side and roof of a 4.2 x 1.8 x 1.5 m box
        x = rng.choice([-5.25, -1.75, 1.75, 5.25]) * s + rng.uniform(-0.4, 0.4) * s
        z, hl, hw, hh = rng.uniform(4, 40) * s, 2.1 * s, 0.9 * s, 0.75 * s
        yc, near = ROAD_Y - 0.3 * s - hh, -1 if x > 0 else 1  # the side facing the camera's axis
        albedo, tex = rng.uniform(0.15, 0.8), rng.uniform(0, 512)
        rows += [rect((x, yc, z), X, Y, hw, hh, albedo=albedo, contrast=0.1, texoff=tex),
                 rect((x + near * hw, yc, z + hl), Z, Y, hl, hh, albedo=albedo * 0.9, contrast=0.1, texoff=tex),
                 rect((x, yc - hh, z + hl), X, Z, hw, hl, albedo=albedo * 1.1, contrast=0.1, texoff=tex),
                 rect((x, yc - 0.25 * hh, z - 1e-3), X, Y, 0.8 * hw, 0.35 * hh, albedo=0.08, contrast=0.3,
                      texoff=tex)]  # the rear window
    for _ in range(8):  # lamp posts and sign poles, 12-24 cm, on the pavements
        x = rng.choice([-1, 1]) * (STREET_HALF + rng.uniform(0.5, 1.5) * s)
        z, height = rng.uniform(5, 40) * s, rng.uniform(3, 7) * s
        rows.append(cylinder((x, KERB_Y - height / 2, z), Y, rng.uniform(0.06, 0.12) * s, height / 2,
                             albedo=rng.uniform(0.2, 0.6), contrast=0.2, texoff=rng.uniform(0, 512)))
    return rows


def _cluttered(t: float, rng: np.random.Generator) -> Rows:
    """Forty objects at 0.7-3.5 m, many in front of each other: boxes facing the camera or turned,
    balls and upright tubes, each with its own print."""
    rows = _backdrop(rng)
    for _ in range(40):
        z = rng.uniform(0.7, 3.5)
        c = (rng.uniform(-0.6, 0.6) * z, rng.uniform(-0.45, 0.45) * z, z)
        size = rng.uniform(0.03, 0.25) * (0.5 + z / 3.5)
        look = dict(albedo=rng.uniform(0.2, 0.8), contrast=rng.uniform(0.2, 0.6),
                    texscale=rng.choice([512.0, 1024.0, 2048.0]), texoff=rng.uniform(0, 512))
        kind = rng.integers(4)
        if kind == 0:
            rows.append(rect(c, X, Y, size, size * rng.uniform(0.4, 1.5), **look))
        elif kind == 1:
            yaw = rng.uniform(-1.2, 1.2)
            rows.append(rect(c, (math.cos(yaw), 0, math.sin(yaw)), Y, size, size * rng.uniform(0.4, 1.5), **look))
        elif kind == 2:
            rows.append(sphere(c, size * 0.7, **look))
        else:
            rows.append(cylinder(c, Y, size * 0.3, size * rng.uniform(1, 2.5), **look))
    return rows


SWEEP_PERIOD_S = 2.0


def _motion(t: float, rng: np.random.Generator) -> Rows:
    w = 2 * math.pi / SWEEP_PERIOD_S  # fastest (1.6 m/s across) at t = 0
    return _everyday(t, rng) + [
        rect((-0.2 + 0.5 * math.sin(w * t), -0.2, 1.3), X, Y, 0.2, 0.25, albedo=0.65, texoff=300.0),
        sphere((0.4 - 0.3 * math.sin(w * t), -0.35, 1.9), 0.15, texoff=400.0),
    ]


CLASSES: dict[str, SceneClass] = {c.name: c for c in (
    SceneClass("slanted", "planes at 35-60 degrees", _slanted),
    SceneClass("curved", "spheres, a pillar and a pipe", _curved),
    SceneClass("thin", "fence slats, poles and wires a few pixels wide", _thin),
    SceneClass("low-texture", "large walls at 2 % print contrast", _low_texture),
    SceneClass("repetitive", "a brick wall and a print repeating every 31 px", _repetitive),
    SceneClass("exposure", "right eye +30 % gain, +10 DN black level", _everyday,
               photometry=Photometry(right_gain=1.3, right_offset=10 / 255)),
    SceneClass("vignetting", "60 % light loss in the corners", _everyday, photometry=Photometry(vignetting=0.6)),
    SceneClass("noise", "dim light, 2.5x sensor noise", _everyday, photometry=Photometry(light=0.35, noise=2.5)),
    SceneClass("motion-blur", "a panel and a ball sweeping across a 16 ms exposure", _motion, moving=(5, 6),
               photometry=Photometry(blur_s=0.016)),
    SceneClass("driving", "a street: road at a grazing angle, cars, poles, facades, sky", _driving,
               photometry=Photometry(right_gain=1.06, right_offset=-3 / 255, vignetting=0.3), disparities=128),
    SceneClass("clutter", "forty objects at many depths in front of each other", _cluttered),
    # 0.6 px at the centre (f = 480 px at 640x480), +-0.4 px more at the left and right edges
    SceneClass("misaligned", "the right imager's rows 0.2-1.0 px off (calibration drift)", _everyday,
               right_turn_rad=(0.6 / 480, 0.4 / 320)),
)}
"""name -> class; the simulator's ``Scene`` has one member per entry (scene.py)."""
