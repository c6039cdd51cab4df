"""Rows of the renderer's primitive table (``render.PRIM_FIELDS`` floats): textured rectangles and
spheres, world frame = left camera frame, metres (x right, y down, z forward)."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from . import render as R

Vec = Sequence[float]


def rect(center: Vec, a1: Vec, a2: Vec, h1: float, h2: float, albedo: float = 0.5, contrast: float = 0.45,
         texscale: float = 1024.0, texoff: float = 0.0) -> list[float]:
    """A rectangle centred at ``center`` spanning ±``h1`` along ``a1`` and ±``h2`` along ``a2`` (the
    axes are normalised); its texture is ``albedo * (1 + contrast * noise)`` at ``texscale`` texels/m."""
    row = [0.0] * R.PRIM_FIELDS
    row[R.KIND] = R.RECT
    row[R.CX:R.CZ + 1] = center
    u1 = np.asarray(a1, float) / np.linalg.norm(a1)
    u2 = np.asarray(a2, float) / np.linalg.norm(a2)
    row[R.A1X:R.A1Z + 1] = u1
    row[R.A2X:R.A2Z + 1] = u2
    row[R.NX:R.NZ + 1] = np.cross(u1, u2)
    row[R.H1], row[R.H2] = h1, h2
    row[R.ALBEDO], row[R.CONTRAST], row[R.TEXSCALE], row[R.TEXOFF] = albedo, contrast, texscale, texoff
    return row


def sphere(center: Vec, radius: float, albedo: float = 0.55, contrast: float = 0.5, texscale: float = 1024.0,
           texoff: float = 0.0) -> list[float]:
    """A sphere of ``radius`` metres centred at ``center``, textured like ``rect``."""
    row = [0.0] * R.PRIM_FIELDS
    row[R.KIND] = R.SPHERE
    row[R.CX:R.CZ + 1] = center
    row[R.H1] = radius
    row[R.ALBEDO], row[R.CONTRAST], row[R.TEXSCALE], row[R.TEXOFF] = albedo, contrast, texscale, texoff
    return row


def cylinder(center: Vec, axis: Vec, radius: float, half_length: float, seam: Vec | None = None,
             albedo: float = 0.55, contrast: float = 0.5, texscale: float = 1024.0, texoff: float = 0.0) -> list[float]:
    """An open tube of ``radius`` around ``axis`` through ``center``, ±``half_length`` along it; its
    print wraps around from ``seam`` (a direction across the axis; any one when None)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    across = (1.0, 0.0, 0.0) if abs(a[0]) < 0.9 else (0.0, 1.0, 0.0)
    s = np.cross(a, across) if seam is None else np.asarray(seam, float)
    s = s - (s @ a) * a
    s /= np.linalg.norm(s)
    row = rect(center, a, s, radius, half_length, albedo, contrast, texscale, texoff)
    row[R.KIND] = R.CYLINDER
    return row
