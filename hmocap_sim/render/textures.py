"""Procedural textures evaluated on the interpolated world position (no image files needed).

Value noise and fractal noise on an integer lattice hash, and material patterns built from
them: wooden floor planks, tiles with grout, mottled wall plaster, fabric with wrinkles and
weave, plain paint, and an image atlas looked up with per-vertex UVs. Everything is a
deterministic function of position and a per-material seed, so frames repeat bit for bit.
Colours are sRGB in [0, 1]; the shader converts to linear light.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

KIND_PLAIN = 0
KIND_WOOD = 1
KIND_TILES = 2
KIND_PLASTER = 3
KIND_FABRIC = 4
KIND_IMAGE = 5
KINDS = {"plain": KIND_PLAIN, "wood": KIND_WOOD, "tiles": KIND_TILES, "plaster": KIND_PLASTER,
         "fabric": KIND_FABRIC, "image": KIND_IMAGE}


@nb.njit(cache=True, nogil=True)
def hash3(ix, iy, iz, seed):
    """Integer lattice hash -> float in [0, 1) (int64 arithmetic wraps, by design)."""
    h = (np.int64(ix) * 73856093) ^ (np.int64(iy) * 19349663) ^ (np.int64(iz) * 83492791) \
        ^ (np.int64(seed) * 2654435761)
    h = (h ^ (h >> 13)) * 1274126177
    h = h ^ (h >> 16)
    h = (h ^ (h >> 7)) * 668265263
    return np.float64((h >> 8) & 0xFFFFFF) / 16777216.0


@nb.njit(cache=True, nogil=True)
def value_noise3(x, y, z, seed):
    """Smooth value noise in [0, 1) with unit lattice spacing."""
    fx = math.floor(x)
    fy = math.floor(y)
    fz = math.floor(z)
    ix = np.int64(fx)
    iy = np.int64(fy)
    iz = np.int64(fz)
    tx = x - fx
    ty = y - fy
    tz = z - fz
    tx = tx * tx * (3.0 - 2.0 * tx)
    ty = ty * ty * (3.0 - 2.0 * ty)
    tz = tz * tz * (3.0 - 2.0 * tz)
    c000 = hash3(ix, iy, iz, seed)
    c100 = hash3(ix + 1, iy, iz, seed)
    c010 = hash3(ix, iy + 1, iz, seed)
    c110 = hash3(ix + 1, iy + 1, iz, seed)
    c001 = hash3(ix, iy, iz + 1, seed)
    c101 = hash3(ix + 1, iy, iz + 1, seed)
    c011 = hash3(ix, iy + 1, iz + 1, seed)
    c111 = hash3(ix + 1, iy + 1, iz + 1, seed)
    a = c000 + tx * (c100 - c000)
    b = c010 + tx * (c110 - c010)
    c = c001 + tx * (c101 - c001)
    d = c011 + tx * (c111 - c011)
    e = a + ty * (b - a)
    f = c + ty * (d - c)
    return e + tz * (f - e)


@nb.njit(cache=True, nogil=True)
def value_noise2(x, y, seed):
    """Smooth 2D value noise in [0, 1) (half the cost of :func:`value_noise3`)."""
    fx = math.floor(x)
    fy = math.floor(y)
    ix = np.int64(fx)
    iy = np.int64(fy)
    tx = x - fx
    ty = y - fy
    tx = tx * tx * (3.0 - 2.0 * tx)
    ty = ty * ty * (3.0 - 2.0 * ty)
    c00 = hash3(ix, iy, 0, seed)
    c10 = hash3(ix + 1, iy, 0, seed)
    c01 = hash3(ix, iy + 1, 0, seed)
    c11 = hash3(ix + 1, iy + 1, 0, seed)
    a = c00 + tx * (c10 - c00)
    b = c01 + tx * (c11 - c01)
    return a + ty * (b - a)


@nb.njit(cache=True, nogil=True)
def fbm2(x, y, octaves, seed):
    """Fractal 2D value noise in [0, 1]."""
    total = 0.0
    amp = 0.5
    norm = 0.0
    for o in range(octaves):
        total += amp * value_noise2(x, y, seed + o)
        norm += amp
        x = x * 2.03 + 17.1
        y = y * 2.03 + 31.7
        amp *= 0.5
    return total / norm


@nb.njit(cache=True, nogil=True)
def fbm3(x, y, z, octaves, seed):
    """Fractal (fBm) value noise in [0, 1]: ``octaves`` octaves, gain 0.5, lacunarity ~2."""
    total = 0.0
    amp = 0.5
    norm = 0.0
    for o in range(octaves):
        total += amp * value_noise3(x, y, z, seed + o)
        norm += amp
        x = x * 2.03 + 17.1
        y = y * 2.03 + 31.7
        z = z * 2.03 + 5.3
        amp *= 0.5
    return total / norm


@nb.njit(cache=True, nogil=True)
def _clamp01(v):
    return min(max(v, 0.0), 1.0)


@nb.njit(cache=True, nogil=True)
def wood_planks(u, v, r1, g1, b1, r2, g2, b2, width, seed):
    """Floor planks along u (width ``width`` m, length 6 widths, staggered rows): per-plank
    tone between colour 1 (light) and colour 2 (dark), grain streaks and rings, dark seams."""
    length = 6.0 * width
    row = math.floor(v / width)
    lv = v - row * width
    uu = u + hash3(row, 3, 5, seed) * length
    col = math.floor(uu / length)
    lu = uu - col * length
    irow = np.int64(row)
    icol = np.int64(col)
    tone = hash3(irow, icol, 11, seed)
    # Grain: streaks along the plank (slow along u, fast across v), warped so they meander,
    # plus growth rings seen as bands; each plank gets its own tone and grain offset.
    warp = fbm2(u * 1.1 + 4.0 + tone * 20.0, lv * 5.0, 2, seed + 13)
    grain = fbm2(u * 1.5 + col * 3.1, (lv + 0.01 * warp) * 160.0 + tone * 50.0, 3, seed + 7)
    rings = 0.5 + 0.5 * math.sin(2.0 * math.pi * (lv * 18.0 + 4.0 * warp + tone * 5.0))
    t = _clamp01(0.2 + 0.4 * tone + 0.7 * (grain - 0.5) + 0.2 * rings * rings)
    r = r1 + t * (r2 - r1)
    g = g1 + t * (g2 - g1)
    b = b1 + t * (b2 - b1)
    # Seams: darken within a few millimetres of a plank edge, fading out smoothly.
    edge = min(lv, width - lv, lu, length - lu)
    seam = 0.55 + 0.45 * _clamp01(edge / 0.004)
    return r * seam, g * seam, b * seam


@nb.njit(cache=True, nogil=True)
def tiles(u, v, r1, g1, b1, r2, g2, b2, size, amp, seed):
    """Square tiles of side ``size`` (colour 1) with grout lines (colour 2), a slight
    per-tile variation and ``amp`` of fine mottling."""
    fu = math.floor(u / size)
    fv = math.floor(v / size)
    lu = u - fu * size
    lv = v - fv * size
    grout = 0.035 * size
    if min(lu, lv, size - lu, size - lv) < 0.5 * grout:
        return r2, g2, b2
    k = 0.93 + 0.14 * hash3(np.int64(fu), np.int64(fv), 23, seed)
    k *= 1.0 + amp * 2.0 * (fbm2(u * 20.0 / size, v * 20.0 / size, 3, seed) - 0.5)
    return r1 * k, g1 * k, b1 * k


@nb.njit(cache=True, nogil=True)
def plaster(u, v, r1, g1, b1, r2, g2, b2, scale, amp, seed):
    """Mottled wall paint on planar coordinates (u, v): cloudy blotches of size ~``scale`` m
    between colour 1 and colour 2, plus fine grain of relative amplitude ``amp``."""
    t = fbm2(u / scale, v / scale, 5, seed)
    t = _clamp01((t - 0.5) * 2.2 + 0.5)
    fine = 1.0 + amp * 2.0 * (value_noise2(u * 150.0, v * 150.0, seed + 3) - 0.5)
    return ((r1 + t * (r2 - r1)) * fine, (g1 + t * (g2 - g1)) * fine,
            (b1 + t * (b2 - b1)) * fine)


@nb.njit(cache=True, nogil=True)
def fabric(x, y, z, u, v, r, g, b, scale, amp, seed):
    """Cloth: soft wrinkle shading (folds ~``scale`` m) of relative amplitude ``amp`` and a
    faint fine-grained texture (a real weave would only alias at camera resolutions)."""
    w = fbm3(x / scale, y / scale, z / scale, 3, seed)
    grain = value_noise3(u * 120.0, v * 120.0, 0.5, seed + 5)
    k = 1.0 + amp * (2.0 * (w - 0.5)) + 0.06 * (grain - 0.5)
    return r * k, g * k, b * k


@nb.njit(cache=True, nogil=True)
def atlas_bilinear(atlas, s, t):
    """Bilinear lookup of an ``(h, w, 3)`` float atlas at UV ``(s, t)`` in [0, 1] (s to the
    right, t down, wrapping)."""
    h = atlas.shape[0]
    w = atlas.shape[1]
    x = (s - math.floor(s)) * w - 0.5
    y = (t - math.floor(t)) * h - 0.5
    x0 = math.floor(x)
    y0 = math.floor(y)
    fx = x - x0
    fy = y - y0
    ix0 = np.int64(x0) % w
    iy0 = np.int64(y0) % h
    ix1 = (ix0 + 1) % w
    iy1 = (iy0 + 1) % h
    out0 = 0.0
    out1 = 0.0
    out2 = 0.0
    for c in range(3):
        a = atlas[iy0, ix0, c] + fx * (atlas[iy0, ix1, c] - atlas[iy0, ix0, c])
        b = atlas[iy1, ix0, c] + fx * (atlas[iy1, ix1, c] - atlas[iy1, ix0, c])
        val = a + fy * (b - a)
        if c == 0:
            out0 = val
        elif c == 1:
            out1 = val
        else:
            out2 = val
    return out0, out1, out2
