"""Silhouette-driven limb proposals: where the foreground says an arm (or leg) could be.

A silhouette cost has a narrow basin around a limb: a model arm 15 degrees away from the true
one overlaps nothing of it, and an arm hidden against the torso is a local minimum (it costs
only the unexplained true arm). Once a fast limb has left the particles' reach, Gaussian
diffusion finds it again only by chance. The thesis answers this with detector-driven
propagation (sec. 2.5.2): particles whose limbs are put, by inverse kinematics, where 3D
extremity detections say they are. This module is the silhouette-only form of that idea,
needing no detector: candidate limb configurations are scored on the masks themselves, and
a fraction of the particles takes its limb DoFs from the best candidates (the rest diffuse
as the thesis says). The weighting function (eq. 2.8 / 2.15) still decides which survive;
a proposal that does not fit costs one evaluation.

Scoring, for one limb (e.g. the left arm: shoulder swing, shoulder twist, elbow flex) with the
rest of the body at a reference pose (the previous estimate):

1. ``n_swing`` proximal swings (shoulder flex/abd) drawn uniformly within the joint limits;
   points along the upper arm are projected into every view; a point is *supported* when it
   falls on foreground (masks dilated by ``tolerance_px``) in all views but ``max_misses``
   (a point of the visual hull; a view it leaves counts as no evidence against it) and
   *new* when, in at least one view, it falls on foreground that the reference pose does not
   explain (the residual). Score = mean(supported) + ``residual_weight`` * mean(new).
2. The ``top_swings`` best swings each get ``n_distal`` draws of the remaining DoFs (twist,
   elbow; hip twist, knee, ankle for legs), scored the same way on the forearm and hand
   points; the configuration score averages both stages over all points.
3. The ``screen`` best configurations by that score are weighed with the real cost
   (eq. 2.8 through ``cost_fn``, the rest of the body at the reference pose; the point score
   is coarse: an arm along the torso is as "supported" as the true one), and the
   ``top_configs`` cheapest are the proposal set; particles draw from it uniformly.

Everything is batched: forward kinematics of a few thousand candidate poses and one
projection per stage (docs/development.md, "Costs the code is shaped by", gives the time).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from hmocap_ros.body.kinematics import end_site_positions, forward_kinematics
from hmocap_ros.body.skeleton import SWING_NORM_MAX, pose_to_local_rotations
from hmocap_ros.geometry.projection import project_batch
from hmocap_ros.render import render_silhouettes

__all__ = ["LIMBS", "PROPOSAL_FRACTION", "LimbProposalParams", "LimbProposer"]

#: Share of the particles that, per arm and frame, take their arm DoFs from these proposals
#: (the tracker, its start-up and its fresh searches): the rest keep the Gaussian kernel, so
#: the proposals add modes the silhouettes show without replacing the filter's own.
PROPOSAL_FRACTION = 0.35
#: limb -> (swing DoFs, other DoFs, proximal chain, distal chain); chains name joints or
#: end sites, the proximal one starts at the joint the swing turns.
LIMBS = {
    "l_arm": (("l_shoulder_flex", "l_shoulder_abd"), ("l_shoulder_twist", "l_elbow_flex"),
              ("l_shoulder", "l_elbow"), ("l_elbow", "l_wrist", "l_hand_tip")),
    "r_arm": (("r_shoulder_flex", "r_shoulder_abd"), ("r_shoulder_twist", "r_elbow_flex"),
              ("r_shoulder", "r_elbow"), ("r_elbow", "r_wrist", "r_hand_tip")),
    "l_leg": (("l_hip_flex", "l_hip_abd"), ("l_hip_twist", "l_knee_flex", "l_ankle_flex"),
              ("l_hip", "l_knee"), ("l_knee", "l_ankle", "l_toe")),
    "r_leg": (("r_hip_flex", "r_hip_abd"), ("r_hip_twist", "r_knee_flex", "r_ankle_flex"),
              ("r_hip", "r_knee"), ("r_knee", "r_ankle", "r_toe")),
}

_FRACTIONS = np.array([1.0 / 3.0, 2.0 / 3.0, 1.0])


@dataclass(frozen=True)
class LimbProposalParams:
    """Sizes and thresholds of :class:`LimbProposer` (see the module docstring)."""

    n_swing: int = 600
    top_swings: int = 12
    n_distal: int = 80
    screen: int = 48
    top_configs: int = 8
    tolerance_px: int = 1
    max_misses: int = 0
    residual_weight: float = 1.0


class LimbProposer:
    """Candidate limb configurations scored on one frame's silhouettes.

    model: the body model (its tracking skeleton). limbs: names from :data:`LIMBS`.
    """

    def __init__(self, model, limbs=("l_arm", "r_arm"), params: LimbProposalParams | None = None):
        self.model = model
        self.skel = model.skeleton
        self.params = params or LimbProposalParams()
        names = list(map(str, model.joint_names))
        ends = list(map(str, model.end_site_names))
        self.limbs = tuple(limbs)
        self._spec = {}
        for limb in self.limbs:
            if limb not in LIMBS:
                raise ValueError(f"unknown limb {limb!r}; known: {sorted(LIMBS)}")
            swing, other, prox, dist = LIMBS[limb]

            def point(n):
                return ("j", names.index(n)) if n in names else ("e", ends.index(n))

            self._spec[limb] = (
                np.array([self.skel.dof_index(d) for d in swing]),
                np.array([self.skel.dof_index(d) for d in other]),
                [point(n) for n in prox], [point(n) for n in dist])

    def dofs(self, limb: str) -> np.ndarray:
        """DoF indices a limb's proposals set (swing first)."""
        swing, other, _, _ = self._spec[limb]
        return np.concatenate([swing, other])

    # ------------------------------------------------------------------ evidence

    def evidence(self, obs, reference: np.ndarray, rest, faces: np.ndarray) -> tuple:
        """(supporting masks (M, h, w) bool, residual masks (M, h, w) bool) of one frame.

        Supporting: the foreground dilated by ``tolerance_px``. Residual: foreground farther
        than ``tolerance_px`` from the silhouette of the reference pose (D,) on the shaped
        ``rest`` (a one-pixel fringe is resampling, not a limb).
        """
        from hmocap_ros.tracking.body_fitness import posed_mesh

        tol = int(self.params.tolerance_px)
        verts, _ = posed_mesh(self.model, reference[None], rest)
        uv, _ = project_batch(verts, obs.K, obs.R, obs.t, obs.D)
        model_sil = render_silhouettes(uv[0], faces, obs.height, obs.width)
        if tol > 0:
            kernel = np.ones((2 * tol + 1, 2 * tol + 1), np.uint8)
            support = np.stack([cv2.dilate(m, kernel) for m in obs.masks]) > 0
            model_sil = np.stack([cv2.dilate(m, kernel) for m in model_sil])
        else:
            support = obs.masks > 0
        residual = (obs.masks > 0) & (model_sil == 0)
        return support, residual

    def _points(self, params: np.ndarray, rest, chain) -> np.ndarray:
        """Points (B, P, 3) at thirds of every bone of ``chain`` for poses (B, D)."""
        rot, root_t = pose_to_local_rotations(self.skel, params)
        transforms, joints = forward_kinematics(rot, root_t, rest.joints, self.model.parents)
        ends = None
        pts = []
        for kind, i in chain:
            if kind == "j":
                pts.append(joints[:, i])
            else:
                if ends is None:
                    ends = end_site_positions(transforms, rest.end_sites,
                                              self.model.end_site_parents, rest.joints)
                pts.append(ends[:, i])
        out = [a[:, None] + _FRACTIONS[None, :, None] * (b - a)[:, None]
               for a, b in zip(pts[:-1], pts[1:])]
        return np.concatenate(out, axis=1)

    def _score(self, points: np.ndarray, obs, support: np.ndarray,
               residual: np.ndarray) -> np.ndarray:
        """Per-candidate (B,) sums over points of supported + residual_weight * new."""
        uv, z = project_batch(points, obs.K, obs.R, obs.t, obs.D)  # (B, M, P, 2)
        u = np.floor(uv[..., 0] + 0.5)
        v = np.floor(uv[..., 1] + 0.5)
        inside = (np.isfinite(u) & np.isfinite(v) & (z > 0) & (u >= 0) & (u < obs.width)
                  & (v >= 0) & (v < obs.height))
        ui = np.where(inside, u, 0).astype(np.intp)
        vi = np.where(inside, v, 0).astype(np.intp)
        m = np.arange(obs.n_views)[None, :, None]
        on_fg = support[m, vi, ui] & inside
        misses = (inside & ~on_fg).sum(axis=1)  # (B, P)
        supported = misses <= self.params.max_misses
        new = (residual[m, vi, ui] & inside).any(axis=1) & supported
        return supported.sum(axis=1) + self.params.residual_weight * new.sum(axis=1)

    # ------------------------------------------------------------------ proposals

    def candidates(self, limb: str, reference: np.ndarray, rest, obs, support, residual,
                   rng: np.random.Generator, cost_fn=None,
                   sizes: LimbProposalParams | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The best configurations of one limb: (values (K, n_dofs), scores (K,)).

        Without ``cost_fn`` the ``top_configs`` best by point score (in [0, 1 + w]); with it
        (``cost_fn(params (K, D)) -> costs (K,)``), the ``top_configs`` of the ``screen`` best
        by point score that cost least, and their costs. ``sizes`` overrides the proposer's
        parameters for this call (a coarser search, say).
        """
        p = sizes or self.params
        swing, other, prox, dist = self._spec[limb]
        lower, upper = np.asarray(self.skel.lower), np.asarray(self.skel.upper)
        # stage 1: swings of the proximal bone
        cand = np.repeat(reference[None], p.n_swing, axis=0)
        sw = lower[swing] + (upper[swing] - lower[swing]) * rng.random((p.n_swing, swing.size))
        norm = np.linalg.norm(sw, axis=1, keepdims=True)
        sw *= np.minimum(1.0, SWING_NORM_MAX / np.maximum(norm, 1e-12))
        cand[:, swing] = sw
        pts = self._points(cand, rest, prox)
        n_prox = pts.shape[1]
        s1 = self._score(pts, obs, support, residual)
        order = np.lexsort((rng.random(s1.size), -s1))[:p.top_swings]
        # stage 2: the other DoFs of the limb, for each kept swing
        best = cand[order]
        cand2 = np.repeat(best, p.n_distal, axis=0)
        n2 = cand2.shape[0]
        cand2[:, other] = lower[other] + (upper[other] - lower[other]) * rng.random((n2, other.size))
        pts2 = self._points(cand2, rest, dist)
        s2 = self._score(pts2, obs, support, residual)
        total = (np.repeat(s1[order], p.n_distal) + s2) / (n_prox + pts2.shape[1])
        dofs = np.concatenate([swing, other])
        if cost_fn is None:
            keep = np.lexsort((rng.random(total.size), -total))[:p.top_configs]
            return cand2[keep][:, dofs], total[keep]
        keep = np.lexsort((rng.random(total.size), -total))[:p.screen]
        costs = np.asarray(cost_fn(cand2[keep]), dtype=np.float64)
        best = np.argsort(costs, kind="stable")[:p.top_configs]
        return cand2[keep[best]][:, dofs], costs[best]

    def apply(self, particles: np.ndarray, reference: np.ndarray, rest, obs, faces: np.ndarray,
              fraction: float, rng: np.random.Generator, cost_fn=None) -> np.ndarray:
        """Give ``fraction`` of the particles (N, D), per limb, a proposed configuration.

        Each limb draws its own particles; their limb DoFs become a uniformly chosen one of
        the limb's :meth:`candidates`. Returns the particles (modified in place).
        """
        if fraction <= 0.0 or obs.n_views == 0 or particles.shape[0] == 0:
            return particles
        support, residual = self.evidence(obs, reference, rest, faces)
        n = particles.shape[0]
        for limb in self.limbs:
            values, _ = self.candidates(limb, reference, rest, obs, support, residual, rng,
                                        cost_fn)
            rows = np.flatnonzero(rng.random(n) < fraction)
            if rows.size and values.shape[0]:
                pick = rng.integers(0, values.shape[0], rows.size)
                particles[np.ix_(rows, self.dofs(limb))] = values[pick]
        return particles
