"""Ray-cast renderer: one camera's view of a scene of textured rectangles and spheres.

Every pixel casts the ray its lens gives it (``rays``: camera-frame directions with z = 1, so an
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
RECT, SPHERE = 0.0, 1.0


def make_texture(seed: int, size: int = 512, levels: int = 9) -> list[np.ndarray]:
    """A tileable band-limited noise texture (zero mean, unit std) and its 2x2 mip pyramid."""
    rng = np.random.default_rng(seed)
    spec = np.fft.fft2(rng.standard_normal((size, size)))
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(size), np.fft.fftfreq(size), indexing="ij"))
    spec *= np.where(f > 0, 1.0 / np.maximum(f, 1.0 / size) ** 0.8, 0.0)  # pinkish spectrum
    tex = np.real(np.fft.ifft2(spec))
    tex = ((tex - tex.mean()) / tex.std()).astype(np.float32)
    pyramid = [tex]
    while len(pyramid) < levels and pyramid[-1].shape[0] > 1:
        t = pyramid[-1]
        pyramid.append(0.25 * (t[0::2, 0::2] + t[1::2, 0::2] + t[0::2, 1::2] + t[1::2, 1::2]))
    return pyramid


def pack_pyramid(pyramid: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Flatten a pyramid for numba: (data, offsets); level k has side size >> k."""
    offsets = np.zeros(len(pyramid) + 1, np.int64)
    for k, lev in enumerate(pyramid):
        offsets[k + 1] = offsets[k] + lev.size
    return np.concatenate([lev.ravel() for lev in pyramid]), offsets


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


@nb.njit(cache=True, parallel=True, nogil=True)
def render_radiance(rays, origin, rot, prims, tex, tex_off, tex_side, light, out_rad, out_depth):
    """Fill ``out_rad`` (scene radiance 0..1) and ``out_depth`` (z in this camera, inf = no hit).

    ``rot`` maps camera-frame directions to the world frame; ``origin`` is the camera centre.
    """
    h, w = out_rad.shape
    n = prims.shape[0]
    for y in nb.prange(h):
        for x in range(w):
            rx, ry, rz = rays[y, x, 0], rays[y, x, 1], rays[y, x, 2]
            dx = rot[0, 0] * rx + rot[0, 1] * ry + rot[0, 2] * rz
            dy = rot[1, 0] * rx + rot[1, 1] * ry + rot[1, 2] * rz
            dz = rot[2, 0] * rx + rot[2, 1] * ry + rot[2, 2] * rz
            best = np.inf
            hit = -1
            for i in range(n):
                px = prims[i, CX] - origin[0]
                py = prims[i, CY] - origin[1]
                pz = prims[i, CZ] - origin[2]
                if prims[i, KIND] == RECT:
                    nx, ny, nz = prims[i, NX], prims[i, NY], prims[i, NZ]
                    den = nx * dx + ny * dy + nz * dz
                    if abs(den) < 1e-12:
                        continue
                    t = (nx * px + ny * py + nz * pz) / den
                    if t <= 1e-6 or t >= best:
                        continue
                    qx, qy, qz = t * dx - px, t * dy - py, t * dz - pz
                    s1 = qx * prims[i, A1X] + qy * prims[i, A1Y] + qz * prims[i, A1Z]
                    s2 = qx * prims[i, A2X] + qy * prims[i, A2Y] + qz * prims[i, A2Z]
                    if abs(s1) <= prims[i, H1] and abs(s2) <= prims[i, H2]:
                        best = t
                        hit = i
                else:
                    r = prims[i, H1]
                    a = dx * dx + dy * dy + dz * dz
                    b = dx * px + dy * py + dz * pz
                    disc = b * b - a * (px * px + py * py + pz * pz - r * r)
                    if disc < 0:
                        continue
                    t = (b - math.sqrt(disc)) / a
                    if t > 1e-6 and t < best:
                        best = t
                        hit = i
            if hit < 0:
                out_rad[y, x] = 0.0
                out_depth[y, x] = np.inf
                continue
            # hit point relative to the primitive centre, surface normal, texture coordinates
            qx = best * dx + origin[0] - prims[hit, CX]
            qy = best * dy + origin[1] - prims[hit, CY]
            qz = best * dz + origin[2] - prims[hit, CZ]
            if prims[hit, KIND] == RECT:
                s1 = qx * prims[hit, A1X] + qy * prims[hit, A1Y] + qz * prims[hit, A1Z]
                s2 = qx * prims[hit, A2X] + qy * prims[hit, A2Y] + qz * prims[hit, A2Z]
                nx, ny, nz = prims[hit, NX], prims[hit, NY], prims[hit, NZ]
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
            out_rad[y, x] = albedo * (0.45 + 0.55 * max(0.0, lam))
            # depth along this camera's optical axis
            out_depth[y, x] = best * rz
