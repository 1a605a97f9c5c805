"""Z-buffer rasteriser: depth, face index and perspective-correct barycentrics per pixel.

For the simulator's RGB and depth images: several meshes (room, furniture, person) are
concatenated (:func:`hmocap_sim.render.meshes.concatenate_meshes`) and rasterised at once; the
face index then says which object each pixel shows, which gives the exact ground-truth
silhouette (:func:`face_range_mask`).

Inputs are plain arrays: vertices already projected to pixels (with lens distortion, see
:mod:`hmocap_ros.geometry.projection`) and their depth along the optical axis (camera z). Coverage
follows :mod:`hmocap_ros.render.scanline` (pixel centres at integer coordinates, top-left rule),
so the z-buffer's coverage equals the silhouette renderer's. There is no near-plane clipping:
a triangle with a vertex at depth <= ``near`` or a non-finite coordinate is skipped, so
scene geometry should be tessellated finely (which distortion needs anyway) and invalid
vertices marked with NaN.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from hmocap_ros.render.scanline import row_range, row_span, sort_by_y


@nb.njit(cache=True, nogil=True, parallel=True)
def _rasterize_kernel(proj, depth, faces, zbuf, face_id, bary, near, perspective,
                      with_barycentrics, n_bands):
    height = zbuf.shape[0]
    width = zbuf.shape[1]
    # Row bands in parallel; each band walks all triangles in index order, so the result does
    # not depend on the number of threads (ties keep the lowest face index).
    for band in nb.prange(n_bands):
        r0 = band * height // n_bands
        r1 = (band + 1) * height // n_bands
        for f in range(faces.shape[0]):
            i0 = faces[f, 0]
            i1 = faces[f, 1]
            i2 = faces[f, 2]
            ax = np.float64(proj[i0, 0])
            ay = np.float64(proj[i0, 1])
            bx = np.float64(proj[i1, 0])
            by = np.float64(proj[i1, 1])
            cx = np.float64(proj[i2, 0])
            cy = np.float64(proj[i2, 1])
            za = np.float64(depth[i0])
            zb = np.float64(depth[i1])
            zc = np.float64(depth[i2])
            if not math.isfinite(ax + ay + bx + by + cx + cy + za + zb + zc):
                continue
            if za <= near or zb <= near or zc <= near:
                continue
            if max(ay, by, cy) < r0 - 1 or min(ay, by, cy) > r1:
                continue
            area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
            if area == 0.0:
                continue
            inv_area = 1.0 / area
            iza = 1.0 / za
            izb = 1.0 / zb
            izc = 1.0 / zc
            sx0, sy0, sx1, sy1, sx2, sy2 = sort_by_y(ax, ay, bx, by, cx, cy)
            y0, y1 = row_range(sy0, sy2, r0, r1)
            for y in range(y0, y1):
                py = np.float64(y)
                x0, x1 = row_span(py, sx0, sy0, sx1, sy1, sx2, sy2, 0, width)
                for x in range(x0, x1):
                    px = np.float64(x)
                    l1 = ((px - ax) * (cy - ay) - (py - ay) * (cx - ax)) * inv_area
                    l2 = ((bx - ax) * (py - ay) - (by - ay) * (px - ax)) * inv_area
                    # Pixel centres are inside; clamp rounding noise so nothing extrapolates.
                    l1 = min(max(l1, 0.0), 1.0)
                    l2 = min(max(l2, 0.0), 1.0 - l1)
                    l0 = 1.0 - l1 - l2
                    if perspective:
                        w0 = l0 * iza
                        w1 = l1 * izb
                        w2 = l2 * izc
                        z = 1.0 / (w0 + w1 + w2)
                        l0 = w0 * z
                        l1 = w1 * z
                        l2 = w2 * z
                    else:
                        z = l0 * za + l1 * zb + l2 * zc
                    if z < zbuf[y, x]:
                        zbuf[y, x] = z
                        face_id[y, x] = f
                        if with_barycentrics:
                            bary[y, x, 0] = l0
                            bary[y, x, 1] = l1
                            bary[y, x, 2] = l2


def rasterize(proj_xy: np.ndarray, depth_z: np.ndarray, faces: np.ndarray, height: int,
              width: int, *, near: float = 1e-3, perspective: bool = True,
              with_barycentrics: bool = True):
    """Rasterise a triangle mesh with a z-buffer.

    Args:
        proj_xy: vertex pixel coordinates ``(V, 2)`` (pixel centres at integer coordinates).
        depth_z: vertex depth ``(V,)`` along the optical axis, in metres (camera z).
        faces: triangles ``(F, 3)``.
        height, width: image size.
        near: triangles with a vertex at depth <= near are skipped (no clipping).
        perspective: interpolate perspective-correctly (1/z linear in the image, the pinhole
            case); False interpolates depth and barycentrics linearly (orthographic views,
            e.g. a directional light's shadow map).
        with_barycentrics: False skips the barycentric image (returns None for it).

    Returns:
        ``(zbuf, face_id, barycentrics)``: float32 ``(H, W)`` depth of the nearest surface
        (inf where empty), int32 ``(H, W)`` its face index (-1 where empty) and float32
        ``(H, W, 3)`` its barycentric weights of the face's three vertices (summing to 1;
        zero where empty).
    """
    proj_xy = np.ascontiguousarray(proj_xy, dtype=np.float32)
    depth_z = np.ascontiguousarray(depth_z, dtype=np.float32)
    faces = np.ascontiguousarray(faces, dtype=np.int32)
    if proj_xy.ndim != 2 or proj_xy.shape[1] != 2:
        raise ValueError(f"proj_xy must have shape (V, 2), got {proj_xy.shape}")
    if depth_z.shape != proj_xy.shape[:1]:
        raise ValueError(f"depth_z must have shape ({proj_xy.shape[0]},), got {depth_z.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {faces.shape}")
    if faces.size and (faces.min() < 0 or faces.max() >= len(proj_xy)):
        raise ValueError(f"face indices out of range for {len(proj_xy)} vertices")
    height = int(height)
    width = int(width)
    zbuf = np.full((height, width), np.inf, dtype=np.float32)
    face_id = np.full((height, width), -1, dtype=np.int32)
    if with_barycentrics:
        bary = np.zeros((height, width, 3), dtype=np.float32)
    else:
        bary = np.zeros((1, 1, 3), dtype=np.float32)
    n_bands = max(1, min(height, 4 * nb.get_num_threads()))
    _rasterize_kernel(proj_xy, depth_z, faces, zbuf, face_id, bary, float(near),
                      bool(perspective), bool(with_barycentrics), n_bands)
    return zbuf, face_id, (bary if with_barycentrics else None)


def face_range_mask(face_id: np.ndarray, start: int, stop: int) -> np.ndarray:
    """uint8 mask (0/1) of the pixels showing faces ``start <= f < stop``, e.g. the exact
    ground-truth silhouette of the person (its face range after concatenation)."""
    return ((face_id >= start) & (face_id < stop)).astype(np.uint8)


def interpolate(attributes: np.ndarray, faces: np.ndarray, face_id: np.ndarray,
                barycentrics: np.ndarray, fill: float = 0.0) -> np.ndarray:
    """Interpolate per-vertex attributes ``(V, C)`` over the image with the rasteriser's
    (perspective-correct) barycentrics: returns ``(H, W, C)`` float32, ``fill`` where empty."""
    attributes = np.asarray(attributes, dtype=np.float32)
    squeeze = attributes.ndim == 1
    if squeeze:
        attributes = attributes[:, None]
    out = np.full(face_id.shape + attributes.shape[1:], fill, dtype=np.float32)
    hit = face_id >= 0
    tri = np.asarray(faces)[face_id[hit]]  # (N, 3)
    out[hit] = np.einsum("nk,nkc->nc", barycentrics[hit], attributes[tri])
    return out[..., 0] if squeeze else out
