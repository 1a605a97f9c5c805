"""Slow, exact reference rasteriser (pure numpy) to check the fast ones against.

Every pixel centre inside a triangle's bounding box is tested with the three edge functions in
float64, ties resolved by the top-left rule (the same convention as
:mod:`hmocap_ros.render.scanline`, derived independently). Vectorised over (triangle, pixel)
pairs; fine for tests at small resolutions, far too slow for the tracker.
"""

from __future__ import annotations

import numpy as np


def _edge_inside(ax, ay, bx, by, px, py):
    """Inside test for one edge a->b of a triangle oriented with positive y-down cross
    product: edge function > 0, or == 0 on a top edge (dy == 0, dx > 0) or left edge (dy < 0)."""
    dx = bx - ax
    dy = by - ay
    e = dx * (py - ay) - dy * (px - ax)
    top_left = (dy < 0) | ((dy == 0) & (dx > 0))
    return (e > 0) | ((e == 0) & top_left)


def coverage_pairs(proj: np.ndarray, faces: np.ndarray, height: int, width: int,
                   chunk: int = 4096):
    """Yield ``(face_index, y, x)`` arrays of every covered (triangle, pixel centre) pair."""
    p = np.asarray(proj, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    for start in range(0, len(faces), chunk):
        f = faces[start:start + chunk]
        tri = p[f]  # (n, 3, 2)
        ok = np.isfinite(tri).all(axis=(1, 2))
        cross = ((tri[:, 1, 0] - tri[:, 0, 0]) * (tri[:, 2, 1] - tri[:, 0, 1])
                 - (tri[:, 1, 1] - tri[:, 0, 1]) * (tri[:, 2, 0] - tri[:, 0, 0]))
        ok &= cross != 0
        # Orient every triangle so that the interior has positive edge functions.
        neg = cross < 0
        tri[neg] = tri[neg][:, [0, 2, 1]]
        idx = np.nonzero(ok)[0]
        tri = tri[idx]
        lo = np.ceil(tri.min(axis=1)).astype(np.int64)
        hi = np.floor(tri.max(axis=1)).astype(np.int64) + 1
        lo = np.clip(lo, 0, [width, height])
        hi = np.clip(hi, 0, [width, height])
        nx = np.maximum(hi[:, 0] - lo[:, 0], 0)
        ny = np.maximum(hi[:, 1] - lo[:, 1], 0)
        n = nx * ny
        if n.sum() == 0:
            continue
        t = np.repeat(np.arange(len(idx)), n)
        k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        x = lo[t, 0] + k % np.maximum(nx[t], 1)
        y = lo[t, 1] + k // np.maximum(nx[t], 1)
        px = x.astype(np.float64)
        py = y.astype(np.float64)
        tt = tri[t]
        inside = np.ones(len(t), dtype=bool)
        for a, b in ((0, 1), (1, 2), (2, 0)):
            inside &= _edge_inside(tt[:, a, 0], tt[:, a, 1], tt[:, b, 0], tt[:, b, 1], px, py)
        yield start + idx[t[inside]], y[inside], x[inside]


def silhouette_reference(proj: np.ndarray, faces: np.ndarray, height: int,
                         width: int) -> np.ndarray:
    """Exact silhouette ``(H, W)`` uint8 {0, 1} of projected vertices ``(V, 2)``."""
    mask = np.zeros((height, width), dtype=np.uint8)
    for _, y, x in coverage_pairs(proj, faces, height, width):
        mask[y, x] = 1
    return mask


def zbuffer_reference(proj: np.ndarray, depth: np.ndarray, faces: np.ndarray, height: int,
                      width: int):
    """Exact z-buffer: ``(zbuf (H, W) float64 with inf background, face_id (H, W) int64 with
    -1 background)``, depth interpolated perspective-correctly (1/z linear in the image);
    equal depths keep the lower face index."""
    p = np.asarray(proj, dtype=np.float64)
    z = np.asarray(depth, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    zbuf = np.full((height, width), np.inf)
    face_id = np.full((height, width), -1, dtype=np.int64)
    pairs = list(coverage_pairs(p, faces, height, width))
    if not pairs:
        return zbuf, face_id
    fi, y, x = (np.concatenate(a) for a in zip(*pairs))
    tri = p[faces[fi]]
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    l1 = ((x - a[:, 0]) * (c[:, 1] - a[:, 1]) - (y - a[:, 1]) * (c[:, 0] - a[:, 0])) / area
    l2 = ((b[:, 0] - a[:, 0]) * (y - a[:, 1]) - (b[:, 1] - a[:, 1]) * (x - a[:, 0])) / area
    l0 = 1.0 - l1 - l2
    zf = z[faces[fi]]
    zz = 1.0 / (l0 / zf[:, 0] + l1 / zf[:, 1] + l2 / zf[:, 2])
    # Per pixel keep the nearest, then the lowest face index.
    pix = y * width + x
    order = np.lexsort((fi, zz, pix))
    first = order[np.r_[True, pix[order][1:] != pix[order][:-1]]]
    zbuf[y[first], x[first]] = zz[first]
    face_id[y[first], x[first]] = fi[first]
    return zbuf, face_id
