"""Inverse kinematics of the gesture poses: weighted tasks, a damped least-squares solver
and pose specifications solved in stages.

A :class:`PoseSpec` holds a base pose and IK stages ``(dof_names, tasks, prior)``;
:func:`solve_spec` solves the stages in order with :func:`solve_ik` (Levenberg-Marquardt on a
numeric Jacobian, inside the joint limits, with a prior towards a natural arm) and restarts a
stage from other arms when a position target is missed.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hmocap_ros.body.skeleton import clip_pose, pose_to_local_rotations
from hmocap_ros.gestures.classes import ALL_GESTURES, class_id
from hmocap_sim.gesture_body import Kinematics, Subject, hand_axes, kinematics, unit

RESTARTS = 4
RESTART_ERROR_M = 0.02


@dataclass
class Task:
    """One IK objective, weighted (weights are per metre for positions, per unit vector
    for directions).

    kind "point": point ``a`` at ``target``; "touch": points ``a`` and ``b`` together
    (``target`` an offset b - a, default 0); "dir": unit direction ``a`` -> ``b`` along
    ``target``; "axis": hand axis ``a`` ("l_volar", "r_d", "l_radial", ...) along
    ``target``.
    """

    kind: str
    a: str
    target: np.ndarray | None = None
    b: str = ""
    weight: float = 1.0

def _point_residual(model, kin: Kinematics, t: Task) -> np.ndarray:
    return kin.point(model, t.a) - t.target


def _touch_residual(model, kin: Kinematics, t: Task) -> np.ndarray:
    off = 0.0 if t.target is None else t.target
    return kin.point(model, t.b) - kin.point(model, t.a) - off


def _dir_residual(model, kin: Kinematics, t: Task) -> np.ndarray:
    d = unit(kin.point(model, t.b) - kin.point(model, t.a))
    return d - t.target


def _axis_residual(model, kin: Kinematics, t: Task) -> np.ndarray:
    side, axis = t.a.split("_")
    d, radial, volar = hand_axes(model, kin, side)
    v = {"d": d, "radial": radial, "volar": volar}[axis]
    return v - t.target


#: Unweighted residual (B, 3) of each task kind: kind -> residual(model, kin, task).
TASK_RESIDUALS = {"point": _point_residual, "touch": _touch_residual, "dir": _dir_residual,
                  "axis": _axis_residual}


def _task_residuals(model, kin: Kinematics, tasks) -> np.ndarray:
    """Weighted residuals of all tasks, (B, 3 * len(tasks))."""
    out = []
    for t in tasks:
        residual = TASK_RESIDUALS.get(t.kind)
        if residual is None:  # pragma: no cover - programming error
            raise ValueError(f"unknown IK task kind {t.kind!r}")
        out.append(t.weight * residual(model, kin, t))
    return np.concatenate(out, axis=1)


def solve_ik(model, subject: Subject, params: np.ndarray, dof_names, tasks, *,
             prior: dict | None = None, prior_weight: float = 0.04, iterations: int = 40,
             tolerance: float = 1e-3, return_cost: bool = False):
    """Damped least squares (Levenberg-Marquardt) over the DoFs ``dof_names``.

    Minimises the sum of squared task residuals plus prior_weight^2 * (q - q_prior)^2
    (radians) for the DoFs named in ``prior`` (name -> degrees), inside the joint limits;
    the Jacobian is a forward difference evaluated as one batch.  Stops after
    ``iterations`` or when a step improves the cost by less than ``tolerance`` (relative,
    or the cost is below 1e-8).  Returns the new (D,)
    parameter vector (and the final cost with ``return_cost``).
    """
    skel = model.skeleton
    dof_names = list(dof_names)
    idx = np.array([skel.dof_index(n) for n in dof_names], dtype=np.intp)
    p = clip_pose(skel, np.asarray(params, dtype=np.float64))
    prior = {n: v for n, v in (prior or {}).items() if n in dof_names}
    p_idx = np.array([skel.dof_index(n) for n in prior], dtype=np.intp)
    q_prior = np.deg2rad(np.array(list(prior.values()), dtype=np.float64))
    lo, hi = skel.lower[idx], skel.upper[idx]
    eps = 1e-4
    lam = 1e-3

    base_rot = pose_to_local_rotations(skel, p[None])[0][0]
    joints = sorted({int(skel.dof_joint[i]) for i in idx})
    if 0 in joints:  # the root's rotation also carries its translation: rebuild everything
        base_rot, joints = None, ()

    def cost_terms(batch):
        r = _task_residuals(model, kinematics(model, subject, batch, base_rot, joints), tasks)
        reg = prior_weight * (batch[:, p_idx] - q_prior)
        return np.concatenate([r, reg], axis=1)

    r0 = cost_terms(p[None])[0]
    c0 = r0 @ r0
    for _ in range(iterations):
        batch = np.repeat(p[None], len(idx), axis=0)
        batch[np.arange(len(idx)), idx] += eps
        jac = (cost_terms(batch) - r0[None]).T / eps  # (R, n)
        jtj = jac.T @ jac
        g = jac.T @ r0
        while True:
            step = -np.linalg.solve(jtj + lam * (np.diag(np.diag(jtj)) + 1e-6 * np.eye(len(idx))), g)
            cand = p.copy()
            cand[idx] = np.clip(p[idx] + step, lo, hi)
            cand = clip_pose(skel, cand)
            r1 = cost_terms(cand[None])[0]
            c1 = r1 @ r1
            if c1 < c0:
                lam = max(lam * 0.3, 1e-7)
                break
            lam *= 10.0
            if lam > 1e6:
                return (p, c0) if return_cost else p
        improvement = c0 - c1
        p, r0, c0 = cand, r1, c1
        if improvement < tolerance * max(c0, 1e-12) or c0 < 1e-8:
            break
    return (p, c0) if return_cost else p


@dataclass
class PoseSpec:
    """A pose to solve: base parameters (torso, legs, fingers, starting arms) and IK stages
    ``(dof_names, tasks, prior)`` solved in order.  ``kind`` is a gesture class or a
    negative kind, ``side`` the main hand ("" when none)."""

    kind: str
    side: str
    base: np.ndarray
    stages: list = field(default_factory=list)

    @property
    def class_id(self) -> int:
        return class_id(self.kind) if self.kind in ALL_GESTURES else 0


def ground(model, subject: Subject, params: np.ndarray) -> np.ndarray:
    """Raise or lower the root so the lowest ankle/toe point stays at its rest height."""
    p = np.array(params, dtype=np.float64, copy=True)
    feet = [model.joint_index(n) for n in ("l_ankle", "r_ankle")]
    toes = [model.end_site_names.index(n) for n in ("l_toe", "r_toe")]
    rest_low = min(subject.rest_joints[feet, 1].min(), subject.rest_ends[toes, 1].min())
    kin = kinematics(model, subject, p)
    low = min(kin.joints[0, feet, 1].min(), kin.ends[0, toes, 1].min())
    p[model.skeleton.translation_dofs[1]] += rest_low - low
    return p


def solve_spec(model, subject: Subject, spec: PoseSpec, start: np.ndarray | None = None,
               iterations: int = 40, restarts: int | None = None) -> np.ndarray:
    """Solve a spec's IK stages (from ``start`` if given, else its base) and put the feet
    on the floor; returns the (D,) body-frame parameters.  A stage whose main position
    targets stay more than 2 cm off is re-solved from up to ``restarts`` (default
    :data:`RESTARTS`) other starting arms."""
    restarts = RESTARTS if restarts is None else restarts
    p = np.array(spec.base if start is None else start, dtype=np.float64, copy=True)
    if start is not None:  # keep the spec's torso, legs and non-IK fingers
        solved = {d for dofs, _, _ in spec.stages for d in dofs}
        keep = np.array([n not in solved for n in model.skeleton.dof_names])
        p[keep] = spec.base[keep]
    for dofs, tasks, prior in spec.stages:
        best, cost = solve_ik(model, subject, p, dofs, tasks, prior=prior, iterations=iterations,
                              return_cost=True)
        # A missed position target is a local minimum: restart from other arm configurations
        # (fixed seeds, so the result stays deterministic) and keep the best solution.
        for restart in range(restarts):
            if _worst_point_error(model, subject, best, tasks) < RESTART_ERROR_M:
                break
            start = p.copy()
            idx = [model.skeleton.dof_index(d) for d in dofs]
            lo, hi = model.skeleton.lower[idx], model.skeleton.upper[idx]
            start[idx] = lo + (hi - lo) * np.random.default_rng(restart).uniform(0.25, 0.75, len(idx))
            cand, c = solve_ik(model, subject, start, dofs, tasks, prior=prior, iterations=max(iterations, 40),
                               return_cost=True)
            if c < cost:
                best, cost = cand, c
        p = best
    return ground(model, subject, p)


def _worst_point_error(model, subject: Subject, params: np.ndarray, tasks) -> float:
    """Largest error (m) of the point and touch tasks that carry most weight (>= 1)."""
    kin = kinematics(model, subject, params)
    errs = [np.linalg.norm(_task_residuals(model, kin, [t])) / t.weight
            for t in tasks if t.kind in ("point", "touch") and t.weight >= 1.0]
    return max(errs, default=0.0)


def jitter_spec(spec: PoseSpec, rng: np.random.Generator, position_sigma: float = 0.008,
                angle_sigma_deg: float = 1.5, model=None) -> PoseSpec:
    """The same pose with small random changes (for the motion of a held gesture): point
    targets move by N(0, position_sigma) metres, torso and head angles by
    N(0, angle_sigma_deg); relative tasks (touch, dir, axis) are unchanged."""
    base = spec.base.copy()
    if model is not None:
        names = model.skeleton.dof_names
        torso = [i for i, n in enumerate(names)
                 if n.split("_")[0] in ("spine", "chest", "neck", "head")]
        base[torso] += np.deg2rad(rng.normal(0.0, angle_sigma_deg, len(torso)))
    stages = []
    for dofs, tasks, prior in spec.stages:
        new = []
        for t in tasks:
            if t.kind == "point":
                t = Task(t.kind, t.a, t.target + rng.normal(0.0, position_sigma, 3), t.b, t.weight)
            new.append(t)
        stages.append((dofs, new, prior))
    return PoseSpec(spec.kind, spec.side, base, stages)
