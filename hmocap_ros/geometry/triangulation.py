"""Multi-view geometry on calibrated cameras: viewing rays, linear (DLT) triangulation and its
robust variant that leaves out disagreeing views, reprojection errors.

Frames and conventions are those of :mod:`hmocap_ros.geometry`.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from hmocap_ros.geometry.pinhole_camera import PinholeCamera
from hmocap_ros.geometry.projection import project_points

__all__ = ["pixel_rays", "reprojection_errors", "triangulate", "triangulate_robust"]


def pixel_rays(cameras: Sequence[PinholeCamera], pixels) -> tuple[np.ndarray, np.ndarray]:
    """Viewing rays of pixels ``(M, ..., 2)`` (axis 0: one entry per camera) in the room frame.

    Returns ``(origins (M, 3), directions (M, ..., 3))`` with unit directions.
    """
    cameras = list(cameras)
    pixels = np.asarray(pixels, dtype=np.float64)
    if pixels.shape[0] != len(cameras) or pixels.shape[-1] != 2:
        raise ValueError(f"pixels must have shape ({len(cameras)}, ..., 2), got {pixels.shape}")
    origins = np.stack([c.position for c in cameras])
    directions = np.stack([c.back_project(p) for c, p in zip(cameras, pixels)])
    return origins, directions


def triangulate(cameras: Sequence[PinholeCamera], pixels, valid=None, min_views: int = 2) -> np.ndarray:
    """Linear (DLT) triangulation of N points seen by M cameras, vectorised over points.

    Hartley & Zisserman, *Multiple View Geometry*, sec. 12.2: each valid view m of point n gives
    the rows ``x P_m^3 - P_m^1`` and ``y P_m^3 - P_m^2`` with ``P_m = [R_m | t_m]`` and ``(x, y)``
    the undistorted normalized coordinates; the homogeneous point is the right singular vector
    of the smallest singular value of the stacked rows ``A`` (batched over N).

    ``pixels`` is ``(M, N, 2)``; ``valid`` ``(M, N)`` selects the views to use (default: all
    finite pixels). Points with fewer than ``min_views`` valid views, or at infinity, are NaN.
    Returns ``(N, 3)`` room points.
    """
    cameras = list(cameras)
    pixels = np.asarray(pixels, dtype=np.float64)
    M = len(cameras)
    if pixels.ndim != 3 or pixels.shape[0] != M or pixels.shape[2] != 2:
        raise ValueError(f"pixels must have shape ({M}, N, 2), got {pixels.shape}")
    N = pixels.shape[1]
    finite = np.all(np.isfinite(pixels), axis=-1)
    valid = finite if valid is None else (np.asarray(valid, dtype=bool) & finite)
    if valid.shape != (M, N):
        raise ValueError(f"valid must have shape ({M}, {N}), got {valid.shape}")
    xy = np.stack([c.undistort_points(np.where(finite[m, :, None], pixels[m], 0.0)) for m, c in enumerate(cameras)])
    valid = valid & np.all(np.isfinite(xy), axis=-1)
    xy = np.where(valid[..., None], xy, 0.0)
    P = np.stack([np.hstack([c.R, c.t[:, None]]) for c in cameras])  # (M, 3, 4)
    rows_x = xy[..., 0, None] * P[:, None, 2, :] - P[:, None, 0, :]  # (M, N, 4)
    rows_y = xy[..., 1, None] * P[:, None, 2, :] - P[:, None, 1, :]
    weight = valid[..., None].astype(np.float64)
    A = np.concatenate([rows_x * weight, rows_y * weight], axis=0)  # (2M, N, 4)
    A = np.moveaxis(A, 1, 0)  # (N, 2M, 4)
    out = np.full((N, 3), np.nan)
    enough = valid.sum(axis=0) >= max(int(min_views), 2)
    if not np.any(enough):
        return out
    A = A[enough]
    # The right singular vector of A for the smallest singular value is the eigenvector of the
    # 4x4 A^T A for the smallest eigenvalue: a batched eigh is twice as fast as a batched SVD.
    _, eigenvectors = np.linalg.eigh(np.matmul(A.transpose(0, 2, 1), A))
    X = eigenvectors[:, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        points = X[:, :3] / X[:, 3:]
    points[np.abs(X[:, 3]) < 1e-12] = np.nan
    out[enough] = points
    return out


def reprojection_errors(cameras: Sequence[PinholeCamera], points, pixels) -> np.ndarray:
    """Pixel distance ``(M, N)`` between room points ``(N, 3)`` projected into each camera and
    the observed ``pixels`` ``(M, N, 2)``; NaN where the point or the pixel is NaN."""
    points = np.asarray(points, dtype=np.float64)
    finite = np.all(np.isfinite(points), axis=1)
    projected = project_points(list(cameras), np.where(finite[:, None], points, 0.0)).pixels
    errors = np.linalg.norm(projected - np.asarray(pixels, dtype=np.float64), axis=-1)
    errors[:, ~finite] = np.nan
    return errors


def triangulate_robust(cameras: Sequence[PinholeCamera], pixels, valid=None,
                       max_reprojection_px: float = 20.0, min_views: int = 2):
    """:func:`triangulate`, leaving out views that disagree with the others.

    A point whose worst used view reprojects further than ``max_reprojection_px`` is
    triangulated again without one view, the one whose removal leaves the best worst-view
    error (the view with the largest error is not always the wrong one: a wrong view drags the
    point towards itself), repeatedly while more than ``min_views`` remain. Meant for
    per-view 2D detections, where one view may have found another person or limb.
    Returns ``(points (N, 3), used (M, N) bool)``.
    """
    cameras = list(cameras)
    pixels = np.asarray(pixels, dtype=np.float64)
    used = np.all(np.isfinite(pixels), axis=-1)
    if valid is not None:
        used &= np.asarray(valid, dtype=bool)
    points = triangulate(cameras, pixels, used, min_views)

    def worst_error(pts, pix, use):
        err = np.where(use, reprojection_errors(cameras, pts, pix), -np.inf)
        return np.nan_to_num(err.max(axis=0), nan=np.inf)

    while True:
        bad = (worst_error(points, pixels, used) > max_reprojection_px) & (used.sum(axis=0) > min_views)
        if not bad.any():
            return points, used
        best_error = np.full(points.shape[0], np.inf)
        best_view = np.full(points.shape[0], -1)
        for m in range(len(cameras)):  # leave one view out at a time (M is a handful)
            candidates = np.flatnonzero(bad & used[m])
            if candidates.size == 0:
                continue
            trial = used[:, candidates].copy()
            trial[m] = False
            error = worst_error(triangulate(cameras, pixels[:, candidates], trial, min_views),
                                pixels[:, candidates], trial)
            better = error < best_error[candidates]
            best_error[candidates[better]] = error[better]
            best_view[candidates[better]] = m
        drop = np.flatnonzero(bad & (best_view >= 0))
        if drop.size == 0:
            return points, used
        used[best_view[drop], drop] = False
        points[drop] = triangulate(cameras, pixels[:, drop], used[:, drop], min_views)
