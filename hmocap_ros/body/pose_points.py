"""Joint and end-site positions of many poses at once: forward kinematics (eq. 2.11) in one
numba kernel, for the per-frame fits that evaluate a pose and its finite differences.

:func:`~hmocap_ros.body.kinematics.forward_kinematics` with
:func:`~hmocap_ros.body.skeleton.pose_to_local_rotations` gives the same numbers (to rounding)
through stacked numpy products, whose per-call overhead dominates for a few dozen poses. Here
the whole chain, rotations from the parameters included, is one compiled loop over poses and
joints: a kinematic fit that needs 31 poses per iteration (a pose and its 30 finite
differences) pays microseconds instead of milliseconds.

Rotations follow :mod:`hmocap_ros.body.skeleton`: a joint's local rotation is the ordered
product of its DoFs' exponential maps (Rodrigues), a ball joint's is ``exp([s]x) exp(t [d]x)``
with the swing vector ``s = flex * a_flex + abd * a_abd``.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numba
import numpy as np

__all__ = ["PosePoints"]

_FIXED, _CHAIN, _SWING_TWIST = 0, 1, 2


@numba.njit(cache=True, inline="always")
def _axis_angle(ax, ay, az, angle, out):
    """out = exp(angle [a]x) for a unit axis (Rodrigues)."""
    s = np.sin(angle)
    c1 = 1.0 - np.cos(angle)
    out[0, 0] = 1.0 - c1 * (ay * ay + az * az)
    out[0, 1] = -s * az + c1 * ax * ay
    out[0, 2] = s * ay + c1 * ax * az
    out[1, 0] = s * az + c1 * ax * ay
    out[1, 1] = 1.0 - c1 * (ax * ax + az * az)
    out[1, 2] = -s * ax + c1 * ay * az
    out[2, 0] = -s * ay + c1 * ax * az
    out[2, 1] = s * ax + c1 * ay * az
    out[2, 2] = 1.0 - c1 * (ax * ax + ay * ay)


@numba.njit(cache=True)
def _pose_points(params, kinds, dof_idx, n_dofs, axes, parents, translation, offsets,
                 end_parents, end_offsets, joints_out, ends_out):
    n_poses, n_joints = params.shape[0], kinds.shape[0]
    g = np.empty((n_joints, 3, 3))
    local = np.empty((3, 3))
    step = np.empty((3, 3))
    tmp = np.empty((3, 3))
    for b in range(n_poses):
        for j in range(n_joints):
            # local rotation of joint j
            for r in range(3):
                for c in range(3):
                    local[r, c] = 1.0 if r == c else 0.0
            kind = kinds[j]
            if kind == _SWING_TWIST:
                f = params[b, dof_idx[j, 0]]
                a = params[b, dof_idx[j, 1]]
                sx = f * axes[j, 0, 0] + a * axes[j, 1, 0]
                sy = f * axes[j, 0, 1] + a * axes[j, 1, 1]
                sz = f * axes[j, 0, 2] + a * axes[j, 1, 2]
                theta = np.sqrt(sx * sx + sy * sy + sz * sz)
                if theta > 1e-12:
                    _axis_angle(sx / theta, sy / theta, sz / theta, theta, local)
                _axis_angle(axes[j, 2, 0], axes[j, 2, 1], axes[j, 2, 2],
                            params[b, dof_idx[j, 2]], step)
                for r in range(3):
                    for c in range(3):
                        tmp[r, c] = (local[r, 0] * step[0, c] + local[r, 1] * step[1, c]
                                     + local[r, 2] * step[2, c])
                local[:, :] = tmp
            elif kind == _CHAIN:
                for k in range(n_dofs[j]):
                    _axis_angle(axes[j, k, 0], axes[j, k, 1], axes[j, k, 2],
                                params[b, dof_idx[j, k]], step)
                    for r in range(3):
                        for c in range(3):
                            tmp[r, c] = (local[r, 0] * step[0, c] + local[r, 1] * step[1, c]
                                         + local[r, 2] * step[2, c])
                    local[:, :] = tmp
            p = parents[j]
            if p < 0:
                g[j] = local
                for r in range(3):
                    joints_out[b, j, r] = params[b, translation[r]]
            else:
                for r in range(3):
                    for c in range(3):
                        g[j, r, c] = (g[p, r, 0] * local[0, c] + g[p, r, 1] * local[1, c]
                                      + g[p, r, 2] * local[2, c])
                    joints_out[b, j, r] = joints_out[b, p, r] + (
                        g[p, r, 0] * offsets[j, 0] + g[p, r, 1] * offsets[j, 1]
                        + g[p, r, 2] * offsets[j, 2])
        for e in range(end_parents.shape[0]):
            q = end_parents[e]
            for r in range(3):
                ends_out[b, e, r] = joints_out[b, q, r] + (
                    g[q, r, 0] * end_offsets[e, 0] + g[q, r, 1] * end_offsets[e, 1]
                    + g[q, r, 2] * end_offsets[e, 2])


@dataclass(frozen=True, eq=False)
class PosePoints:
    """Joint and end-site positions of poses of one skeleton on one (shaped) rest.

    ``PosePoints.of(model, rest)``; ``points(params (B, D)) -> (joints (B, J, 3), end sites
    (B, E, 3))`` in the model's world frame, as ``forward_kinematics`` and
    ``end_site_positions`` give them.
    """

    kinds: np.ndarray
    dof_idx: np.ndarray
    n_dofs: np.ndarray
    axes: np.ndarray
    parents: np.ndarray
    translation: np.ndarray
    offsets: np.ndarray
    end_parents: np.ndarray
    end_offsets: np.ndarray

    @classmethod
    def of(cls, model, rest=None) -> "PosePoints":
        """The kernel's arrays for ``model`` on ``rest`` (a ShapedRest with (J, 3) joints and
        (E, 3) end sites; None: the model's own rest)."""
        skel = model.skeleton
        joints = np.asarray(skel.joints_rest if rest is None else rest.joints, np.float64)
        ends = np.asarray(model.end_sites_rest if rest is None else rest.end_sites, np.float64)
        parents = np.asarray(model.parents, np.int64)
        n_joints = len(parents)
        kinds = np.zeros(n_joints, np.int64)
        dof_idx = np.zeros((n_joints, 3), np.int64)
        n_dofs = np.zeros(n_joints, np.int64)
        axes = np.zeros((n_joints, 3, 3))
        for j, (kind, dofs, ax) in enumerate(zip(skel.joint_kind, skel.joint_dofs,
                                                 skel.joint_axes)):
            if kind == "fixed" or not dofs:
                continue
            kinds[j] = _SWING_TWIST if kind == "swing_twist" else _CHAIN
            n_dofs[j] = len(dofs)
            dof_idx[j, :len(dofs)] = dofs
            axes[j, :len(dofs)] = np.asarray(ax, np.float64).reshape(len(dofs), 3)
        offsets = joints - joints[np.maximum(parents, 0)]
        offsets[0] = 0.0
        end_parents = np.asarray(model.end_site_parents, np.int64)
        end_offsets = ends - joints[end_parents]
        return cls(kinds, dof_idx, n_dofs, axes, parents,
                   np.asarray(skel.translation_dofs, np.int64), offsets, end_parents,
                   end_offsets)

    def with_sites(self, parents, offsets) -> "PosePoints":
        """The same kinematics with other end sites: ``parents`` (S,) joint indices and
        ``offsets`` (S, 3) in the parent's frame at rest (model axes, metres)."""
        return dataclasses.replace(self, end_parents=np.asarray(parents, np.int64),
                                   end_offsets=np.asarray(offsets, np.float64).reshape(-1, 3))

    def points(self, params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        params = np.ascontiguousarray(np.atleast_2d(params), dtype=np.float64)
        n = len(params)
        joints = np.empty((n, len(self.parents), 3))
        ends = np.empty((n, len(self.end_parents), 3))
        _pose_points(params, self.kinds, self.dof_idx, self.n_dofs, self.axes, self.parents,
                     self.translation, self.offsets, self.end_parents, self.end_offsets,
                     joints, ends)
        return joints, ends
