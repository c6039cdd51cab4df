"""Ray-cast renderer: one camera's view of a scene of textured rectangles and spheres.

Primitives: rectangles, spheres and open cylinders (a tube: its outside, and its inside through an
open end). Every pixel casts the ray its lens gives it (``rays``: camera-frame directions with z = 1, so an
ideal pinhole and a distorted lens use the same kernel), hits the nearest primitive, samples the
primitive's printed texture from a mip pyramid at the pixel's footprint (so the image is band-
limited like a real optical image, and both eyes see the same surface), shades it Lambertian, and
records the hit depth along the camera's optical axis. Sensor noise is added by ``sensor.py``.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

# primitive record layout (float64 row)
KIND, CX, CY, CZ, A1X, A1Y, A1Z, A2X, A2Y, A2Z, H1, H2, ALBEDO, CONTRAST, TEXSCALE, TEXOFF, NX, NY, NZ = range(19)
PRIM_FIELDS = 19
RECT, SPHERE, CYLINDER = 0.0, 1.0, 2.0  # a cylinder: axis A1, radius H1, half-length H2, seam A2


@nb.njit(cache=True, inline="always")
def _bilinear(data, off, side, u, v):
    u -= 0.5
    v -= 0.5
    fu = math.floor(u)
    fv = math.floor(v)
    au = u - fu
    av = v - fv
    mask = side - 1  # sides are powers of two: wrap with a mask
    iu = int(fu) & mask
    iv = int(fv) & mask
    ju = (iu + 1) & mask
    jv = (iv + 1) & mask
    a = data[off + iv * side + iu]
    b = data[off + iv * side + ju]
    c = data[off + jv * side + iu]
    d = data[off + jv * side + ju]
    return (a * (1 - au) + b * au) * (1 - av) + (c * (1 - au) + d * au) * av


@nb.njit(cache=True, inline="always")
def _sample(data, offsets, side0, u, v, footprint_texels):
    """Trilinear mip lookup at texel coords (u, v) of level 0."""
    nlev = offsets.shape[0] - 1
    lod = math.log2(footprint_texels) if footprint_texels > 1.0 else 0.0
    if lod > nlev - 1.001:
        lod = nlev - 1.001
    l0 = int(lod)
    t = lod - l0
    s0 = side0 >> l0
    s1 = side0 >> (l0 + 1)
    k0 = float(1 << l0)
    x0 = _bilinear(data, offsets[l0], s0, u / k0, v / k0)
    x1 = _bilinear(data, offsets[l0 + 1], s1, u / (2 * k0), v / (2 * k0))
    return x0 * (1 - t) + x1 * t


@nb.njit(cache=True, inline="always")
def _direction(rays, rot, y, x):
    """World-frame direction of pixel (y, x)'s ray."""
    rx, ry, rz = rays[y, x, 0], rays[y, x, 1], rays[y, x, 2]
    dx = rot[0, 0] * rx + rot[0, 1] * ry + rot[0, 2] * rz
    dy = rot[1, 0] * rx + rot[1, 1] * ry + rot[1, 2] * rz
    dz = rot[2, 0] * rx + rot[2, 1] * ry + rot[2, 2] * rz
    return dx, dy, dz


@nb.njit(cache=True, inline="always")
def _intersect(prims, i, origin, dx, dy, dz):
    """Ray parameter of the hit on primitive ``i``; inf for a miss (or a hit at t <= 1e-6)."""
    px = prims[i, CX] - origin[0]
    py = prims[i, CY] - origin[1]
    pz = prims[i, CZ] - origin[2]
    if prims[i, KIND] == RECT:
        nx, ny, nz = prims[i, NX], prims[i, NY], prims[i, NZ]
        den = nx * dx + ny * dy + nz * dz
        if abs(den) < 1e-12:
            return np.inf
        t = (nx * px + ny * py + nz * pz) / den
        if t <= 1e-6:
            return np.inf
        qx, qy, qz = t * dx - px, t * dy - py, t * dz - pz
        s1 = qx * prims[i, A1X] + qy * prims[i, A1Y] + qz * prims[i, A1Z]
        s2 = qx * prims[i, A2X] + qy * prims[i, A2Y] + qz * prims[i, A2Z]
        if abs(s1) <= prims[i, H1] and abs(s2) <= prims[i, H2]:
            return t
        return np.inf
    if prims[i, KIND] == CYLINDER:
        return _cylinder_hit(prims, i, px, py, pz, dx, dy, dz)
    r = prims[i, H1]
    a = dx * dx + dy * dy + dz * dz
    b = dx * px + dy * py + dz * pz
    disc = b * b - a * (px * px + py * py + pz * pz - r * r)
    if disc < 0:
        return np.inf
    t = (b - math.sqrt(disc)) / a
    return t if t > 1e-6 else np.inf


