"""The skinned body fitted to one frame set's labelled 3D keypoints (inverse kinematics over
the whole kinematic tree): the centre of the keypoint-first filter (:mod:`.keypoint_first`).

The keypoints (:class:`~hmocap_ros.detection.detections.Detections` of the keypoint
detector: head, hands, feet, shoulders, elbows, wrists, hips, knees, ankles, each with a
score) are matched to points of the body model (:data:`MODEL_POINTS`): a joint, the
midpoint of a joint and an end site (the hands: wrist and hand tip; the head: head joint
and head top), or an end site (the feet: the toes), as the detector's body points are
defined (:mod:`hmocap_ros.detection.keypoint_triangulation`, step 4), each moved by the
landmark's *offset*: where the network puts that landmark relative to the model's point, a
fixed vector in the frame of the joint the point hangs on (BlazePose's hip landmarks lie
several centimetres from the model's hip joints). The offsets ship with the body model
(``hmocap_ros/data/keypoint_model.json``, :func:`load_keypoint_model`), measured once on
simulated clips no evaluation uses (``tools/learn_keypoint_model.py``: the median, over the
frames, of each keypoint's residual from the true pose's body point, turned into the joint's
frame).

The fit minimises over the 30 pose DoFs, within the joint limits,

    E(theta) = sum_k w_k rho(|P_k(theta) - p_k| / s) + sum_d ((theta_d - prior_d) / sigma_d)^2

with ``p_k`` the keypoints, ``P_k`` the model points on the body's estimated shape, ``w_k``
the keypoint's score, ``s`` = :data:`KEYPOINT_STD` and ``rho`` Huber's loss at
:data:`ROBUST_SCALE` stds
(a keypoint far from where the others put the body costs linearly, so one wrong keypoint
pulls its limb less than its square would). The prior is the predicted pose, with
``sigma_d`` the DoF's motion std over the elapsed frames times :data:`PRIOR_SCALE`: it holds the
DoFs no keypoint sees (the neck's twist, an ankle whose foot is not detected) and breaks
the ties the keypoints leave. Levenberg-Marquardt with a forward-difference Jacobian (one
batch of D + 1 poses through :class:`~hmocap_ros.body.pose_points.PosePoints` per
iteration), iteratively reweighted for Huber's loss, each step clipped to the limits.

Without a prior (a new track) the root is placed first: the pelvis at the hips' midpoint
(the model's rest offset of pelvis from hips), the heading from the hips' and shoulders'
left-right axes; the fit then starts from the rest pose there.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hmocap_ros.body.pose_points import PosePoints
from hmocap_ros.detection.detections import Detections
from hmocap_ros.tracking.body_layers import body_sigma0, clip_body_pose

__all__ = ["KEYPOINT_MODEL_FILE", "MODEL_POINTS", "KeypointFit", "FitResult",
           "load_keypoint_model"]

#: the landmark offsets and size corrections of the shipped body model
KEYPOINT_MODEL_FILE = Path(__file__).resolve().parents[1] / "data" / "keypoint_model.json"


def load_keypoint_model(path: str | Path | None = None) -> dict:
    """``{"offsets": {label: (3,)}, "size_corrections": {measure: ratio}}`` of the keypoint
    detector on the body model (module docstring; :mod:`.keypoint_anthropometry`)."""
    data = json.loads(Path(KEYPOINT_MODEL_FILE if path is None else path).read_text())
    return {"offsets": {k: np.asarray(v, float) for k, v in data.get("offsets", {}).items()},
            "size_corrections": {k: float(v) for k, v in data.get("size_corrections", {}).items()}}

#: keypoint label -> the model point it is: ("joint", name), ("mid", joint, end site) or
#: ("end", end site)
MODEL_POINTS = {
    "head": ("mid", "head", "head_top"),
    "left_hand": ("mid", "l_wrist", "l_hand_tip"), "right_hand": ("mid", "r_wrist", "r_hand_tip"),
    "left_foot": ("end", "l_toe"), "right_foot": ("end", "r_toe"),
    **{f"{side}_{part}": ("joint", f"{side[0]}_{part}")
       for side in ("left", "right")
       for part in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")},
}
#: finite-difference step of the Jacobian (rad / m)
_STEP = 1e-5


#: std (m) of a keypoint of score 1 about its body point: the scale of the landmarks' spread
#: about their offsets (docs/tracking.md, sec. 3.7)
KEYPOINT_STD = 0.03
#: Huber threshold in keypoint stds: residuals beyond it cost linearly
ROBUST_SCALE = 2.0
#: std of the prior on each DoF about the predicted pose, in motion stds (``body_sigma0``) over
#: the elapsed frames: a tighter prior lags fast limbs, a looser one lets the keypoints' noise
#: through (docs/tracking.md, sec. 3.7)
PRIOR_SCALE = 6.0
#: Levenberg-Marquardt iterations per fit (it stops earlier when converged)
ITERATIONS = 10


@dataclass(frozen=True, eq=False)
class FitResult:
    """A fit: ``params`` (D,) the pose; ``labels`` the keypoints fitted, ``residuals`` (K,)
    their distance (m) to their body points; ``cost`` the final E (module docstring)."""

    params: np.ndarray
    labels: tuple
    residuals: np.ndarray
    cost: float


class KeypointFit:
    """Fits ``model`` (the tracking body) to labelled keypoints (module docstring)."""

    def __init__(self, model, min_score: float = 0.3, room=None, offsets: dict | None = None):
        self.model = model
        self.skel = model.skeleton
        self.min_score = float(min_score)
        self.room = room
        joints = list(map(str, model.joint_names))
        ends = list(map(str, model.end_site_names))
        self.labels = tuple(MODEL_POINTS)
        # each label's body point as a site on one joint: the joint itself, its end site, or
        # the midpoint of the two; plus the landmark's learnt offset in that joint's frame
        self._site_joint = np.zeros(len(self.labels), np.intp)
        self._site_end = np.full(len(self.labels), -1, np.intp)
        self._site_share = np.zeros(len(self.labels))
        end_parents = np.asarray(model.end_site_parents)
        for k, label in enumerate(self.labels):
            spec = MODEL_POINTS[label]
            if spec[0] == "joint":
                self._site_joint[k] = joints.index(spec[1])
            else:
                e = ends.index(spec[-1])
                self._site_joint[k] = end_parents[e]
                self._site_end[k] = e
                self._site_share[k] = 1.0 if spec[0] == "end" else 0.5
        #: per label, the joint its body point hangs on
        self.site_joints = self._site_joint
        self.offsets = np.zeros((len(self.labels), 3))
        if offsets is not None:
            for k, label in enumerate(self.labels):
                if label in offsets:
                    self.offsets[k] = offsets[label]
        self._sigma0 = body_sigma0(self.skel)
        self._rest_key = None  # the rest the kernel was built on
        self._kernel: PosePoints | None = None
        lo, hi = np.asarray(self.skel.lower, float), np.asarray(self.skel.upper, float)
        wrap = np.zeros(self.skel.n_dofs, bool)
        wrap[np.asarray(self.skel.wrap_dofs, int)] = True
        self._lower = np.where(wrap, -np.inf, lo)
        self._upper = np.where(wrap, np.inf, hi)
        self._pelvis = joints.index("pelvis")
        self._hips = (joints.index("l_hip"), joints.index("r_hip"))

    # ------------------------------------------------------------------ model points

    def kernel(self, rest) -> PosePoints:
        """The forward kinematics of the labels' body points on ``rest`` (rebuilt when the
        rest changes): one site per label on its joint."""
        if self._kernel is None or rest is not self._rest_key:
            base = PosePoints.of(self.model, rest)
            joints = np.asarray(self.skel.joints_rest if rest is None else rest.joints)
            ends = np.asarray(self.model.end_sites_rest if rest is None else rest.end_sites)
            vec = np.zeros((len(self.labels), 3))
            has_end = self._site_end >= 0
            vec[has_end] = self._site_share[has_end, None] * (
                ends[self._site_end[has_end]] - joints[self._site_joint[has_end]])
            self._kernel = base.with_sites(self._site_joint, vec + self.offsets)
            self._rest_key = rest  # held, so that its identity stays its own
        return self._kernel

    def body_points(self, params: np.ndarray, rest) -> np.ndarray:
        """(B, L, 3) the body point of every label (:data:`MODEL_POINTS`) of poses (B, D)."""
        return self.kernel(rest).points(params)[1]

    def targets(self, detections: Detections | None, drop=()) -> tuple:
        """``(rows, positions (K, 3), scores (K,))`` of the keypoints to fit: the best-scored
        detection per label of :data:`MODEL_POINTS` with a score of at least ``min_score``
        (the constructor's), except the labels in ``drop``."""
        rows, pos, score = [], [], []
        if detections is not None:
            for k, label in enumerate(self.labels):
                if label in drop:
                    continue
                p = detections.position(label)
                if p is None or not np.all(np.isfinite(p)):
                    continue
                s = max(float(detections.scores[i]) for i, lab in enumerate(detections.labels)
                        if lab == label)
                if s >= self.min_score:
                    rows.append(k)
                    pos.append(p)
                    score.append(s)
        return (np.array(rows, dtype=np.intp), np.array(pos, float).reshape(-1, 3),
                np.array(score, float))

    # ------------------------------------------------------------------ start

    def initial_pose(self, rows: np.ndarray, positions: np.ndarray, rest) -> np.ndarray | None:
        """A rest pose placed at the keypoints' hips and turned to their heading, or None
        without both hips."""
        named = {self.labels[r]: p for r, p in zip(rows, positions)}
        if "left_hip" not in named or "right_hip" not in named:
            return None
        skel = self.skel
        x = np.zeros(skel.n_dofs)
        rest_joints = np.asarray(skel.joints_rest if rest is None else rest.joints)
        hips_mid_rest = 0.5 * (rest_joints[self._hips[0]] + rest_joints[self._hips[1]])
        offset = rest_joints[self._pelvis] - hips_mid_rest
        across = named["left_hip"] - named["right_hip"]
        if "left_shoulder" in named and "right_shoulder" in named:
            across = across + (named["left_shoulder"] - named["right_shoulder"])
        # the body faces +z with +x its left: yaw turns +x onto the left-right axis
        yaw = float(np.arctan2(-across[2], across[0]))
        c, s = np.cos(yaw), np.sin(yaw)
        turn = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
        x[skel.translation_dofs] = 0.5 * (named["left_hip"] + named["right_hip"]) + turn @ offset
        x[skel.dof_index("root_yaw")] = yaw
        return x

    # ------------------------------------------------------------------ fit

    def fit(self, detections: Detections | None, rest, prior: np.ndarray | None = None,
            periods: float = 1.0, drop=()) -> FitResult | None:
        """The pose (module docstring) of one frame set's keypoints, started from ``prior``
        (the predicted pose, also the prior's centre) or, without one, from
        :meth:`initial_pose`. ``periods``: frame periods since the prior's frame (the
        prior's stds grow with it). None when there is no keypoint to fit, or no prior and
        no hips."""
        rows, positions, scores = self.targets(detections, drop)
        if len(rows) == 0:
            return None
        if prior is None:
            start = self.initial_pose(rows, positions, rest)
            if start is None:
                return None
            prior_w = np.full(self.skel.n_dofs, 1.0 / np.pi)  # a new track: only a nudge
            prior_w[self.skel.translation_dofs] = 1.0
            centre = start
        else:
            start = centre = np.asarray(prior, float)
            prior_w = 1.0 / (PRIOR_SCALE * max(periods, 1.0) * self._sigma0)
        x = start.copy()

        sqrt_w = np.sqrt(scores) / KEYPOINT_STD
        kernel = self.kernel(rest)
        n = self.skel.n_dofs
        probe = np.vstack([np.zeros(n), _STEP * np.eye(n)])
        lam = 1e-3

        def points_of(poses):
            return kernel.points(poses)[1][:, rows]

        def energy(x, pts):
            d = np.linalg.norm(pts - positions, axis=1) * sqrt_w
            return float(np.sum(_huber(d, ROBUST_SCALE)) + np.sum(((x - centre) * prior_w) ** 2))

        pts = points_of(x[None])[0]
        e = energy(x, pts)
        for _ in range(ITERATIONS):
            batch = points_of(x[None] + probe)
            pts = batch[0]
            jac = (batch[1:] - pts[None]).transpose(1, 2, 0).reshape(-1, n) / _STEP  # (3K, D)
            resid = pts - positions
            dist = np.linalg.norm(resid, axis=1) * sqrt_w
            irls = sqrt_w * np.sqrt(_huber_weight(dist, ROBUST_SCALE))  # (K,)
            w3 = np.repeat(irls, 3)
            a = jac * w3[:, None]
            r = resid.reshape(-1) * w3
            hess = a.T @ a + np.diag(prior_w ** 2)
            grad = a.T @ r + prior_w ** 2 * (x - centre)
            before = e
            for _ in range(6):
                step = np.linalg.solve(hess + lam * np.diag(np.diag(hess) + 1e-9), -grad)
                trial = np.clip(x + step, self._lower, self._upper)
                trial_pts = points_of(trial[None])[0]
                e_trial = energy(trial, trial_pts)
                if e_trial < e:
                    x, e, pts = trial, e_trial, trial_pts
                    lam = max(lam * 0.3, 1e-7)
                    break
                lam *= 10.0
            if before - e <= 1e-4 * before:  # converged (or no step improves)
                break
        if self.room is not None:
            x = clip_body_pose(self.skel, x[None].copy(), *self.room)[0]
            pts = points_of(x[None])[0]
        residuals = np.linalg.norm(pts - positions, axis=1)
        return FitResult(x, tuple(self.labels[r] for r in rows), residuals, e)


def _huber(d: np.ndarray, c: float) -> np.ndarray:
    """Huber's loss of normalised residuals ``d >= 0`` (the square below ``c``)."""
    return np.where(d <= c, d * d, 2.0 * c * d - c * c)


def _huber_weight(d: np.ndarray, c: float) -> np.ndarray:
    """IRLS weight of Huber's loss: 1 below ``c``, ``c / d`` beyond."""
    return np.where(d <= c, 1.0, c / np.maximum(d, 1e-12))
