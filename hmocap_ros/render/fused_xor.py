"""Silhouette XOR counts straight from posed vertices: projection and scan-fill in one pass.

The weighting function of the tracker (eq. 2.8 / 2.15) projects every particle's mesh into
every view and counts the pixels where the model silhouette and the foreground differ.
:func:`hmocap_ros.render.xor_counts` takes projected vertices; at the thesis' budget
(3,500 particles x 4 views x 1,202 vertices) the projected array alone is about 130 MB,
written once and read back. Here each (particle, view) is projected into a small per-thread
buffer and rasterised at once, with the same projection (:mod:`hmocap_ros.geometry.projection`,
OpenCV distortion) and the same coverage rule (:mod:`hmocap_ros.render.silhouette`), so the
counts are identical to ``xor_counts(project_batch(...))``.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from hmocap_ros.geometry.distortion import coefficients8, monotonic_radius2
from hmocap_ros.geometry.projection import project_one_view
from hmocap_ros.render.silhouette import (
    binary_observed,
    clip_boxes,
    count_xor_and_clear,
    fill_silhouette,
    observed_counts,
)

__all__ = ["xor_counts_from_vertices"]


def _fused_body(verts, K, R, t, d, near, max_r2, faces, observed, rects, observed_in_rect,
                front_only, n_chunks, out, c):
    n_poses = verts.shape[0]
    n_views = K.shape[0]
    n_vert = verts.shape[1]
    height = observed.shape[1]
    width = observed.shape[2]
    n = n_poses * n_views
    buf = np.zeros((height, width), dtype=np.uint8)
    uv = np.empty((n_vert, 2), dtype=np.float32)
    z = np.empty(n_vert, dtype=np.float32)
    for i in range(c * n // n_chunks, (c + 1) * n // n_chunks):
        b = i // n_views
        m = i % n_views
        project_one_view(verts[b], K[m], R[m], t[m], d[m], near, max_r2[m], uv, z)
        x0, y0, x1, y1 = fill_silhouette(
            buf, uv, faces, rects[m, 0], rects[m, 1], rects[m, 2], rects[m, 3], front_only)
        rendered, both = count_xor_and_clear(buf, observed[m], x0, y0, x1, y1)
        out[b, m] = observed_in_rect[m] + rendered - 2 * both


_fused_chunk = nb.njit(cache=True, nogil=True)(_fused_body)


@nb.njit(cache=True, nogil=True, parallel=True)
def _fused_parallel(verts, K, R, t, d, near, max_r2, faces, observed, rects, observed_in_rect,
                    front_only, n_chunks, out):
    for c in nb.prange(n_chunks):
        _fused_chunk(verts, K, R, t, d, near, max_r2, faces, observed, rects, observed_in_rect,
                     front_only, n_chunks, out, c)


@nb.njit(cache=True, nogil=True)
def _fused_serial(verts, K, R, t, d, near, max_r2, faces, observed, rects, observed_in_rect,
                  front_only, out):
    _fused_chunk(verts, K, R, t, d, near, max_r2, faces, observed, rects, observed_in_rect,
                 front_only, 1, out, 0)


#: Below this many (pose, view) pairs the kernel runs on the calling thread: waking numba's
#: workers costs milliseconds on a small, loaded machine (a Powell step weighs one pose).
PARALLEL_MIN_ITEMS = 64


def xor_counts_from_vertices(verts: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray,
                             dist, faces: np.ndarray, observed: np.ndarray,
                             boxes: np.ndarray | None = None, *, front_only: bool = False,
                             near: float = 1e-3, max_r2: np.ndarray | None = None) -> np.ndarray:
    """XOR counts (B, M) of posed meshes ``verts (B, V, 3)`` against masks ``(M, H, W)``.

    Cameras: ``K, R (M, 3, 3)``, ``t (M, 3)``, ``dist (M, k)`` OpenCV coefficients or None, at
    the masks' resolution. ``faces``, ``boxes`` and ``front_only`` as in
    :func:`hmocap_ros.render.xor_counts`. ``max_r2`` (M,): the cameras'
    :func:`~hmocap_ros.geometry.distortion.monotonic_radius2`, if the caller keeps them.
    Parallel over poses x views (serial below :data:`PARALLEL_MIN_ITEMS` pairs).
    """
    verts = np.asarray(verts)
    if verts.dtype not in (np.float32, np.float64):
        verts = verts.astype(np.float32)
    verts = np.ascontiguousarray(verts)
    if verts.ndim != 3 or verts.shape[2] != 3:
        raise ValueError(f"verts must have shape (B, V, 3), got {verts.shape}")
    faces = np.ascontiguousarray(faces, dtype=np.int32)
    if faces.size and (faces.min() < 0 or faces.max() >= verts.shape[1]):
        raise ValueError(f"face indices out of range for {verts.shape[1]} vertices")
    K = np.ascontiguousarray(K, dtype=np.float64).reshape(-1, 3, 3)
    R = np.ascontiguousarray(R, dtype=np.float64).reshape(-1, 3, 3)
    t = np.ascontiguousarray(t, dtype=np.float64).reshape(-1, 3)
    n_views = K.shape[0]
    observed = np.asarray(observed)
    if observed.ndim != 3 or observed.shape[0] != n_views:
        raise ValueError(f"observed must have shape (M={n_views}, H, W), got {observed.shape}")
    if dist is None:
        d = np.zeros((n_views, 8))
    else:
        d = coefficients8(np.asarray(dist, dtype=np.float64).reshape(n_views, -1))
    if max_r2 is None:
        max_r2 = np.array([monotonic_radius2(x) for x in d])
    max_r2 = np.ascontiguousarray(max_r2, dtype=np.float64)
    obs01 = binary_observed(observed)
    _, height, width = obs01.shape
    rects = clip_boxes(boxes, n_views, height, width)
    counts = observed_counts(obs01, rects)
    out = np.empty((verts.shape[0], n_views), dtype=np.int64)
    if out.size == 0:
        return out
    if out.size < PARALLEL_MIN_ITEMS or nb.get_num_threads() == 1:
        _fused_serial(verts, K, R, t, d, float(near), max_r2, faces, obs01, rects, counts,
                      bool(front_only), out)
    else:
        n_chunks = min(out.size, 4 * nb.get_num_threads())
        _fused_parallel(verts, K, R, t, d, float(near), max_r2, faces, obs01, rects, counts,
                        bool(front_only), n_chunks, out)
    return out