@nb.njit(cache=True, inline="always")
def _cylinder_hit(prims, i, px, py, pz, dx, dy, dz):
    """Nearest ray parameter on cylinder ``i``'s side within its length (``p``: centre - origin)."""
    ax, ay, az = prims[i, A1X], prims[i, A1Y], prims[i, A1Z]
    da = dx * ax + dy * ay + dz * az
    pa = px * ax + py * ay + pz * az
    wx, wy, wz = dx - da * ax, dy - da * ay, dz - da * az  # components across the axis
    qx, qy, qz = px - pa * ax, py - pa * ay, pz - pa * az
    a = wx * wx + wy * wy + wz * wz
    if a < 1e-18:
        return np.inf
    b = wx * qx + wy * qy + wz * qz
    r = prims[i, H1]
    disc = b * b - a * (qx * qx + qy * qy + qz * qz - r * r)
    if disc < 0:
        return np.inf
    root = math.sqrt(disc)
    for t in ((b - root) / a, (b + root) / a):  # the outside, else the inside through an open end
        if t > 1e-6 and abs(t * da - pa) <= prims[i, H2]:
            return t
    return np.inf


@nb.njit(cache=True, inline="always")
def _shade(rays, y, x, origin, dx, dy, dz, prims, hit, best, tex, tex_off, tex_side, light):
    """Radiance of the hit at ray parameter ``best`` on primitive ``hit``."""
    w = rays.shape[1]
    # hit point relative to the primitive centre, surface normal, texture coordinates
    qx = best * dx + origin[0] - prims[hit, CX]
    qy = best * dy + origin[1] - prims[hit, CY]
    qz = best * dz + origin[2] - prims[hit, CZ]
    if prims[hit, KIND] == RECT:
        s1 = qx * prims[hit, A1X] + qy * prims[hit, A1Y] + qz * prims[hit, A1Z]
        s2 = qx * prims[hit, A2X] + qy * prims[hit, A2Y] + qz * prims[hit, A2Z]
        nx, ny, nz = prims[hit, NX], prims[hit, NY], prims[hit, NZ]
    elif prims[hit, KIND] == CYLINDER:
        r = prims[hit, H1]
        s2 = qx * prims[hit, A1X] + qy * prims[hit, A1Y] + qz * prims[hit, A1Z]  # along the axis
        nx = (qx - s2 * prims[hit, A1X]) / r
        ny = (qy - s2 * prims[hit, A1Y]) / r
        nz = (qz - s2 * prims[hit, A1Z]) / r
        c2 = nx * prims[hit, A2X] + ny * prims[hit, A2Y] + nz * prims[hit, A2Z]
        c3 = nx * prims[hit, NX] + ny * prims[hit, NY] + nz * prims[hit, NZ]  # NX..NZ: A1 x A2
        s1 = r * math.atan2(c3, c2)
    else:
        r = prims[hit, H1]
        nx, ny, nz = qx / r, qy / r, qz / r
        s1 = r * math.atan2(nx, -nz)
        s2 = r * math.asin(min(1.0, max(-1.0, ny)))
    dn = math.sqrt(dx * dx + dy * dy + dz * dz)
    cosv = abs(nx * dx + ny * dy + nz * dz) / dn
    # footprint of one pixel on the surface, in texels (ray spacing ~ 1/f per unit z)
    pix = rays[y, min(x + 1, w - 1), 0] - rays[y, max(x - 1, 0), 0]
    pix = abs(pix) * 0.5 if w > 1 else 1e-3
    foot = best * dn * pix / max(cosv, 0.2) * prims[hit, TEXSCALE]
    u = s1 * prims[hit, TEXSCALE] + prims[hit, TEXOFF]
    v = s2 * prims[hit, TEXSCALE] + prims[hit, TEXOFF]
    texel = _sample(tex, tex_off, tex_side, u, v, foot)
    albedo = prims[hit, ALBEDO] * (1.0 + prims[hit, CONTRAST] * texel)
    albedo = min(1.0, max(0.02, albedo))
    lam = -(nx * light[0] + ny * light[1] + nz * light[2])
    if nx * dx + ny * dy + nz * dz > 0:  # normal faces away from the camera: flip
        lam = -lam
    return albedo * (0.45 + 0.55 * max(0.0, lam))


@nb.njit(cache=True, parallel=True, nogil=True)
def render_radiance(rays, origin, rot, prims, tex, tex_off, tex_side, light, out_rad, out_depth):
    """Fill ``out_rad`` (scene radiance 0..1) and ``out_depth`` (z in this camera, inf = no hit).

    ``rot`` maps camera-frame directions to the world frame; ``origin`` is the camera centre.
    The nearest hit wins; of equally near hits, the primitive listed first.
    """
    h, w = out_rad.shape
    n = prims.shape[0]
    for y in nb.prange(h):
        for x in range(w):
            dx, dy, dz = _direction(rays, rot, y, x)
            best = np.inf
            hit = -1
            for i in range(n):
                t = _intersect(prims, i, origin, dx, dy, dz)
                if t < best:
                    best = t
                    hit = i
            if hit < 0:
                out_rad[y, x] = 0.0
                out_depth[y, x] = np.inf
                continue
            out_rad[y, x] = _shade(rays, y, x, origin, dx, dy, dz, prims, hit, best, tex, tex_off, tex_side,
                                   light)
            out_depth[y, x] = best * rays[y, x, 2]  # depth along this camera's optical axis


