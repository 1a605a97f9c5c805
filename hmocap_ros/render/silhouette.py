"""Binary silhouettes of a triangle mesh for batches of poses x views, and the fused XOR cost.

The tracker's hot path (thesis sec. 2.2.1, eq. 2.8; approximate partitioning, eq. 2.15) needs,
for every particle ``b`` and view ``m``, the number of pixels where the model silhouette
``M_v`` and the observed foreground ``S_v`` differ. :func:`xor_counts` computes it without
materialising the masks: each (particle, view) is scan-filled into a small per-thread buffer,
compared with the observation only inside the rendered bounding box, and cleared again, using

    XOR(M, S) = |S| + |M| - 2 |M and S|       (all counted inside the optional box).

A silhouette needs no depth test: it is the union of the triangles. Coverage follows
:mod:`hmocap_ros.render.scanline` (pixel centres at integer coordinates, top-left rule).
Vertices are projected beforehand (with lens distortion; the meshes are dense enough for
straight edges); triangles with a non-finite vertex are skipped, so mark invalid vertices
(behind the camera, outside the lens' valid field) with NaN.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from hmocap_ros.render.scanline import row_range, row_span, sort_by_y


@nb.njit(cache=True, nogil=True)
def fill_silhouette(buf, proj, faces, x_min, y_min, x_max, y_max, front_only):
    """Set ``buf[y, x] = 1`` for every pixel centre covered by a triangle, inside the clip
    rectangle ``[x_min, x_max) x [y_min, y_max)``. Return the bounding box of what was set
    as ``(x0, y0, x1, y1)`` (empty when ``x0 >= x1``)."""
    bx0 = x_max
    by0 = y_max
    bx1 = x_min
    by1 = y_min
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
        if not math.isfinite(ax + ay + bx + by + cx + cy):
            continue
        if front_only:
            # Outward-oriented faces seen from the front are clockwise in a y-down image.
            if not ((bx - ax) * (cy - ay) - (by - ay) * (cx - ax) < 0.0):
                continue
        ax, ay, bx, by, cx, cy = sort_by_y(ax, ay, bx, by, cx, cy)
        y0, y1 = row_range(ay, cy, y_min, y_max)
        for y in range(y0, y1):
            x0, x1 = row_span(np.float64(y), ax, ay, bx, by, cx, cy, x_min, x_max)
            if x0 < x1:
                for x in range(x0, x1):
                    buf[y, x] = 1
                if x0 < bx0:
                    bx0 = x0
                if x1 > bx1:
                    bx1 = x1
                if y < by0:
                    by0 = y
                if y + 1 > by1:
                    by1 = y + 1
    return bx0, by0, bx1, by1


@nb.njit(cache=True, nogil=True, inline="always")
def count_xor_and_clear(buf, observed, x0, y0, x1, y1):
    """Over ``[x0, x1) x [y0, y1)``: the rendered pixels of ``buf`` and those also set in
    ``observed`` (``|M|``, ``|M and S|``), clearing ``buf`` for its next use."""
    rendered = 0
    both = 0
    for y in range(y0, y1):
        for x in range(x0, x1):
            v = buf[y, x]
            rendered += v
            both += v & observed[y, x]
            buf[y, x] = 0
    return rendered, both


@nb.njit(cache=True, nogil=True, parallel=True)
def _render_kernel(proj, faces, out, front_only):
    n = proj.shape[0]
    height = out.shape[1]
    width = out.shape[2]
    for i in nb.prange(n):
        out[i, :, :] = 0
        fill_silhouette(out[i], proj[i], faces, 0, 0, width, height, front_only)


@nb.njit(cache=True, nogil=True, parallel=True)
def _xor_kernel(proj, faces, observed, rects, observed_in_rect, front_only, n_chunks, out):
    n_poses = proj.shape[0]
    n_views = proj.shape[1]
    height = observed.shape[1]
    width = observed.shape[2]
    n = n_poses * n_views
    # A few chunks per thread, each with its own scratch mask that stays zero between uses.
    for c in nb.prange(n_chunks):
        buf = np.zeros((height, width), dtype=np.uint8)
        for i in range(c * n // n_chunks, (c + 1) * n // n_chunks):
            b = i // n_views
            m = i % n_views
            x0, y0, x1, y1 = fill_silhouette(
                buf, proj[b, m], faces, rects[m, 0], rects[m, 1], rects[m, 2], rects[m, 3],
                front_only)
            rendered, both = count_xor_and_clear(buf, observed[m], x0, y0, x1, y1)
            out[b, m] = observed_in_rect[m] + rendered - 2 * both


def _check_proj_faces(proj, faces, n_vertices_axis=-2):
    proj = np.ascontiguousarray(proj, dtype=np.float32)
    faces = np.ascontiguousarray(faces, dtype=np.int32)
    if proj.ndim < 2 or proj.shape[-1] != 2:
        raise ValueError(f"projected vertices must have shape (..., V, 2), got {proj.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces must have shape (F, 3), got {faces.shape}")
    n_vertices = proj.shape[n_vertices_axis]
    if faces.size and (faces.min() < 0 or faces.max() >= n_vertices):
        raise ValueError(f"face indices out of range for {n_vertices} vertices")
    return proj, faces


def clip_boxes(boxes, n_views: int, height: int, width: int) -> np.ndarray:
    """Per-view boxes ``(M, 4)`` as ``[x0, y0, x1, y1)`` in pixels (half-open, like slices),
    clipped to the image; ``None`` means the whole image. Returns int64 ``(M, 4)``."""
    if boxes is None:
        return np.tile(np.array([0, 0, width, height], dtype=np.int64), (n_views, 1))
    boxes = np.asarray(boxes)
    if boxes.shape != (n_views, 4):
        raise ValueError(f"boxes must have shape ({n_views}, 4), got {boxes.shape}")
    rects = np.floor(np.asarray(boxes, dtype=np.float64) + 0.5)  # round half up, no banker's
    rects = np.nan_to_num(rects, nan=0.0)
    rects[:, 0::2] = np.clip(rects[:, 0::2], 0, width)
    rects[:, 1::2] = np.clip(rects[:, 1::2], 0, height)
    rects[:, 2] = np.maximum(rects[:, 2], rects[:, 0])
    rects[:, 3] = np.maximum(rects[:, 3], rects[:, 1])
    return rects.astype(np.int64)


def binary_observed(observed: np.ndarray) -> np.ndarray:
    """Masks ``(M, H, W)`` (non-zero = foreground) as the XOR kernels read them: C-contiguous
    uint8 {0, 1}."""
    return np.ascontiguousarray(np.asarray(observed) != 0, dtype=np.uint8)


def observed_counts(observed: np.ndarray, boxes: np.ndarray | None = None) -> np.ndarray:
    """Number of foreground (non-zero) pixels of each observed mask ``(M, H, W)`` inside each
    view's box (whole image when ``boxes`` is None): ``C(S_v)`` of eq. 2.8. Returns int64 (M,)."""
    observed = np.asarray(observed)
    n_views, height, width = observed.shape
    rects = clip_boxes(boxes, n_views, height, width)
    return np.array([np.count_nonzero(observed[m, y0:y1, x0:x1])
                     for m, (x0, y0, x1, y1) in enumerate(rects)], dtype=np.int64)


