"""Projection of room points into several calibrated cameras at once (thesis sec. 2.1: the
projective transformations p_v of the views v).

The cameras are :class:`~hmocap_ros.camera_model.PinholeCamera` objects, or any sequence of them
such as a :class:`~hmocap_ros.rig.Rig`; frames and conventions are those of
:mod:`hmocap_ros.camera_model`.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from hmocap_ros.lens_distortion import distort_xy

__all__ = ["DEFAULT_MIN_DEPTH", "Projection", "project_points"]

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
