"""Projection of room points into several calibrated cameras at once (thesis sec. 2.1: the
projective transformations p_v of the views v).

:func:`project_points` takes :class:`~hmocap_ros.geometry.PinholeCamera` objects, or any
sequence of them such as a :class:`~hmocap_ros.geometry.rig.Rig`, and returns float64 pixels
with a visibility mask; frames and conventions are those of :mod:`hmocap_ros.geometry`.

:func:`project_batch` is its numba kernel for the hot paths (the tracker's particles, the
renderers): B point sets into M cameras given as plain arrays (K, R, t, distortion), in
parallel, float32 pixels and depths. It follows the same OpenCV model (``cv2.projectPoints``):
``X_c = R X + t``, ``x = X_c / Z_c``, the radial and tangential terms of
:mod:`~hmocap_ros.geometry.distortion`, then ``K``. Points that cannot be projected
meaningfully (depth <= near, or beyond the radius where the distortion polynomial stops being
monotonic, :func:`~hmocap_ros.geometry.distortion.monotonic_radius2`, and would fold far-away
points back into the image) get NaN pixel coordinates, which the rasterisers skip.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numba as nb
import numpy as np

from hmocap_ros.geometry.distortion import coefficients8, distort_xy, monotonic_radius2

__all__ = ["DEFAULT_MIN_DEPTH", "Projection", "project_batch", "project_one_view", "project_points"]

#: Points nearer than this (metres along the optical axis) are not visible.
DEFAULT_MIN_DEPTH = 1e-6


class Projection(NamedTuple):
    """Result of :func:`project_points` for M cameras and points of batch shape ``S``."""

    pixels: np.ndarray  #: (M, *S, 2) pixel coordinates (distorted image)
    depth: np.ndarray  #: (M, *S) z in each camera's optical frame
    visible: np.ndarray  #: (M, *S) in front, inside the image and inside the valid distortion range


def _stack(cameras: Sequence):
    cameras = list(cameras)
    if not cameras:
        raise ValueError("need at least one camera")
    R = np.stack([c.R for c in cameras])
    t = np.stack([c.t for c in cameras])
    K = np.stack([c.K for c in cameras])
    D = np.stack([c.distortion8 for c in cameras])
    return cameras, R, t, K, D


def project_points(cameras: Sequence, points_world, distort: bool = True,
                   min_depth: float = DEFAULT_MIN_DEPTH) -> Projection:
    """Project room points ``(..., 3)`` into M cameras at once.

    Returns :class:`Projection` with pixels ``(M, ..., 2)``, depth ``(M, ...)`` and the visibility
    mask ``(M, ...)``: depth > ``min_depth``, inside the image, and (with distortion) within the
    range where the lens model is monotonic. ``cameras`` is any sequence (e.g. a ``Rig``).
    """
    cameras, R, t, K, D = _stack(cameras)
    points = np.asarray(points_world, dtype=np.float64)
    if points.shape[-1] != 3:
        raise ValueError(f"points must have shape (..., 3), got {points.shape}")
    batch = points.shape[:-1]
    flat = points.reshape(-1, 3)
    cam = np.matmul(flat[None], R.transpose(0, 2, 1)) + t[:, None, :]  # (M, N, 3); BLAS, unlike einsum
    depth = cam[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = cam[..., 0] / depth
        y = cam[..., 1] / depth
    r2 = x * x + y * y
    if distort:
        xd, yd = distort_xy(x, y, tuple(D.T[:, :, None]))
    else:
        xd, yd = x, y
    u = K[:, 0, 0, None] * xd + K[:, 0, 1, None] * yd + K[:, 0, 2, None]
    v = K[:, 1, 1, None] * yd + K[:, 1, 2, None]
    sizes = np.array([[c.width, c.height] for c in cameras], dtype=np.float64)
    with np.errstate(invalid="ignore"):
        visible = (
            (depth > min_depth)
            & (u >= -0.5) & (u < sizes[:, 0, None] - 0.5)
            & (v >= -0.5) & (v < sizes[:, 1, None] - 0.5)
        )
        if distort:
            r2_max = np.array([c.max_normalized_radius2 for c in cameras])
            visible &= r2 <= r2_max[:, None]
    M = len(cameras)
    pixels = np.stack([u, v], axis=-1).reshape((M,) + batch + (2,))
    return Projection(pixels, depth.reshape((M,) + batch), visible.reshape((M,) + batch))


@nb.njit(cache=True, nogil=True)
def project_one_view(p, K, R, t, d, near, max_r2, uv, z):
    """numba kernel: points ``p`` (N, 3) into one camera (``d``: the 8 coefficients of
    :func:`~hmocap_ros.geometry.distortion.coefficients8`), pixels into ``uv`` (N, 2) and depths
    into ``z`` (N,); NaN pixels at depth <= ``near`` or beyond the squared normalised radius
    ``max_r2`` (:func:`~hmocap_ros.geometry.distortion.monotonic_radius2`)."""
    for i in range(p.shape[0]):
        X = p[i, 0]
        Y = p[i, 1]
        Z = p[i, 2]
        xc = R[0, 0] * X + R[0, 1] * Y + R[0, 2] * Z + t[0]
        yc = R[1, 0] * X + R[1, 1] * Y + R[1, 2] * Z + t[1]
        zc = R[2, 0] * X + R[2, 1] * Y + R[2, 2] * Z + t[2]
        z[i] = zc
        if not zc > near:
            uv[i, 0] = np.nan
            uv[i, 1] = np.nan
            continue
        x = xc / zc
        y = yc / zc
        r2 = x * x + y * y
        if r2 > max_r2:
            uv[i, 0] = np.nan
            uv[i, 1] = np.nan
            continue
        radial = ((1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4])))
                  / (1.0 + r2 * (d[5] + r2 * (d[6] + r2 * d[7]))))
        xd = x * radial + 2.0 * d[2] * x * y + d[3] * (r2 + 2.0 * x * x)
        yd = y * radial + d[2] * (r2 + 2.0 * y * y) + 2.0 * d[3] * x * y
        uv[i, 0] = K[0, 0] * xd + K[0, 1] * yd + K[0, 2]
        uv[i, 1] = K[1, 1] * yd + K[1, 2]


@nb.njit(cache=True, nogil=True, parallel=True)
def _project_batch_kernel(points, K, R, t, d, near, max_r2, uv, z):
    n_poses = points.shape[0]
    n_views = K.shape[0]
    for i in nb.prange(n_poses * n_views):
        b = i // n_views
        m = i % n_views
        project_one_view(points[b], K[m], R[m], t[m], d[m], near, max_r2[m], uv[b, m], z[b, m])


def project_batch(points: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray,
                  dist=None, *, near: float = 1e-3, scale: float = 1.0):
    """Project B point sets ``(B, V, 3)`` into M cameras, in parallel (the numba kernel).

    Args:
        points: world points ``(B, V, 3)``.
        K, R, t: intrinsics ``(M, 3, 3)``, world -> camera rotations ``(M, 3, 3)`` and
            translations ``(M, 3)``.
        dist: OpenCV distortion coefficients ``(M, k)``, k <= 8, or None.
        near: points with camera depth <= near get NaN pixels.
        scale: image scale factor (e.g. 0.25 for 640x480 -> 160x120); pixel centres stay at
            integer coordinates, so ``u' = (u + 0.5) * scale - 0.5``.

    Returns:
        ``uv (B, M, V, 2)`` float32 pixel coordinates (the input of
        :func:`hmocap_ros.render.silhouette.xor_counts`) and ``z (B, M, V)`` float32 camera
        depths (metres).
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    if points.ndim != 3 or points.shape[2] != 3:
        raise ValueError(f"points must have shape (B, V, 3), got {points.shape}")
    K = np.ascontiguousarray(K, dtype=np.float64).reshape(-1, 3, 3).copy()
    R = np.ascontiguousarray(R, dtype=np.float64).reshape(-1, 3, 3)
    t = np.ascontiguousarray(t, dtype=np.float64).reshape(-1, 3)
    n_views = K.shape[0]
    if R.shape[0] != n_views or t.shape[0] != n_views:
        raise ValueError("K, R and t must describe the same number of cameras")
    if dist is None:
        d = np.zeros((n_views, 8))
    else:
        d = coefficients8(np.asarray(dist, dtype=np.float64).reshape(n_views, -1))
    max_r2 = np.array([monotonic_radius2(x) for x in d])
    if scale != 1.0:
        # Pixel centres at integer coordinates: u' = (u + 0.5) s - 0.5.
        K[:, :2, :] *= scale
        K[:, 0, 2] += 0.5 * scale - 0.5
        K[:, 1, 2] += 0.5 * scale - 0.5
    uv = np.empty(points.shape[:1] + (n_views, points.shape[1], 2), dtype=np.float32)
    z = np.empty(points.shape[:1] + (n_views, points.shape[1]), dtype=np.float32)
    _project_batch_kernel(points, K, R, t, d, float(near), max_r2, uv, z)
    return uv, z
