"""Pinhole projection with OpenCV lens distortion, on plain arrays (K, R, t, dist).

A small stand-alone projector so the renderers stay decoupled from the camera class; it
follows the OpenCV model exactly (same as ``cv2.projectPoints``): world -> camera
``X_c = R X + t``, ``x = X_c / Z_c``, radial ``(1 + k1 r^2 + k2 r^4 + k3 r^6) /
(1 + k4 r^2 + k5 r^4 + k6 r^6)`` and tangential ``p1, p2`` terms, then ``K``. Points that cannot
be projected meaningfully (depth <= near, or beyond the radius where the distortion polynomial
stops being monotonic and would fold far-away points back into the image) get NaN pixel
coordinates, which the rasterisers skip.
"""

from __future__ import annotations

import numba as nb
import numpy as np


def distortion8(dist) -> np.ndarray:
    """OpenCV distortion coefficients (none, 4, 5 or 8) as the 8 of the rational model
    (k1, k2, p1, p2, k3, k4, k5, k6), zeros where not given."""
    d = np.zeros(8, dtype=np.float64)
    if dist is not None:
        dist = np.asarray(dist, dtype=np.float64).ravel()
        if len(dist) not in (0, 4, 5, 8):
            raise ValueError(f"distortion must have 4, 5 or 8 OpenCV coefficients, got {len(dist)}")
        d[:len(dist)] = dist
    return d


def distortion_valid_r2(dist, r_max: float = 4.0) -> float:
    """Largest squared normalised radius ``r^2`` up to which the radial distortion
    ``r -> r * radial(r)`` increases monotonically (inf when it does up to ``r_max``)."""
    d = distortion8(dist)
    r = np.linspace(0.0, r_max, 8001)
    r2 = r * r
    radial = ((1 + d[0] * r2 + d[1] * r2**2 + d[4] * r2**3)
              / (1 + d[5] * r2 + d[6] * r2**2 + d[7] * r2**3))
    rd = r * radial
    bad = np.nonzero((np.diff(rd) <= 0) | ~np.isfinite(rd[1:]))[0]
    if len(bad) == 0:
        return float("inf")
    return float(r2[bad[0]])


@nb.njit(cache=True, nogil=True)
def project_one_view(p, K, R, t, d, near, max_r2, uv, z):
    """numba kernel: points ``p`` (N, 3) into one camera (``d``: :func:`distortion8`), pixels
    into ``uv`` (N, 2) and depths into ``z`` (N,); NaN pixels at depth <= ``near`` or beyond
    the squared normalised radius ``max_r2`` (module docstring)."""
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


def project_points(points: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray,
                   dist=None, *, near: float = 1e-3, scale: float = 1.0):
    """Project world points ``(N, 3)`` into one camera.

    Args:
        points: world points ``(N, 3)``.
        K, R, t: intrinsics (3, 3), world -> camera rotation (3, 3) and translation (3,).
        dist: OpenCV distortion coefficients (4, 5 or 8) or None.
        near: points with camera depth <= near get NaN pixels.
        scale: image scale factor (e.g. 0.25 for 640x480 -> 160x120); pixel centres stay at
            integer coordinates, so ``u' = (u + 0.5) * scale - 0.5``.

    Returns:
        ``(uv (N, 2) float32, z (N,) float32)``: pixel coordinates and camera depth (metres).
    """
    uv, z = project_batch(np.asarray(points, dtype=np.float64)[None], np.asarray(K)[None],
                          np.asarray(R)[None], np.asarray(t)[None],
                          None if dist is None else np.asarray(dist)[None],
                          near=near, scale=scale)
    return uv[0, 0], z[0, 0]


def project_batch(points: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray,
                  dist=None, *, near: float = 1e-3, scale: float = 1.0):
    """Project B point sets ``(B, V, 3)`` into M cameras (``K, R (M, 3, 3)``, ``t (M, 3)``,
    ``dist (M, k)`` or None), in parallel. Returns ``uv (B, M, V, 2)`` float32 (the input of
    :func:`hmocap_ros.render.silhouette.xor_counts`) and ``z (B, M, V)`` float32; see
    :func:`project_points` for ``near`` and ``scale``."""
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
        d = np.stack([distortion8(x) for x in np.asarray(dist, dtype=np.float64).reshape(n_views, -1)])
    max_r2 = np.array([distortion_valid_r2(x) for x in d])
    if scale != 1.0:
        # Pixel centres at integer coordinates: u' = (u + 0.5) s - 0.5.
        K[:, :2, :] *= scale
        K[:, 0, 2] += 0.5 * scale - 0.5
        K[:, 1, 2] += 0.5 * scale - 0.5
    uv = np.empty(points.shape[:1] + (n_views, points.shape[1], 2), dtype=np.float32)
    z = np.empty(points.shape[:1] + (n_views, points.shape[1]), dtype=np.float32)
    _project_batch_kernel(points, K, R, t, d, float(near), max_r2, uv, z)
    return uv, z


def look_at(eye, target, up=(0.0, 1.0, 0.0)):
    """World -> camera ``(R, t)`` of a camera at ``eye`` looking at ``target`` (OpenCV axes:
    x right, y down, z forward), with ``up`` the world's up direction."""
    eye = np.asarray(eye, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(right) < 1e-9:
        right = np.cross(forward, [1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])
    return R, -R @ eye
