"""Small batched rotation helpers (numpy): exponential map, hinge and Euler projections.

All functions take stacks of shape (..., 3, 3) / (..., 3) and never loop in Python over
the batch.  Angles are radians.
"""
from __future__ import annotations

import numpy as np

_EPS = 1e-12


def skew(axis: np.ndarray) -> np.ndarray:
    """Cross-product matrix [a]x of one axis (3,)."""
    x, y, z = np.asarray(axis, dtype=np.float64)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def axis_angle_matrix(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """exp(angle [axis]x) for one unit axis and a batch of angles (...,) -> (..., 3, 3).

    Rodrigues' formula R = I + sin(t) K + (1 - cos(t)) K^2: the exponential map of a
    revolute twist with a fixed axis (thesis eq. 2.11).
    """
    k = skew(axis)
    k2 = k @ k
    t = np.asarray(angle, dtype=np.float64)[..., None, None]
    return np.eye(3) + np.sin(t) * k + (1.0 - np.cos(t)) * k2


def rotvec_to_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Exponential map of rotation vectors (..., 3) -> (..., 3, 3)."""
    v = np.asarray(rotvec, dtype=np.float64)
    theta = np.linalg.norm(v, axis=-1)
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    # sin(t)/t and (1-cos t)/t^2 with their Taylor limits near zero
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    zero = np.zeros_like(x)
    k = np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1),
                  np.stack([-y, x, zero], -1)], -2)
    return np.eye(3) + a[..., None, None] * k + b[..., None, None] * (k @ k)


def matrix_to_rotvec(r: np.ndarray) -> np.ndarray:
    """Logarithm map (..., 3, 3) -> rotation vectors (..., 3) with angle in [0, pi]."""
    r = np.asarray(r, dtype=np.float64)
    cos_t = np.clip((np.trace(r, axis1=-2, axis2=-1) - 1.0) * 0.5, -1.0, 1.0)
    w = np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0],
                  r[..., 1, 0] - r[..., 0, 1]], -1)
    sin_t = 0.5 * np.linalg.norm(w, axis=-1)
    theta = np.arctan2(sin_t, cos_t)
    scale = np.where(sin_t > 1e-8, theta / (2.0 * np.maximum(sin_t, 1e-300)), 0.5)
    out = w * scale[..., None]
    # near pi the antisymmetric part vanishes: take the axis from R + I
    near_pi = (sin_t <= 1e-6) & (cos_t < 0.0)
    if np.any(near_pi):
        m = (r[near_pi] + np.eye(3)) * 0.5
        col = np.argmax(np.diagonal(m, axis1=-2, axis2=-1), axis=-1)
        axis = m[np.arange(len(m)), :, col]
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        out[near_pi] = axis * theta[near_pi][..., None]
    return out


def hinge_angle(r: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Least-squares angle t maximising trace(exp(t[axis]x)^T R) for R (..., 3, 3).

    With K = [axis]x, trace(exp(tK)^T R) = const + A sin t - C cos t where A = -tr(K R)
    and C = tr(K^2 R), so t = atan2(A, -C); exact when R is a rotation about ``axis``.
    """
    k = skew(axis)
    a = -np.einsum("ik,...ki->...", k, r)
    c = np.einsum("ik,...ki->...", k @ k, r)
    return np.arctan2(a, -c)


def euler2_angles(r: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple:
    """Project R onto exp(alpha[a]x) exp(beta[b]x) with a ⟂ b.

    alpha turns b onto the projection of R b on the plane normal to a (exact for R in the
    set); beta is then the least-squares hinge angle of the remainder about b.
    """
    rb = r @ b
    alpha = np.arctan2(rb @ np.cross(a, b), rb @ b)
    rest = np.swapaxes(axis_angle_matrix(a, alpha), -1, -2) @ r
    return alpha, hinge_angle(rest, b)


def euler3_angles(r: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Angles (..., 3) with R = exp(t0[a0]x) exp(t1[a1]x) exp(t2[a2]x), axes orthonormal rows.

    Intrinsic X-Y-Z decomposition in the frame of the axes; a left-handed axis triple is
    handled by flipping the last axis and its angle.
    """
    axes = np.asarray(axes, dtype=np.float64)
    sign = 1.0
    if np.linalg.det(axes) < 0:
        axes = axes.copy()
        axes[2] = -axes[2]
        sign = -1.0
    rp = axes @ r @ axes.T  # R expressed in the joint frame
    beta = np.arcsin(np.clip(rp[..., 0, 2], -1.0, 1.0))
    alpha = np.arctan2(-rp[..., 1, 2], rp[..., 2, 2])
    gamma = np.arctan2(-rp[..., 0, 1], rp[..., 0, 0])
    return np.stack([alpha, beta, sign * gamma], -1)


def swing_twist_angles(r: np.ndarray, swing_axes: np.ndarray, twist_axis: np.ndarray) -> np.ndarray:
    """Decompose R = exp([s]x) exp(t[d]x): swing vector components along the two swing axes
    (both ⟂ d) and the twist angle t about d (..., 3).

    The swing is the shortest rotation taking the rest bone direction d onto R d, so the
    decomposition is singular only when the bone points opposite to its rest direction.
    """
    d = np.asarray(twist_axis, dtype=np.float64)
    dp = r @ d
    cross = np.cross(d, dp)
    s = np.linalg.norm(cross, axis=-1)
    c = dp @ d
    angle = np.arctan2(s, c)
    unit = np.where(s[..., None] > _EPS, cross / np.maximum(s, _EPS)[..., None], swing_axes[0])
    swing = unit * angle[..., None]
    comps = swing @ np.asarray(swing_axes, dtype=np.float64).T
    sw = rotvec_to_matrix(swing)
    twist = hinge_angle(np.swapaxes(sw, -1, -2) @ r, d)
    return np.concatenate([comps, twist[..., None]], -1)
