"""Multi-view triangulation of 2D keypoints (direct linear transform), vectorised.

Used by ``tools/peer_mediapipe.py`` to measure the peer the tracker is compared with (2D pose
per view + DLT, the FreeMoCap approach), and by anything else that lifts per-view detections
to the room frame (e.g. the 3D extremity detections of thesis sec. 2.5).

Pixels are undistorted with the camera's OpenCV model first (``undistort_normalized``), so
the DLT works on normalised image coordinates: for a camera ``x_cam = R x + t`` the rows of
the linear system for one observation ``(u, v)`` are ``u P3 - P1`` and ``v P3 - P2`` with
``P = [R | t]``, solved in the least-squares sense by the SVD of the stacked rows.
"""
from __future__ import annotations

import numpy as np

from hmocap_ros.camera_model import undistort_normalized


def normalized_points(camera, pixels: np.ndarray) -> np.ndarray:
    """Pixels ``(..., 2)`` of ``camera`` -> undistorted normalised coordinates ``(..., 2)``."""
    pixels = np.asarray(pixels, dtype=np.float64)
    xd = (pixels[..., 0] - camera.cx) / camera.fx
    yd = (pixels[..., 1] - camera.cy) / camera.fy
    return undistort_normalized(np.stack([xd, yd], axis=-1), camera.D)


def triangulate(cameras, pixels: np.ndarray, valid: np.ndarray | None = None,
                max_reprojection_px: float | None = None, min_views: int = 2):
    """Triangulate N points seen in V cameras.

    cameras: V PinholeCamera; pixels: (V, N, 2); valid: (V, N) bool (default: finite pixels).
    max_reprojection_px: when given, a point whose worst view reprojects further than this is
    triangulated again without the one view whose removal fits the rest best, repeatedly, as
    long as more than ``min_views`` remain (a detector that took the wrong person or limb in
    one view should not drag the point).
    Returns ``(points (N, 3), used (V, N) bool)``; points seen in fewer than ``min_views``
    views are NaN.
    """
    pixels = np.asarray(pixels, dtype=np.float64)
    n_views, n_points = pixels.shape[:2]
    if len(cameras) != n_views:
        raise ValueError(f"{len(cameras)} cameras for pixels of {n_views} views")
    finite = np.isfinite(pixels).all(axis=-1)
    used = finite if valid is None else (np.asarray(valid, bool) & finite)
    norm = np.full_like(pixels, np.nan)
    for v, cam in enumerate(cameras):
        ok = finite[v]
        norm[v, ok] = normalized_points(cam, pixels[v, ok])
    P = np.stack([np.hstack([cam.R, np.asarray(cam.t, float).reshape(3, 1)]) for cam in cameras])
    used = used.copy()
    points = _dlt(P, norm, used, min_views)
    if max_reprojection_px is None:
        return points, used
    while True:
        worst = _max_error(cameras, points, pixels, used)
        bad = (worst > max_reprojection_px) & (used.sum(axis=0) > min_views)
        if not bad.any():
            return points, used
        # leave each view out in turn; keep the subset whose worst view fits best (the view
        # with the largest error is not always the wrong one: a wrong view drags the point)
        best_err = np.full(n_points, np.inf)
        best_view = np.full(n_points, -1)
        for v in range(n_views):
            trial = used.copy()
            trial[v] = False
            cand = (bad & used[v])
            if not cand.any():
                continue
            pts = _dlt(P, norm[:, cand], trial[:, cand], min_views)
            err = _max_error(cameras, pts, pixels[:, cand], trial[:, cand])
            idx = np.flatnonzero(cand)
            better = err < best_err[idx]
            best_err[idx[better]] = err[better]
            best_view[idx[better]] = v
        drop = np.flatnonzero(bad & (best_view >= 0))
        if drop.size == 0:
            return points, used
        used[best_view[drop], drop] = False
        points[drop] = _dlt(P, norm[:, drop], used[:, drop], min_views)


def _max_error(cameras, points, pixels, used) -> np.ndarray:
    err = np.where(used, reprojection_errors(cameras, points, pixels), -np.inf)
    return np.nan_to_num(err.max(axis=0), nan=np.inf)


def _dlt(P: np.ndarray, norm: np.ndarray, used: np.ndarray, min_views: int) -> np.ndarray:
    n_views, n_points = used.shape
    u = np.nan_to_num(norm[..., 0])[..., None]  # (V, N, 1)
    v = np.nan_to_num(norm[..., 1])[..., None]
    rows_u = u * P[:, None, 2, :] - P[:, None, 0, :]  # (V, N, 4)
    rows_v = v * P[:, None, 2, :] - P[:, None, 1, :]
    w = used[..., None].astype(np.float64)  # unused views contribute zero rows
    A = np.concatenate([rows_u * w, rows_v * w], axis=0).transpose(1, 0, 2)  # (N, 2V, 4)
    _, _, vt = np.linalg.svd(A)
    X = vt[:, -1, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        points = X[:, :3] / X[:, 3:4]
    points[used.sum(axis=0) < min_views] = np.nan
    return points


def reprojection_errors(cameras, points: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Pixel distance ``(V, N)`` between ``points`` (N, 3) projected and ``pixels`` (V, N, 2)."""
    out = np.full(pixels.shape[:2], np.nan)
    ok = np.isfinite(points).all(axis=1)
    for v, cam in enumerate(cameras):
        if ok.any():
            proj, _ = cam.project(points[ok])
            out[v, ok] = np.linalg.norm(proj - pixels[v, ok], axis=1)
    return out
