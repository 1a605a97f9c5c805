"""Rigid transforms as (R, t) pairs, vectorised: Rodrigues vectors <-> matrices, composition,
inversion and rotation averaging."""

from __future__ import annotations

import numpy as np

__all__ = ["rotation_matrices", "rotation_vectors", "invert", "compose", "mean_rotation",
           "rotation_angle_deg"]


def rotation_matrices(rvecs: np.ndarray) -> np.ndarray:
    """(N, 3) Rodrigues vectors -> (N, 3, 3) rotation matrices (Rodrigues' formula)."""
    rvecs = np.asarray(rvecs, np.float64).reshape(-1, 3)
    theta = np.linalg.norm(rvecs, axis=1)
    small = theta < 1e-12
    k = rvecs / np.where(small, 1.0, theta)[:, None]
    K = np.zeros((len(rvecs), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K -= K.transpose(0, 2, 1)
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return np.eye(3)[None] + s * K + (1.0 - c) * (K @ K)


def rotation_vectors(R: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotation matrices -> (N, 3) Rodrigues vectors (via scipy's quaternion path,
    exact near 180 degrees)."""
    from scipy.spatial.transform import Rotation

    # a writable copy: SciPy 1.11 (Ubuntu 24.04's) refuses a read-only array
    return Rotation.from_matrix(np.array(R, np.float64).reshape(-1, 3, 3)).as_rotvec()


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