def render_silhouettes(proj: np.ndarray, faces: np.ndarray, height: int, width: int, *,
                       front_only: bool = False, out: np.ndarray | None = None) -> np.ndarray:
    """Render binary silhouettes of a mesh for any batch of projections.

    Args:
        proj: projected vertices ``(..., V, 2)`` in pixels of the ``width x height`` image
            (e.g. ``(B, M, V, 2)`` for B poses x M views), pixel centres at integer coordinates.
        faces: triangles ``(F, 3)`` indexing the V vertices.
        height, width: image size in pixels.
        front_only: draw only triangles facing the camera. Exact (and about twice as fast)
            for a closed, outward-oriented mesh (positive signed volume) seen by a proper
            (det R = +1) camera; wrong for open or inside-out meshes.
        out: optional uint8 C-contiguous array ``(..., H, W)`` to render into (reusing one
            saves allocating and page-faulting fresh memory on every call).

    Returns:
        uint8 masks ``(..., H, W)`` with 1 where a pixel centre is covered, else 0.
    """
    proj, faces = _check_proj_faces(proj, faces)
    lead = proj.shape[:-2]
    flat = proj.reshape((-1,) + proj.shape[-2:])
    shape = lead + (int(height), int(width))
    if out is None:
        out = np.empty(shape, dtype=np.uint8)
    elif out.shape != shape or out.dtype != np.uint8 or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous uint8 array of shape {shape}")
    _render_kernel(flat, faces, out.reshape((-1, int(height), int(width))), bool(front_only))
    return out


def xor_counts(proj: np.ndarray, faces: np.ndarray, observed: np.ndarray,
               boxes: np.ndarray | None = None, *, front_only: bool = False) -> np.ndarray:
    """Silhouette XOR counts of B poses against M observed foreground masks (eq. 2.8 / 2.15).

    Args:
        proj: projected vertices ``(B, M, V, 2)`` float pixels at the masks' resolution.
        faces: triangles ``(F, 3)``.
        observed: foreground masks ``(M, H, W)``, any non-zero value is foreground.
        boxes: optional per-view boxes ``(M, 4)`` = ``[x0, y0, x1, y1)`` (half-open, pixels):
            only pixels inside the box count (the approximate partitioning of observations,
            eq. 2.15). ``None`` counts the whole image.
        front_only: see :func:`render_silhouettes`.

    Returns:
        int64 ``(B, M)``: number of pixels (inside the box) where the rendered silhouette and
        the observed mask differ. Runs in parallel over poses x views
        (``numba.set_num_threads`` sets the thread count).
    """
    proj, faces = _check_proj_faces(proj, faces)
    if proj.ndim != 4:
        raise ValueError(f"proj must have shape (B, M, V, 2), got {proj.shape}")
    observed = np.asarray(observed)
    if observed.ndim != 3 or observed.shape[0] != proj.shape[1]:
        raise ValueError(f"observed must have shape (M={proj.shape[1]}, H, W), "
                         f"got {observed.shape}")
    obs01 = binary_observed(observed)
    n_views, height, width = obs01.shape
    rects = clip_boxes(boxes, n_views, height, width)
    counts = observed_counts(obs01, rects)
    out = np.empty(proj.shape[:2], dtype=np.int64)
    n = out.size
    if n == 0:
        return out
    n_chunks = min(n, 4 * nb.get_num_threads())
    _xor_kernel(proj, faces, obs01, rects, counts, bool(front_only), n_chunks, out)
    return out