@nb.njit(cache=True, parallel=True, nogil=True)
def render_layer(rays, origin, rot, prims, subset, tex, tex_off, tex_side, light, out_rad, out_t, out_hit):
    """``render_radiance`` restricted to the primitives ``subset`` (increasing indices into
    ``prims``), keeping each pixel's hit (ray parameter ``out_t``, primitive ``out_hit``, -1 and
    inf for none): the view of a scene's static part, which ``render_over`` completes per frame."""
    h, w = out_rad.shape
    for y in nb.prange(h):
        for x in range(w):
            dx, dy, dz = _direction(rays, rot, y, x)
            best = np.inf
            hit = -1
            for k in range(subset.shape[0]):
                t = _intersect(prims, subset[k], origin, dx, dy, dz)
                if t < best:
                    best = t
                    hit = subset[k]
            out_t[y, x] = best
            out_hit[y, x] = hit
            out_rad[y, x] = 0.0 if hit < 0 else _shade(rays, y, x, origin, dx, dy, dz, prims, hit, best, tex,
                                                        tex_off, tex_side, light)


TILE = 16  # pixels per side of the tiles render_over culls moving primitives on


def ray_cones(rays: np.ndarray) -> np.ndarray:
    """Per ``TILE`` x ``TILE`` block of a ray table: the cone holding all its rays, as
    (unit axis x, y, z, half-angle in radians), shape (ceil(H/tile), ceil(W/tile), 4)."""
    h, w = rays.shape[:2]
    tile = TILE
    nty, ntx = -(-h // tile), -(-w // tile)
    padded = np.full((nty * tile, ntx * tile, 3), np.nan)
    padded[:h, :w] = rays / np.linalg.norm(rays.astype(np.float64), axis=2, keepdims=True)
    blocks = padded.reshape(nty, tile, ntx, tile, 3).transpose(0, 2, 1, 3, 4).reshape(nty, ntx, tile * tile, 3)
    axis = np.nanmean(blocks, axis=2)
    axis /= np.linalg.norm(axis, axis=2, keepdims=True)
    cos = np.clip(np.einsum("yxkc,yxc->yxk", blocks, axis), -1.0, 1.0)
    half = np.nanmax(np.arccos(cos), axis=2)
    return np.ascontiguousarray(np.concatenate([axis, half[..., None]], axis=2))


@nb.njit(cache=True, inline="always")
def _may_hit(cones, ty, tx, rot, prims, i, origin):
    """False only if primitive ``i``'s bounding sphere lies clear outside tile (ty, tx)'s ray cone."""
    cx = prims[i, CX] - origin[0]
    cy = prims[i, CY] - origin[1]
    cz = prims[i, CZ] - origin[2]
    rho = prims[i, H1] if prims[i, KIND] == SPHERE else math.sqrt(prims[i, H1] ** 2 + prims[i, H2] ** 2)
    dist = math.sqrt(cx * cx + cy * cy + cz * cz)
    if dist <= rho * 1.001 + 1e-9:
        return True
    ax, ay, az = _direction(cones, rot, ty, tx)
    cos = (ax * cx + ay * cy + az * cz) / dist
    theta = math.acos(min(1.0, max(-1.0, cos)))
    return theta - math.asin(rho / dist) <= cones[ty, tx, 3] + 1e-6


@nb.njit(cache=True, parallel=True, nogil=True)
def render_over(rays, cones, origin, rot, prims, subset, base_rad, base_t, base_hit, tex, tex_off, tex_side,
                light, out_rad):
    """The radiance ``render_radiance`` gives for all of ``prims``, from the layer of the other
    primitives (``render_layer``) plus the primitives ``subset``: bit-identical, ties included.
    Tiles whose ray cone (``ray_cones``) misses a primitive's bounding sphere skip its test."""
    h, w = out_rad.shape
    nty, ntx = cones.shape[0], cones.shape[1]
    tile = TILE
    for ty in nb.prange(nty):
        active = np.empty(subset.shape[0], np.int64)
        for tx in range(ntx):
            na = 0
            for k in range(subset.shape[0]):
                if _may_hit(cones, ty, tx, rot, prims, subset[k], origin):
                    active[na] = subset[k]
                    na += 1
            for y in range(ty * tile, min((ty + 1) * tile, h)):
                for x in range(tx * tile, min((tx + 1) * tile, w)):
                    if na == 0:
                        out_rad[y, x] = base_rad[y, x]
                        continue
                    dx, dy, dz = _direction(rays, rot, y, x)
                    best = base_t[y, x]
                    hit = base_hit[y, x]
                    moved = False
                    for k in range(na):
                        i = active[k]
                        t = _intersect(prims, i, origin, dx, dy, dz)
                        if t < best or (t == best and t < np.inf and i < hit):
                            best = t
                            hit = i
                            moved = True
                    out_rad[y, x] = _shade(rays, y, x, origin, dx, dy, dz, prims, hit, best, tex, tex_off,
                                           tex_side, light) if moved else base_rad[y, x]
