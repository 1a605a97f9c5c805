"""Rotation helpers and body forward kinematics used by :mod:`hmocap_sim.retarget`.

Weighted Kabsch fits (Kabsch 1976; Markley 1988), the projection onto SO(3), minimal (swing)
rotations between directions (Rodrigues' formula), the BVH up axis, and the body's forward
kinematics in the convention of :class:`hmocap_sim.retarget_motion.Motion`.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["end_site_forward_kinematics", "joint_forward_kinematics", "kabsch", "nearest_rotation",
           "rotation_about_y", "swing", "topological_order", "unit_vectors", "up_axis_rotation"]


def unit_vectors(v: np.ndarray) -> np.ndarray:
    """``v`` (..., 3) scaled to unit length along its last axis (zero vectors left as they are)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def kabsch(
    rest_dirs: np.ndarray, observed_dirs: np.ndarray, weights: np.ndarray | None = None
) -> np.ndarray:
    """Rotations R minimising ``sum_i w_i |R a_i - b_i|^2`` (Kabsch 1976, with weights).

    Args:
        rest_dirs: (..., N, 3) vectors ``a_i`` (broadcast against ``observed_dirs``).
        observed_dirs: (..., N, 3) vectors ``b_i``.
        weights: (N,) or (..., N) non-negative weights; ones by default.

    Returns:
        (..., 3, 3) proper rotations (det +1).
    """
    a = np.asarray(rest_dirs, dtype=np.float64)
    b = np.asarray(observed_dirs, dtype=np.float64)
    w = np.ones(a.shape[-2]) if weights is None else np.asarray(weights, dtype=np.float64)
    h = np.einsum("...n,...ni,...nj->...ij", w, b, a)
    return nearest_rotation(h)


def nearest_rotation(m: np.ndarray) -> np.ndarray:
    """Projection of (..., 3, 3) matrices onto SO(3) (polar decomposition with det fix)."""
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt))
    d = np.where(d == 0, 1.0, d)
    u = u.copy()
    u[..., :, 2] *= d[..., None]
    return u @ vt


def swing(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Minimal rotations taking directions ``u`` to ``v`` (..., 3) -> (..., 3, 3).

    Rodrigues' formula with ``k = u x v``: ``R = I + [k]x + [k]x^2 / (1 + u.v)``; for opposite
    directions a half turn about an axis perpendicular to ``u``.
    """
    u, v = np.broadcast_arrays(unit_vectors(np.asarray(u, float)), unit_vectors(np.asarray(v, float)))
    k = np.cross(u, v)
    c = np.einsum("...i,...i->...", u, v)
    kx = np.zeros(k.shape + (3,))
    kx[..., 0, 1], kx[..., 0, 2], kx[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    kx[..., 1, 0], kx[..., 2, 0], kx[..., 2, 1] = k[..., 2], -k[..., 1], k[..., 0]
    opposite = c < -1.0 + 1e-9
    denom = np.where(opposite, 1.0, 1.0 + c)
    r = np.eye(3) + kx + kx @ kx / denom[..., None, None]
    if np.any(opposite):
        helper = np.where(np.abs(u[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        n = unit_vectors(np.cross(u, helper))
        half_turn = 2.0 * n[..., :, None] * n[..., None, :] - np.eye(3)
        r = np.where(opposite[..., None, None], half_turn, r)
    return r


def rotation_about_y(angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` (rad) about +Y (the room's up axis)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def up_axis_rotation(up: np.ndarray) -> np.ndarray:
    """Rotation taking the BVH axis nearest to ``up`` onto +Y, horizontal axes kept if possible."""
    axis = np.zeros(3)
    i = int(np.argmax(np.abs(up)))
    axis[i] = np.sign(up[i])
    if np.allclose(axis, [0, 1, 0]):
        return np.eye(3)
    if np.allclose(axis, [0, -1, 0]):
        return np.diag([1.0, -1.0, -1.0])
    return np.rint(swing(axis, np.array([0.0, 1.0, 0.0])))


def topological_order(parents: np.ndarray) -> list[int]:
    """Joint indices by depth in the tree of ``parents`` (-1: root), parents before children;
    ValueError when the parents hold a cycle."""
    depth = np.zeros(len(parents), dtype=int)
    for j in range(len(parents)):
        p, d = parents[j], 0
        while p >= 0:
            p, d = parents[p], d + 1
            if d > len(parents):
                raise ValueError("body parents contain a cycle")
        depth[j] = d
    return [int(j) for j in np.argsort(depth, kind="stable")]


def joint_forward_kinematics(
    local_rotations: np.ndarray, root_translation: np.ndarray, rest_joints: np.ndarray,
    parents: Sequence[int],
) -> tuple[np.ndarray, np.ndarray]:
    """Body forward kinematics (convention in ``Motion``).

    Returns positions (F, J, 3) and global rotations (F, J, 3, 3). A stand-in with the
    convention of ``hmocap_ros.body.kinematics.forward_kinematics`` (tested to agree), so this
    module does not depend on the body package.
    """
    local = np.asarray(local_rotations, float)
    rest = np.asarray(rest_joints, float)
    parents = np.asarray(parents, int)
    glob = np.empty_like(local)
    pos = np.empty(local.shape[:2] + (3,))
    for j in topological_order(parents):
        p = parents[j]
        if p < 0:
            glob[:, j] = local[:, j]
            pos[:, j] = root_translation
        else:
            glob[:, j] = glob[:, p] @ local[:, j]
            pos[:, j] = pos[:, p] + glob[:, p] @ (rest[j] - rest[p])
    return pos, glob


def end_site_forward_kinematics(
    positions: np.ndarray, glob: np.ndarray, rest_joints: np.ndarray,
    end_sites_rest: np.ndarray, end_site_parents: Sequence[int],
) -> np.ndarray:
    """(F, E, 3) end-site positions from posed joints and their global rotations."""
    par = np.asarray(end_site_parents, int)
    offsets = np.asarray(end_sites_rest, float) - np.asarray(rest_joints, float)[par]
    return positions[:, par] + np.einsum("feij,ej->fei", glob[:, par], offsets)
