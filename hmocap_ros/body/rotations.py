"""Batched rotation helpers of the body model (numpy): revolute twists, hinge and Euler projections.

The rotation primitives (exponential map, quaternions) are :mod:`hmocap_ros.geometry.rotations`.

All functions take stacks of shape (..., 3, 3) / (..., 3) and never loop in Python over
the batch.  Angles are radians.
"""
from __future__ import annotations

import numpy as np

from hmocap_ros.geometry.rotations import rotvec_to_matrix, skew

_EPS = 1e-12


def axis_angle_matrix(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """exp(angle [axis]x) for one unit axis and a batch of angles (...,) -> (..., 3, 3).

    Rodrigues' formula R = I + sin(t) K + (1 - cos(t)) K^2: the exponential map of a
    revolute twist with a fixed axis (thesis eq. 2.11).
    """
    k = skew(axis)
    k2 = k @ k
    t = np.asarray(angle, dtype=np.float64)[..., None, None]
    return np.eye(3) + np.sin(t) * k + (1.0 - np.cos(t)) * k2


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
