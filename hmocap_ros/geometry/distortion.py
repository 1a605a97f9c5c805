"""OpenCV lens distortion of normalized image coordinates, vectorised in numpy.

The Brown-Conrady model of OpenCV and ROS (``plumb_bob``: ``D = (k1, k2, p1, p2, k3)``,
``rational_polynomial``: ``D = (k1, k2, p1, p2, k3, k4, k5, k6)``), with
``r^2 = x^2 + y^2`` and ``g = (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)``:

    x_d = x g + 2 p1 x y + p2 (r^2 + 2 x^2),    y_d = y g + p1 (r^2 + 2 y^2) + 2 p2 x y

Every function broadcasts over batches of points and over coefficient sets, so one call serves
many cameras (matches ``cv2.projectPoints`` / ``cv2.undistortPoints`` to 1e-9).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "DISTORTION_MODELS",
    "coefficients8",
    "distort_normalized",
    "distort_xy",
    "monotonic_radius2",
    "undistort_normalized",
]

#: Number of coefficients of each supported ROS ``distortion_model``.
DISTORTION_MODELS = {"plumb_bob": 5, "rational_polynomial": 8}


def coefficients8(D) -> np.ndarray:
    """Distortion coefficients padded with zeros to OpenCV's 8 (k1, k2, p1, p2, k3, k4, k5, k6)."""
    d = np.asarray(D, dtype=np.float64)
    if d.shape[-1] > 8:
        raise ValueError(f"at most 8 distortion coefficients are supported, got {d.shape[-1]}")
    pad = [(0, 0)] * (d.ndim - 1) + [(0, 8 - d.shape[-1])]
    return np.pad(d, pad)


def _radial_terms(r2, d8):
    """Radial factor g(r^2) and its derivative dg/d(r^2); ``d8`` is a tuple of 8 broadcastable arrays."""
    k1, k2, _, _, k3, k4, k5, k6 = d8
    num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    dnum = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3)
    dden = k4 + r2 * (2.0 * k5 + 3.0 * r2 * k6)
    g = num / den
    dg = (dnum * den - num * dden) / (den * den)
    return g, dg


def _radial_factor(r2, d8):
    """Radial factor g(r^2) alone; skips the rational denominator when it is 1 (plumb_bob)."""
    k1, k2, _, _, k3, k4, k5, k6 = d8
    g = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    if np.any(k4) or np.any(k5) or np.any(k6):
        g = g / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    return g


def distort_xy(x, y, d8):
    """OpenCV distortion of normalized coordinates (the formula of the module docstring)."""
    p1, p2 = d8[2], d8[3]
    r2 = x * x + y * y
    g = _radial_factor(r2, d8)
    xy = x * y
    xd = x * g + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x)
    yd = y * g + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy
    return xd, yd


def distort_normalized(xy, D) -> np.ndarray:
    """Apply OpenCV distortion ``D`` (0 to 8 coefficients) to normalized coordinates ``(..., 2)``."""
    xy = np.asarray(xy, dtype=np.float64)
    d8 = tuple(coefficients8(D))
    xd, yd = distort_xy(xy[..., 0], xy[..., 1], d8)
    return np.stack([xd, yd], axis=-1)


def undistort_normalized(xy_distorted, D, iterations: int = 20, tolerance: float = 1e-14) -> np.ndarray:
    """Invert :func:`distort_normalized` by vectorised Newton iterations.

    Solves ``distort(x) = x_d`` for every point with the analytic 2x2 Jacobian of the OpenCV
    model, starting from ``x = x_d``; converges quadratically for any point inside the monotonic
    part of the distortion (every point of a calibrated image). Points that do not converge are
    returned as NaN. ``D`` may be ``(n,)`` or broadcast against the batch shape as ``(..., n)``.
    """
    xy_distorted = np.asarray(xy_distorted, dtype=np.float64)
    coeffs = coefficients8(D)
    d8 = tuple(np.moveaxis(coeffs, -1, 0))
    if not np.any(coeffs):
        return xy_distorted.copy()
    p1, p2 = d8[2], d8[3]
    xd, yd = xy_distorted[..., 0], xy_distorted[..., 1]
    x, y = xd.copy(), yd.copy()
    for _ in range(iterations):
        r2 = x * x + y * y
        g, dg = _radial_terms(r2, d8)
        xy = x * y
        fx = x * g + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x) - xd
        fy = y * g + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy - yd
        j11 = g + 2.0 * x * x * dg + 2.0 * p1 * y + 6.0 * p2 * x
        j12 = 2.0 * xy * dg + 2.0 * p1 * x + 2.0 * p2 * y
        j22 = g + 2.0 * y * y * dg + 6.0 * p1 * y + 2.0 * p2 * x
        det = j11 * j22 - j12 * j12  # the Jacobian is symmetric (j21 == j12)
        with np.errstate(divide="ignore", invalid="ignore"):
            dx = (j22 * fx - j12 * fy) / det
            dy = (j11 * fy - j12 * fx) / det
        x = x - dx
        y = y - dy
        if np.nanmax(np.abs(np.concatenate([np.ravel(dx), np.ravel(dy), [0.0]]))) < tolerance:
            break
    r2 = x * x + y * y
    x2, y2 = distort_xy(x, y, d8)
    with np.errstate(invalid="ignore"):
        bad = ~(np.hypot(x2 - xd, y2 - yd) <= 1e-9 * (1.0 + np.sqrt(r2)))
    out = np.stack([x, y], axis=-1)
    out[bad] = np.nan
    return out


def monotonic_radius2(d8: np.ndarray, r_max: float = 20.0, samples: int = 8001) -> float:
    """Largest r^2 up to which the radial distortion r -> r g(r^2) is increasing.

    Beyond it the polynomial folds back and maps points far outside the field of view into the
    image, so projections there are meaningless; :func:`~hmocap_ros.geometry.projection.project_points`
    marks them invisible.
    Tangential terms are ignored (they are tiny in any real calibration).
    """
    if not np.any(d8[[0, 1, 4, 5, 6, 7]]):
        return float("inf")
    r = np.linspace(0.0, r_max, samples)
    r2 = r * r
    num = 1.0 + r2 * (d8[0] + r2 * (d8[1] + r2 * d8[4]))
    den = 1.0 + r2 * (d8[5] + r2 * (d8[6] + r2 * d8[7]))
    g, dg = _radial_terms(r2, tuple(d8))
    slope = g + 2.0 * r2 * dg  # d(r g(r^2)) / dr
    bad = (slope <= 0.0) | (den <= 0.0) | (num <= 0.0)
    if not np.any(bad):
        return float("inf")
    first = int(np.argmax(bad))
    return float(r2[max(first - 1, 0)])
