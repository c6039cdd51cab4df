"""A scene class seen by an ideal rectified rig, with exact truth: the pair a matcher is measured on.

The rig is two pinhole cameras with the simulator's nominal focal length (``truth.NOMINAL_FOCAL_PX``
scaled to the width), centred principal points and a ``PAIR_BASELINE_M`` baseline along x, so the
images are rectified by construction and the truth needs no resampling: a left pixel that sees a
surface at depth z has disparity f * B / z, exactly (the ray caster's hit). It is *occluded* when the
right camera does not see that same surface point: another surface is nearer along the right
camera's ray to it, or it falls outside the right image. A misaligned class turns the right camera
off that pose (``SceneClass.right_turn``): its rows no longer meet the left's, and the truth is the
horizontal part of where the point lands in the right image, x - x_right.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..calibration.truth import NOMINAL_FOCAL_PX, NOMINAL_WIDTH
from . import render, texture
from .photometry import Photometry
from .scene_classes import CLASSES, SceneClass
from .sensor import LIGHT, Geometry, expose

PAIR_BASELINE_M = 0.08
EXPOSURE_SCALE = 255.0  # DN at radiance 1: the sensor's reference exposure at gain 0
TEXTURE_SIDE = 512
Texture = tuple[np.ndarray, np.ndarray, int]  # the packed mip pyramid, its level offsets, its side
SAME_POINT_REL = 1e-4  # relative distance within which the right eye's hit is the point itself (float32 rays)


@dataclass(frozen=True)
class StereoPair:
    """Rectified 8-bit images and the left view's truth."""

    name: str
    left: np.ndarray
    right: np.ndarray
    disparity: np.ndarray  # float32 px, NaN where the left pixel sees no surface
    occluded: np.ndarray  # bool: a surface the right camera does not see (hidden or out of its view)
    geometry: Geometry


def ideal_geometry(width: int, height: int) -> Geometry:
    """The rectified rig the pairs are rendered with."""
    return Geometry(width, height, NOMINAL_FOCAL_PX * width / NOMINAL_WIDTH, (width - 1) / 2, (height - 1) / 2,
                    PAIR_BASELINE_M)


def scene_class(name: str) -> SceneClass:
    """The class called ``name``; ValueError naming the known ones otherwise."""
    try:
        return CLASSES[name]
    except KeyError:
        raise ValueError(f"unknown scene class {name!r}; known: {', '.join(CLASSES)}") from None


def render_pair(name: str, width: int = 640, height: int = 480, seed: int = 0, t: float = 0.0) -> StereoPair:
    """Scene class ``name`` at placement ``seed`` and scene time ``t`` (the middle of the exposure)."""
    cls = scene_class(name)
    prims = [cls.build(ti, seed) for ti in cls.photometry.instants(t)]
    return render_primitives(name, prims, cls.build(t, seed), cls.photometry, ideal_geometry(width, height), seed,
                             cls.right_turn())


def render_primitives(name: str, exposure: list[np.ndarray], at_t: np.ndarray, photometry: Photometry,
                      geometry: Geometry, seed: int, right_turn: np.ndarray | None = None) -> StereoPair:
    """The pair for primitive tables ``exposure`` (one per sub-instant the exposure averages) and
    the truth of ``at_t`` (the table at the exposure's middle); ``right_turn``: the right camera's
    rotation off the rectified pose (None: none)."""
    rays = geometry.rays()
    tex = (*texture.pack_pyramid(texture.make_texture(seed, TEXTURE_SIDE)), TEXTURE_SIDE)
    right_origin = np.array([geometry.baseline_m, 0.0, 0.0])
    origins = (np.zeros(3), right_origin)
    turned = right_turn is not None and not np.array_equal(right_turn, np.eye(3))
    eye_rots = (np.eye(3), np.ascontiguousarray(right_turn, np.float64) if turned else np.eye(3))
    shape = (geometry.height, geometry.width)
    images = []
    for eye, origin in enumerate(origins):
        rad = np.zeros(shape, np.float32)
        for prims in exposure:
            sub, depth = np.empty(shape, np.float32), np.empty(shape, np.float32)
            render.render_radiance(rays, origin, eye_rots[eye], prims, *tex, LIGHT, sub, depth)
            rad += sub
        rad = photometry.apply(rad / np.float32(len(exposure)), rays, eye)
        img = np.empty(shape, np.uint8)
        expose(rad, EXPOSURE_SCALE, (seed * 2 + eye) ^ (0x5CE7E << 32), img, photometry.noise)
        images.append(img)
    depth = _depth(rays, np.zeros(3), np.eye(3), at_t, tex)
    seen = np.isfinite(depth)
    if turned:  # the horizontal part of the correspondence: x minus the point's column in the right image
        point = rays.astype(np.float64) * np.where(seen, depth, 1.0)[..., None]
        in_right = (point - right_origin) @ eye_rots[1]  # rows: R^T (p - c), R camera -> world
        disparity = np.where(seen, geometry.focal_px * (rays[..., 0] - in_right[..., 0] / in_right[..., 2]), np.nan)
    else:
        disparity = np.where(seen, geometry.focal_px * geometry.baseline_m / np.where(seen, depth, 1.0), np.nan)
    occluded = occlusion(rays, np.eye(3), depth, disparity, right_origin, at_t, tex)
    return StereoPair(name, images[0], images[1], disparity.astype(np.float32), occluded, geometry)


def occlusion(rays: np.ndarray, rot: np.ndarray, depth: np.ndarray, disparity: np.ndarray, right_centre: np.ndarray,
              prims: np.ndarray, tex: Texture) -> np.ndarray:
    """Which pixels of a rectified left view (camera-frame ``rays`` with z = 1, camera->world ``rot``,
    hit ``depth`` along its axis, truth ``disparity``) see a surface point the right camera, centred
    at ``right_centre`` (world), does not: another surface is nearer along its ray to the point, or
    the point falls left of the right image (x - disparity < -0.5)."""
    seen = np.isfinite(depth)
    point = (rays.astype(np.float64) * np.where(seen, depth, 1.0)[..., None]) @ np.asarray(rot, np.float64).T
    to_point = point - right_centre  # world frame; z > 0 for anything in front of both cameras
    along = to_point[..., 2]
    hit = _depth((to_point / along[..., None]).astype(np.float32), right_centre, np.eye(3), prims, tex)
    hidden = hit < along * (1.0 - SAME_POINT_REL)
    outside = np.arange(depth.shape[1])[None, :] - disparity < -0.5
    return seen & (hidden | outside)


def _depth(rays: np.ndarray, origin: np.ndarray, rot: np.ndarray, prims: np.ndarray, tex: Texture) -> np.ndarray:
    """Depth along the optical axis of the nearest hit per ray (inf for none), float32."""
    rad, depth = np.empty(rays.shape[:2], np.float32), np.empty(rays.shape[:2], np.float32)
    render.render_radiance(rays, origin, np.ascontiguousarray(rot, np.float64), prims, *tex, LIGHT, rad, depth)
    return depth
