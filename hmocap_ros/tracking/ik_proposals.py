"""Detector-driven propagation: IK particles for the arms and legs (thesis sec. 2.5.2).

"Pose variables from the appropriate layer are drawn by means of Inverse Kinematics using the
detected end-effector locations. Particles drawn from this proposal are termed IK particles";
the other particles diffuse as before. The share of IK particles follows the *IK survival
rate*: above 0.5 a small fraction of regular particles becomes IK particles, below it the
reverse, with at least 25% of each kind.

Inverse kinematics of an arm (shoulder swing 2 DoF, twist, elbow flex) onto a hand position
has a one-parameter family of solutions (the elbow's swivel about the shoulder-hand line);
the silhouettes are what tells them apart. So :meth:`IKProposer.solve` keeps that family
rather than one solution: ``n_seeds`` configurations drawn uniformly within the joint limits
(the rest of the body at the reference pose) each take ``iterations`` damped least-squares
steps (Jacobian by finite differences, damping ``damping``, joint limits enforced) towards the
detected hand; the seeds that end within ``tolerance`` of it are the IK solutions, spread
along the swivel. Batched forward kinematics, no loop over seeds.

Choices where the thesis is vague:

- End-effectors: a hand is the midpoint of wrist and hand tip (the detector returns the end
  of a skin blob, see ``extremity_detection``), a foot its toe end site (where the hull's
  geodesic extremum, averaged over 8 cm, lands: nearer to it than to the ankle-toe midpoint,
  docs/tracking.md, sec. 3.5); the head is the midpoint of head joint and head top. IK drives the
  arms and legs; the head detection serves the classification (it keeps the face from being
  taken for a hand) and not the torso layer, whose 6 root DoFs the silhouettes fix well.
- IK survival rate: the weighted share of the final layer's particles whose hand lies within
  ``survival_radius`` of the detection (the particles the filter kept where the detector
  said), measured per arm; the IK fraction moves by ``fraction_step`` per frame within
  ``[min_fraction, 1 - min_fraction]``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hmocap_ros.body.kinematics import end_site_positions, forward_kinematics
from hmocap_ros.body.skeleton import SWING_NORM_MAX, pose_to_local_rotations
from hmocap_ros.tracking.limb_proposals import LIMBS

__all__ = ["IKParams", "IKProposer", "LIMB_OF"]

#: end-effector index (extremity_detection.END_EFFECTORS) -> limb it drives
LIMB_OF = {0: "l_arm", 1: "r_arm", 3: "l_leg", 4: "r_leg"}


@dataclass(frozen=True)
class IKParams:
    """Sizes of the IK search and of the IK-particle share (see the module docstring)."""

    n_seeds: int = 96
    iterations: int = 8
    damping: float = 0.05       #: m, damping lambda of the least-squares steps
    tolerance: float = 0.04     #: m, an IK solution's hand is this close to the detection
    start_fraction: float = 0.5
    min_fraction: float = 0.25
    fraction_step: float = 0.05
    survival_radius: float = 0.08


class IKProposer:
    """IK solutions of the arms onto detected hands, and the per-arm IK-particle share."""

    def __init__(self, model, params: IKParams | None = None):
        self.model = model
        self.skel = model.skeleton
        self.params = params or IKParams()
        names = list(map(str, model.joint_names))
        ends = list(map(str, model.end_site_names))
        self._midpoints = (  # (joint, end site) whose midpoint is the hand / head end-effector
            (names.index("l_wrist"), ends.index("l_hand_tip")),
            (names.index("r_wrist"), ends.index("r_hand_tip")),
            (names.index("head"), ends.index("head_top")),
        )
        self._toes = (ends.index("l_toe"), ends.index("r_toe"))  # the feet's end-effectors
        self._dofs = {}
        for limb in LIMB_OF.values():
            swing, other, _, _ = LIMBS[limb]
            self._dofs[limb] = (np.array([self.skel.dof_index(d) for d in swing]),
                                np.array([self.skel.dof_index(d) for d in other]))
        self.reset()

    def reset(self) -> None:
        """Back to the starting IK share (a new track)."""
        self.fraction = {limb: self.params.start_fraction for limb in LIMB_OF.values()}

    def dofs(self, limb: str) -> np.ndarray:
        swing, other = self._dofs[limb]
        return np.concatenate([swing, other])

    def end_effectors(self, params: np.ndarray, rest) -> np.ndarray:
        """(B, 5, 3) left hand, right hand, head, left foot, right foot centres of poses (B, D)
        on the shaped rest (the order of ``extremity_detection.END_EFFECTORS``)."""
        rot, root_t = pose_to_local_rotations(self.skel, np.atleast_2d(params))
        transforms, joints = forward_kinematics(rot, root_t, rest.joints, self.model.parents)
        ends = end_site_positions(transforms, rest.end_sites, self.model.end_site_parents,
                                  rest.joints)
        return np.stack([0.5 * (joints[:, j] + ends[:, e]) for j, e in self._midpoints]
                        + [ends[:, e] for e in self._toes], axis=1)

    def solve(self, limb: str, target: np.ndarray, reference: np.ndarray, rest,
              rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """IK solutions of ``limb`` putting its hand at ``target`` (3,): (values (K, n), dist (K,)).

        values are the limb's DoFs (order of :meth:`dofs`); K may be 0 when the target is out
        of reach from the reference pose's shoulder.
        """
        p = self.params
        swing, other = self._dofs[limb]
        dofs = np.concatenate([swing, other])
        e_idx = {limb_: e for e, limb_ in LIMB_OF.items()}[limb]
        lower = np.asarray(self.skel.lower)[dofs]
        upper = np.asarray(self.skel.upper)[dofs]
        n_dofs = dofs.size
        vals = lower + (upper - lower) * rng.random((p.n_seeds, n_dofs))
        vals = self._limit_swing(vals, swing.size)
        base = np.asarray(reference, dtype=np.float64)
        h = 1e-4
        probe = np.vstack([np.zeros(n_dofs), h * np.eye(n_dofs)])  # (1 + n, n)

        def hand(v: np.ndarray) -> np.ndarray:
            x = np.repeat(base[None], len(v), axis=0)
            x[:, dofs] = v
            return self.end_effectors(x, rest)[:, e_idx]

        lam2 = p.damping ** 2
        for _ in range(p.iterations):
            f = hand((vals[:, None] + probe[None]).reshape(-1, n_dofs)).reshape(
                p.n_seeds, n_dofs + 1, 3)
            jac = (f[:, 1:] - f[:, :1]).transpose(0, 2, 1) / h  # (S, 3, n)
            err = target - f[:, 0]
            jjt = jac @ jac.transpose(0, 2, 1) + lam2 * np.eye(3)
            step = (jac.transpose(0, 2, 1) @ np.linalg.solve(jjt, err[..., None]))[..., 0]
            vals = self._limit_swing(np.clip(vals + step, lower, upper), swing.size)
        d = np.linalg.norm(hand(vals) - target, axis=1)
        ok = d <= p.tolerance
        return vals[ok], d[ok]

    @staticmethod
    def _limit_swing(vals: np.ndarray, n_swing: int) -> np.ndarray:
        sw = vals[:, :n_swing]
        norm = np.linalg.norm(sw, axis=1, keepdims=True)
        vals[:, :n_swing] = sw * np.minimum(1.0, SWING_NORM_MAX / np.maximum(norm, 1e-12))
        return vals

    def apply(self, particles: np.ndarray, detections: np.ndarray, reference: np.ndarray, rest,
              rng: np.random.Generator) -> dict:
        """Turn each arm's IK share of the particles (N, D) into IK particles (in place).

        detections: (5, 3) per end-effector (NaN rows: not detected). Returns per limb the
        number of IK particles made (0 where there was no detection or no solution).
        """
        made = {}
        n = particles.shape[0]
        for e, limb in LIMB_OF.items():
            made[limb] = 0
            if not np.isfinite(detections[e]).all():
                continue
            values, _ = self.solve(limb, detections[e], reference, rest, rng)
            if values.shape[0] == 0:
                continue
            rows = np.flatnonzero(rng.random(n) < self.fraction[limb])
            if rows.size:
                pick = rng.integers(0, values.shape[0], rows.size)
                particles[np.ix_(rows, self.dofs(limb))] = values[pick]
            made[limb] = int(rows.size)
        return made

    def update_fraction(self, particles: np.ndarray, weights: np.ndarray,
                        detections: np.ndarray, rest) -> dict:
        """Move each detected arm's IK share by its IK survival rate; returns the rates."""
        p = self.params
        rates = {}
        w = np.asarray(weights, dtype=np.float64)
        w = w / w.sum() if w.sum() > 0 else np.full(len(w), 1.0 / len(w))
        ee = None
        for e, limb in LIMB_OF.items():
            if not np.isfinite(detections[e]).all():
                continue
            if ee is None:
                ee = self.end_effectors(particles, rest)
            near = np.linalg.norm(ee[:, e] - detections[e], axis=1) <= p.survival_radius
            rate = float(w[near].sum())
            rates[limb] = rate
            delta = p.fraction_step if rate > 0.5 else -p.fraction_step
            self.fraction[limb] = float(np.clip(self.fraction[limb] + delta, p.min_fraction,
                                                1.0 - p.min_fraction))
        return rates
