"""Keypoint-first tracking (thesis sec. 2.5 taken to its end): the body fitted to the frame
set's labelled 3D keypoints is the centre of the layered filter, whose budget follows what
the keypoints leave uncertain.

Per frame set (:class:`KeypointFirst`, called by
:class:`~hmocap_ros.tracking.body_tracker.BodyTracker` for ``method: kf-hpf``):

1. **Fit** (:mod:`.keypoint_fit`): the skinned body, on its estimated shape, fitted to the
   keypoints by inverse kinematics over the whole tree from the predicted pose.
2. **The silhouettes check the keypoints** (:func:`contradicted`): each keypoint's segment
   (from its parent keypoint to it: upper arm to the elbow, forearm to the wrist, wrist to
   the hand, thigh, shin, foot; the shoulders' midpoint to the head; hips and shoulders by
   themselves) is sampled at :data:`CHECK_SAMPLES` points over its half towards the keypoint
   (the other half is the parent's) and projected into every view. A view
   contradicts the keypoint when it sees at least two of the samples and fewer than
   :data:`CHECK_SUPPORT` of those fall on its foreground (dilated by :data:`CHECK_DILATE_PX` at the
   working resolution, the segmentation's own inaccuracy). A keypoint that
   ``check_views`` or more views contradict is dropped, and the body fitted again without
   it: a wrist the network puts in empty space, where every view shows the forearm
   elsewhere, does not drag the arm.
3. **Budget** (:meth:`KeypointFirst.uncertain_blocks`): a body block of the hierarchical
   schedule (torso, legs, shoulders, elbows) is *explained* when every keypoint it moves
   (``BLOCK_KEYPOINTS``) was fitted with a score of at least :data:`CONFIDENT_SCORE` and a
   residual under :data:`MAX_RESIDUAL`; else it is *uncertain*: a keypoint missing, dropped by
   the silhouettes, unsure, or at odds with the body's bone lengths.
4. **Filter** (:meth:`KeypointFirst.frame_filter`): the particles start at the fitted pose.
   Explained blocks are only jittered by :data:`EXPLAINED_STD` motion stds; each uncertain block
   gets a layer of ``filter.particles`` (eq. 2.15 in its boxes, half of its particles
   carried over from the last frame's filter, so that the silhouettes can hold a limb the
   keypoints lost or got wrong); a final whole-body layer of as many weighs
   eq. 2.8 plus the keypoint term over all kept keypoints (eq. 2.21 with the keypoints as
   ``C_t``). Every layer's cost adds :data:`KAPPA` times the score-weighted mean distance
   (each capped at :data:`CAP`) of the kept keypoints of its block and the blocks it moves
   (a shoulder layer samples the elbow too) to their body points. With every block
   explained, the fit is the estimate.
   Live, under a time budget (the node's frame period), the layers share the weight
   evaluations that the budget pays at the measured cost of one evaluation; when it pays
   fewer than :data:`MIN_PARTICLES` per layer, the fit is the frame's estimate and the
   particles carry over, so that the filter corrects the track on a later frame set.

Without keypoints in a frame set the tracker runs the silhouette filter (``hpf-apo``'s
schedule) for that frame; it says so once in the log and in its diagnostics.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from hmocap_ros.geometry.projection import project_batch
from hmocap_ros.lpf.layered_filter import Layer, LayeredFilter
from hmocap_ros.params import param
from hmocap_ros.tracking.body_layers import BODY_BLOCKS, BodySchedule, block_dims, body_sigma0
from hmocap_ros.tracking.keypoint_fit import KeypointFit
from hmocap_ros.tracking.methods import get_method
from hmocap_ros.tracking.observation_boxes import layer_vertex_indices

__all__ = ["BLOCK_KEYPOINTS", "MIN_PARTICLES", "SEGMENT_FROM", "KeypointFirstParams",
           "KeypointFirst", "contradicted", "dilate_masks"]

#: per body block, the keypoints whose places it decides
BLOCK_KEYPOINTS = {
    "torso": ("left_shoulder", "right_shoulder", "left_hip", "right_hip", "head"),
    "l_leg": ("left_knee", "left_ankle", "left_foot"),
    "r_leg": ("right_knee", "right_ankle", "right_foot"),
    "l_shoulder": ("left_elbow",), "r_shoulder": ("right_elbow",),
    "l_elbow": ("left_wrist", "left_hand"), "r_elbow": ("right_wrist", "right_hand"),
}
#: per block's layer, the keypoints its DoFs move (a shoulder layer samples the elbow too)
LAYER_KEYPOINTS = {**BLOCK_KEYPOINTS,
                   "l_shoulder": BLOCK_KEYPOINTS["l_shoulder"] + BLOCK_KEYPOINTS["l_elbow"],
                   "r_shoulder": BLOCK_KEYPOINTS["r_shoulder"] + BLOCK_KEYPOINTS["r_elbow"]}
#: fewest particles per layer worth a filter run within a time budget
MIN_PARTICLES = 16
#: a keypoint's segment starts at this keypoint (None: the keypoint alone; "shoulders": the
#: shoulders' midpoint)
SEGMENT_FROM = {
    "head": "shoulders", "left_shoulder": None, "right_shoulder": None,
    "left_hip": None, "right_hip": None,
    **{f"{s}_{child}": f"{s}_{parent}" for s in ("left", "right")
       for parent, child in (("shoulder", "elbow"), ("elbow", "wrist"), ("wrist", "hand"),
                             ("hip", "knee"), ("knee", "ankle"), ("ankle", "foot"))},
}


#: points sampled along each keypoint's segment to test it against the foreground
CHECK_SAMPLES = 4
#: a view contradicts a keypoint when fewer than this share of the samples it sees lie on its
#: foreground
CHECK_SUPPORT = 0.5
#: dilation (working-resolution pixels) of the foreground the samples are tested on: the
#: segmentation's own inaccuracy at 160x120
CHECK_DILATE_PX = 1
#: smallest keypoint score for a block to be explained by its keypoints
CONFIDENT_SCORE = 0.5
#: largest distance (m) of a keypoint from its fitted body point for its block to be explained:
#: twice the landmarks' spread about their offsets
MAX_RESIDUAL = 0.08
#: jitter of the explained blocks' DoFs, in motion stds
EXPLAINED_STD = 0.5
#: weight (per metre) of the keypoint term of every layer, and the largest distance (m) one
#: keypoint adds to it: a keypoint the check kept wrongly costs a bounded amount (the values
#: of the thesis' refinement layer, eq. 2.21, :data:`~.detector_driven.REFINE_KAPPA`)
KAPPA, CAP = 2.0, 0.25


@dataclass(frozen=True)
class KeypointFirstParams:
    """Keypoint-first tracking (``kf-hpf``, :mod:`.keypoint_first`)."""

    min_score: float = param(0.3, "Keypoints with a lower score are not fitted (in [0, 1]).")
    check_views: int = param(2, "Views (>= 1) whose foreground must contradict a keypoint for "
                                "it to be dropped.")
    shape_frames: int = param(50, "Frame sets (>= 0) of a new track whose keypoints measure "
                                   "the body's shape (keypoint_anthropometry); the shape is "
                                   "solved again whenever their count doubles, then kept. 0: "
                                   "the model's proportions.")
    min_start_keypoints: int = param(8, "Keypoints (>= 1, the hips among them) a track needs "
                                        "to start from the keypoints alone; with fewer, the "
                                        "silhouette start-up (sec. 2.3) starts it.")

    def __post_init__(self):
        bad = [name for name, ok in (
            ("min_score", 0.0 <= self.min_score <= 1.0),
            ("check_views", self.check_views >= 1),
            ("min_start_keypoints", self.min_start_keypoints >= 1),
            ("shape_frames", self.shape_frames >= 0)) if not ok]
        if bad:
            raise ValueError("keypoints: out of range: " + ", ".join(bad))


def _segments(named: dict, samples: int) -> tuple[list, np.ndarray]:
    """Labels and their sample points (K, S, 3) along their segments (module docstring)."""
    labels, points = [], []
    t = 0.5 + 0.5 * (np.arange(samples) + 1.0) / samples  # the half towards the keypoint
    for label, p in named.items():
        start = SEGMENT_FROM.get(label, None)
        if start == "shoulders":
            a = (0.5 * (named["left_shoulder"] + named["right_shoulder"])
                 if "left_shoulder" in named and "right_shoulder" in named else None)
        else:
            a = named.get(start) if start is not None else None
        a = p if a is None else a
        labels.append(label)
        points.append(a[None] + t[:, None] * (p - a)[None])
    return labels, np.array(points).reshape(len(labels), samples, 3)


def contradicted(named: dict, obs, params: KeypointFirstParams, dilated=None) -> list[str]:
    """The keypoints (``{label: (3,) position}``) that ``check_views`` or more views of
    ``obs`` contradict (module docstring, step 2). ``dilated``: the observation's masks
    already dilated (M, h, w), else dilated here."""
    if not named or obs.n_views == 0:
        return []
    if dilated is None:
        dilated = dilate_masks(obs.masks, CHECK_DILATE_PX)
    labels, pts = _segments(named, CHECK_SAMPLES)
    uv, z = project_batch(pts.reshape(1, -1, 3), obs.K, obs.R, obs.t, obs.D)
    uv, z = uv[0], z[0]  # (M, K*S, 2), (M, K*S)
    col = np.rint(uv[..., 0]).astype(np.int64)
    row = np.rint(uv[..., 1]).astype(np.int64)
    h, w = dilated.shape[1:]
    seen = (z > 0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
    views = np.arange(len(dilated))[:, None]
    on = seen & (dilated[views, np.clip(row, 0, h - 1), np.clip(col, 0, w - 1)] > 0)
    seen = seen.reshape(len(dilated), len(labels), -1).sum(axis=2)
    on = on.reshape(len(dilated), len(labels), -1).sum(axis=2)
    against = (seen >= 2) & (on < CHECK_SUPPORT * seen)
    return [label for label, n in zip(labels, against.sum(axis=0)) if n >= params.check_views]


def dilate_masks(masks: np.ndarray, radius: int) -> np.ndarray:
    """Masks (M, h, w) {0, 1} dilated by a square of ``radius`` pixels."""
    if radius <= 0 or len(masks) == 0:
        return masks
    kernel = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
    return np.stack([cv2.dilate(m, kernel) for m in masks])


class KeypointFirst:
    """One tracker's keypoint fit, keypoint check and per-frame filter (module docstring).

    model: the tracking body; params: the tracker's ``keypoints`` group; n_particles: an
    uncertain block's layer size; survival_rate, kernel: the schedule's; room: the room box;
    offsets: the landmark offsets of :func:`~.keypoint_fit.load_keypoint_model`.
    """

    def __init__(self, model, params: KeypointFirstParams, n_particles: int,
                 survival_rate: float, kernel, room=None, offsets: dict | None = None):
        self.model = model
        self.skel = model.skeleton
        self.params = params
        self.n_particles = int(n_particles)
        self.survival_rate = survival_rate
        self.kernel = kernel
        self.fitter = KeypointFit(model, params.min_score, room, offsets)
        self.sigma0 = body_sigma0(self.skel)
        self.block_dims = dict(zip(BODY_BLOCKS, block_dims(self.skel)))
        self.own_dims = {b: self.skel.group_dofs(b) for b in BODY_BLOCKS}
        self.block_vertices = {b: layer_vertex_indices(model, (b,)) for b in BODY_BLOCKS}
        self.method = get_method("hpf-apo")

    # ------------------------------------------------------------------ fit and check

    def fit(self, detections, rest, obs, prior, periods: float):
        """Steps 1-2: ``(fit, dropped labels)``; fit None without keypoints to fit."""
        first = self.fitter.fit(detections, rest, prior, periods)
        if first is None:
            return None, []
        named = {lab: detections.position(lab) for lab in first.labels}
        dropped = contradicted(named, obs, self.params)
        if not dropped:
            return first, []
        again = self.fitter.fit(detections, rest, first.params if prior is None else prior,
                                periods, drop=dropped)
        return (again if again is not None else first), dropped

    def uncertain_blocks(self, fit, detections) -> list[str]:
        """Step 3: the blocks whose keypoints do not explain them, in schedule order."""
        ok = {}
        for label, resid in zip(fit.labels, fit.residuals):
            score = max(float(s) for lab, s in zip(detections.labels, detections.scores)
                        if lab == label)
            ok[label] = score >= CONFIDENT_SCORE and resid <= MAX_RESIDUAL
        return [b for b in BODY_BLOCKS if not all(ok.get(k, False) for k in BLOCK_KEYPOINTS[b])]

    # ------------------------------------------------------------------ filter

    def frame_particles(self, centre: np.ndarray, previous: np.ndarray | None,
                        uncertain: list[str], periods: float, rng: np.random.Generator,
                        n: int | None = None) -> np.ndarray:
        """Step 4's starting set (n, D): the fit, jittered on the explained blocks; each
        uncertain block takes half its particles' DoFs from the last frame's set."""
        n = self.n_particles if n is None else int(n)
        out = np.repeat(centre[None], n, axis=0)
        explained = np.ones(self.skel.n_dofs, bool)
        for b in uncertain:
            explained[self.own_dims[b]] = False
        std = EXPLAINED_STD * periods * self.sigma0 * explained
        out += rng.standard_normal(out.shape) * std
        if previous is not None and len(previous) and uncertain:
            rows = rng.integers(0, len(previous), n // 2)
            for b in uncertain:
                dims = self.own_dims[b]
                out[: n // 2, dims] = previous[rows][:, dims]
        return out

    def layer_particles(self, uncertain: list[str], budget: float | None) -> int:
        """Particles per layer within ``budget`` weight evaluations (None: the full
        ``n_particles``); 0 when the budget cannot pay ``MIN_PARTICLES`` per layer."""
        if budget is None:
            return self.n_particles
        if not uncertain:
            return 0
        n = int(min(self.n_particles, budget // (len(uncertain) + 1)))
        return n if n >= MIN_PARTICLES else 0

    def frame_filter(self, uncertain: list[str], periods: float,
                     n_particles: int | None = None) -> BodySchedule | None:
        """Step 4's schedule: a boxed layer per uncertain block, then the final layer, with
        ``n_particles`` per layer (None: ``n_particles`` of the tracker); None when there is
        nothing to filter or no particle to filter with."""
        d = self.skel.n_dofs
        n = self.n_particles if n_particles is None else int(n_particles)
        if not uncertain or n == 0:
            return None
        layers = []
        for k, b in enumerate(uncertain):
            std = np.zeros(d)
            if k + 1 < len(uncertain):  # diffuse the next block right before it is weighed
                nxt = uncertain[k + 1]
                std[self.block_dims[nxt]] = periods * self.sigma0[self.block_dims[nxt]]
            layers.append(Layer(dims=self.block_dims[b], survival_rate=self.survival_rate,
                                n_particles=n, std=std, kernel=self.kernel))
        final = Layer(survival_rate=self.survival_rate, n_particles=n,
                      std=np.zeros(d), kernel=self.kernel)
        lpf = LayeredFilter(layers=tuple(layers), sigma0=self.sigma0, final=final)
        return BodySchedule(self.method, lpf, tuple((b,) for b in uncertain) + ((),),
                            tuple([True] * len(uncertain) + [False]))

    def first_diffusion(self, particles: np.ndarray, uncertain: list[str], periods: float,
                        rng: np.random.Generator) -> np.ndarray:
        """The first uncertain block diffused before its layer weighs it (the kernel of the
        layer before, which this frame's filter does not have)."""
        if uncertain:
            dims = self.block_dims[uncertain[0]]
            particles = particles.copy()
            std = np.zeros(self.skel.n_dofs)
            std[dims] = periods * self.sigma0[dims]
            particles = self.kernel(particles, std, rng)
        return particles

    def layer_vertices(self, schedule: BodySchedule) -> list:
        return [self.block_vertices[blocks[0]] if boxed else None
                for blocks, boxed in zip(schedule.layer_blocks, schedule.boxed)]

    def terms(self, schedule: BodySchedule, fit, detections, rest) -> list:
        """Per weighting, the keypoint term (module docstring) or None."""
        kappa, cap = KAPPA, CAP
        if kappa <= 0 or fit is None:
            return [None] * len(schedule.layer_blocks)
        labels = list(self.fitter.labels)
        scores = {lab: max(float(s) for l2, s in zip(detections.labels, detections.scores)
                           if l2 == lab) for lab in fit.labels}
        out: list[Callable[..., np.ndarray] | None] = []
        for blocks in schedule.layer_blocks:
            wanted = ([k for b in blocks for k in LAYER_KEYPOINTS[b]] if blocks
                      else list(fit.labels))
            keep = [k for k in wanted if k in scores]
            if not keep:
                out.append(None)
                continue
            rows = np.array([labels.index(k) for k in keep])
            target = np.array([detections.position(k) for k in keep])
            w = np.array([scores[k] for k in keep])
            w = w / w.sum()

            def cost(particles, joints, rows=rows, target=target, w=w):
                pts = self.fitter.body_points(particles, rest)[:, rows]
                d = np.linalg.norm(pts - target[None], axis=2)
                return kappa * (np.minimum(d, cap) @ w)

            out.append(cost)
        return out
