"""Rotations, one implementation each: unit quaternions ``(x, y, z, w)`` (the order of
``geometry_msgs/Quaternion``), rotation vectors (Rodrigues' formula, the exponential map and
its logarithm), rigid transforms as ``(R, t)`` pairs, and rotation averaging.

Every function takes stacks of shape ``(..., 3, 3)`` / ``(..., 3)`` where it says so and never
loops in Python over the batch; angles are radians unless a name says degrees. Used by the
cameras (:mod:`.pinhole_camera`), TF (:mod:`hmocap_ros.io.tf`), the body model
(:mod:`hmocap_ros.body.rotations`, thesis eq. 2.11) and the calibration's bundle adjustment.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "QUATERNION_TOLERANCE",
    "compose",
    "invert",
    "matrix_to_quaternion",
    "matrix_to_rotvec",
    "mean_rotation",
    "quaternion_to_matrix",
    "rotation_angle_deg",
    "rotvec_to_matrix",
    "skew",
]

#: Tolerance on the norm of a pose quaternion before it is renormalised.
QUATERNION_TOLERANCE = 1e-3


def quaternion_to_matrix(quaternion_xyzw, tolerance: float | None = QUATERNION_TOLERANCE) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion ``(x, y, z, w)``, renormalised first.

    Raises ``ValueError`` if the quaternion is not 4 finite numbers, or its norm differs from 1
    by more than ``tolerance`` (None: any non-zero norm, the quaternion of a tf2 transform).
    """
    q = np.asarray(quaternion_xyzw, dtype=np.float64)
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise ValueError(f"quaternion must be 4 finite numbers (x, y, z, w), got {quaternion_xyzw!r}")
    norm = float(np.linalg.norm(q))
    if tolerance is None and not norm > 0:
        raise ValueError(f"a quaternion must be 4 finite numbers (x, y, z, w), not all zero: {quaternion_xyzw!r}")
    if tolerance is not None and abs(norm - 1.0) > tolerance:
        raise ValueError(f"quaternion {q.tolist()} is not a unit quaternion (norm {norm:.6g})")
    return Rotation.from_quat(q / norm).as_matrix()


def matrix_to_quaternion(rotation) -> np.ndarray:
    """Unit quaternion ``(x, y, z, w)`` of a rotation matrix, with ``w >= 0`` (canonical sign)."""
    # a writable copy: SciPy 1.11 (Ubuntu 24.04's) refuses a read-only array (a camera's R)
    return Rotation.from_matrix(np.array(rotation, dtype=np.float64)).as_quat(canonical=True)


def skew(axis: np.ndarray) -> np.ndarray:
    """Cross-product matrix [a]x of one axis (3,)."""
    x, y, z = np.asarray(axis, dtype=np.float64)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


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


def invert(R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of ``x -> R x + t`` (batched or single)."""
    Rt = np.swapaxes(R, -1, -2)
    return Rt, -np.einsum("...ij,...j->...i", Rt, t)


def compose(Ra, ta, Rb, tb) -> tuple[np.ndarray, np.ndarray]:
    """``a o b``: ``x -> Ra (Rb x + tb) + ta``."""
    return Ra @ Rb, np.einsum("...ij,...j->...i", Ra, tb) + ta


def mean_rotation(R: np.ndarray) -> np.ndarray:
    """Chordal L2 mean of (N, 3, 3) rotations: the rotation nearest their arithmetic mean."""
    U, _, Vt = np.linalg.svd(np.mean(R, axis=0))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def rotation_angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Angle (degrees) of the rotation between ``Ra`` and ``Rb`` (batched)."""
    cos = (np.trace(np.swapaxes(Ra, -1, -2) @ Rb, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
