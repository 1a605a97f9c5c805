"""Automatic start and anthropometry estimation from multi-view silhouettes (thesis sec. 2.3.3-2.3.4).

Pipeline, per person appearing in the room:

1. Visual hull (:mod:`.visual_hull`): the model is put at the hull centroid, standing, turned
   to a heading, and scaled to the hull height (sec. 2.3.4; :mod:`.startup_pose`).
2. Powell refinement (``scipy.optimize.minimize(method="Powell")``) of the root (6 DoF), then
   of each limb separately (shoulder swing and elbow per arm, hip swing and knee per leg: "we
   split the variables of each limb in separate optimization steps";
   :func:`~.startup_pose.powell_fit`). Silhouettes cannot tell a person's front from their
   back in every pose, so the most likely headings are refined
   (:func:`~.startup_pose.search_headings`), and kept as separate hypotheses (below).
3. Layered filtering over shape and pose ``X = Phi u Theta`` (:mod:`.anthropometry_state`)
   with the layering of table 2.2 (:mod:`.anthropometry_layers`). The shape dimensions move
   with the rejection-sampling kernel of eq. 2.13
   (:func:`~hmocap_ros.lpf.kernels.rejection_kernel`, tau = 0.7, table 2.1 priors via
   :func:`~hmocap_ros.body.anthropometry.shape_log_prior`), the pose dimensions with a
   Gaussian kernel within the joint limits; the weighting is the silhouette XOR (eq. 2.8).
   It runs once per frame over the first ``frames`` frames (the subject moves, the shape does
   not), then each hypothesis' estimate is scored by its mean final cost and the better one
   wins.

Choices where the thesis is vague:

* Eq. 2.13's acceptance test compares the candidate with the current particle:
  ``P(candidate) >= tau P(current)``; at most ``rejection_trials`` draws. The prior is
  evaluated on the subject's proportions (entity sizes at global scale 1): the global scale
  is measured (visual hull height), and table 2.1's absolute sizes would otherwise pull every
  entity of a tall or short subject back to the population mean.
* Growth (:meth:`AnthropometryEstimator.grow_to`, beyond the thesis, which assumes one good
  frame): when a later start-up frame's hull stands taller than the body (the segmentation
  lost the head in the first one), the body grows to it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hmocap_ros.body.anthropometry import BodyShape, shape_log_prior
from hmocap_ros.detection.visual_hull import Hull
from hmocap_ros.lpf.kernels import rejection_kernel
from hmocap_ros.lpf.layered_filter import beta_for_survival_rate, lpf_run
from hmocap_ros.tracking.anthropometry_layers import INIT_SPREAD, TABLE_2_2, init_spread, shape_std, startup_filters
from hmocap_ros.tracking.anthropometry_state import (
    ROOT_DOFS,
    SHAPE_KEYS,
    SHAPE_PARAMS,
    entity_size_errors,
    shape_from_state,
    shape_to_state,
)
from hmocap_ros.tracking.body_fitness import Observation, SilhouetteFitness
from hmocap_ros.tracking.body_layers import clip_body_pose, root_room_limits
from hmocap_ros.tracking.params import EstimationParams
from hmocap_ros.tracking.startup_pose import (
    HEADING_SEARCH_SIZES,
    LIMB_GRID,
    LIMB_STEPS,
    initial_pose,
    powell_fit,
    search_headings,
)

__all__ = [
    "HEADING_SEARCH_SIZES", "INIT_SPREAD", "LIMB_GRID", "LIMB_STEPS", "ROOT_DOFS", "SHAPE_KEYS",
    "SHAPE_PARAMS", "TABLE_2_2", "AnthropometryEstimator", "Hypothesis",
    "entity_size_errors", "initial_pose", "powell_fit", "shape_from_state", "shape_to_state",
]


@dataclass(eq=False)
class Hypothesis:
    """One heading hypothesis of the start-up: particles over [pose | shape] and its scores."""

    heading: float
    particles: np.ndarray
    estimate: np.ndarray
    costs: list = field(default_factory=list)

    @property
    def score(self) -> float:
        return float(np.mean(self.costs)) if self.costs else float("inf")


def body_and_hull_tops(model, states: np.ndarray, hull: Hull, column: float) -> tuple:
    """Per start-up state (H, D + S): ``(body tops (H,), hull tops [H] (None: no voxel))``.

    ``column`` > 0: both tops are read in the column of that radius (metres, on the floor)
    around the body's head top (its ``head_top`` end site), the hull's with
    :meth:`Hull.top_within`, the body's from its vertices there, so that a hand raised beside
    the head tops neither. 0: the hull's and the body's highest points.
    """
    n_pose = model.skeleton.n_dofs
    posed = model.forward(states[:, :n_pose], shape_from_state(states[:, n_pose:]))
    verts = posed.vertices
    if column <= 0.0:
        return verts[..., 1].max(axis=1), [hull.top] * len(states)
    head = posed.end_sites[:, model.end_site_names.index("head_top")][:, [0, 2]]
    d = verts[..., [0, 2]] - head[:, None]
    near = np.einsum("bvk,bvk->bv", d, d) <= column * column
    body_top = np.where(near, verts[..., 1], -np.inf).max(axis=1)
    return body_top, [hull.top_within(c, column) for c in head]


class AnthropometryEstimator:
    """Start-up of one person: Powell, then table 2.2's layered filter over a few frames.

    fitness: weighting at the start-up's working resolution. room: the room box (pelvis
    limits). fixed_shape: a known shape; then only the pose is fitted and filtered.
    proposer: a :class:`~.limb_proposals.LimbProposer` for the heading search, the Powell
    limb starts and (``proposal_fraction`` > 0) the particles of each frame.
    """

    def __init__(self, fitness: SilhouetteFitness, params: EstimationParams,
                 rng: np.random.Generator, room: tuple | None = None,
                 fixed_shape: BodyShape | None = None, proposer=None):
        self.fitness = fitness
        self.proposer = proposer
        self.model = fitness.model
        self.skel = self.model.skeleton
        self.params = params
        self.rng = rng
        self.fixed_shape = fixed_shape
        self.estimate_shape = params.estimate_shape and fixed_shape is None
        self.room_lo: np.ndarray | None
        self.room_hi: np.ndarray | None
        self.room_lo, self.room_hi = (None, None) if room is None else root_room_limits(*room)
        self.n_pose = self.skel.n_dofs
        self.n_shape = len(SHAPE_PARAMS)
        self.hypotheses: list[Hypothesis] = []
        self.frames_done = 0
        self.base_shape_state = (shape_to_state(fixed_shape) if fixed_shape is not None
                                 else np.ones(self.n_shape))
        self._init_spread = init_spread(self.skel, params.init_spread_scale)
        self._filters = startup_filters(self.skel, params, self.estimate_shape,
                                        self._init_spread, shape_std(params), self._kernel)

    # ------------------------------------------------------------------ kernel, weights

    def _clip(self, x: np.ndarray) -> np.ndarray:
        clip_body_pose(self.skel, x[:, :self.n_pose], self.room_lo, self.room_hi)
        lo, hi = self.params.shape_limits
        x[:, self.n_pose:] = np.clip(x[:, self.n_pose:], lo, hi)
        g = self.n_pose + SHAPE_KEYS.index("global")
        x[:, g] = np.clip(x[:, g], *self.params.scale_limits)
        return x

    def _log_prior(self, x: np.ndarray) -> np.ndarray:
        """Eq. 2.13 on the subject's proportions: entity sizes at global scale 1."""
        shape = shape_from_state(x[:, self.n_pose:])
        if self.params.prior_on_proportions:
            shape = BodyShape(shape.bone_scale, shape.radial_scale, np.ones(len(x)))
        return shape_log_prior(self.model, shape)

    def _kernel(self, particles: np.ndarray, std: np.ndarray,
                rng: np.random.Generator) -> np.ndarray:
        """Eq. 2.13's rejection sampling where a shape dimension diffuses, else Gaussian;
        then the joint, room and shape limits."""
        if self.estimate_shape and np.any(std[self.n_pose:] > 0):
            out = rejection_kernel(particles, std, rng, log_prior=self._log_prior,
                                   tau=self.params.rejection_tau,
                                   max_trials=self.params.rejection_trials,
                                   prior_dims=np.arange(self.n_pose, particles.shape[1]))
        else:
            out = particles
            active = np.flatnonzero(std > 0)
            if active.size:
                out[:, active] += rng.standard_normal((len(out), active.size)) * std[active]
        return self._clip(out)

    def _weight_fn(self, obs: Observation):
        """Eq. 2.8 costs, annealed by table 2.2's rate times the exponent that keeps
        ``survival_rate`` of the particles (eq. 2.9)."""
        rates = [row[3] for row in TABLE_2_2] + [1.0]
        target = self.params.survival_rate

        def weight_fn(x: np.ndarray, layer: int) -> np.ndarray:
            shape = (self.fixed_shape if self.fixed_shape is not None
                     else shape_from_state(x[:, self.n_pose:]))
            c = self.fitness.costs(x[:, :self.n_pose], obs, shape)
            beta = beta_for_survival_rate(c, target)
            return c * (rates[layer] * beta)
        return weight_fn

    def _shape_of(self, state: np.ndarray) -> BodyShape:
        return (self.fixed_shape if self.fixed_shape is not None
                else shape_from_state(state[self.n_pose:]))

    # ------------------------------------------------------------------ public

    def start(self, obs: Observation, hull: Hull, headings: tuple | None = None,
              also: tuple = ()) -> None:
        """Powell fits for each heading hypothesis and their initial particle sets.

        The global scale is the hull height over the model's (sec. 2.3.4). headings: the
        hypotheses' headings (None: :meth:`search_headings`); also: headings searched and
        kept as hypotheses in addition to the search's (e.g. the direction a person
        travels)."""
        p = self.params
        if self.fixed_shape is None:
            model_height = float(np.asarray(self.model.vertices)[:, 1].max())
            scale0 = float(np.clip(hull.height / model_height, *p.scale_limits))
            pelvis_y = float(self.skel.joints_rest[0][1]) * scale0
        else:
            scale0 = float(self.fixed_shape.global_scale)
            pelvis_y = float(self.fitness.rest(self.fixed_shape).joints[0][1])
        if headings is None:
            starts = self.search_headings(obs, hull, pelvis_y, scale0, required=also)
        else:
            starts = [(h, initial_pose(self.model, hull, h, pelvis_y))
                      for h in tuple(headings) + tuple(also)]
        self.hypotheses = []
        for h, pose0 in starts:
            params, scale, _ = powell_fit(
                self.fitness, obs, pose0, scale0, self.fixed_shape,
                fit_scale=self.fixed_shape is None and p.powell_scale, maxfev=p.powell_maxfev,
                limb_maxfev=p.limb_maxfev, scale_limits=p.scale_limits,
                proposer=self.proposer, rng=self.rng)
            shape_state = self.base_shape_state.copy()
            if self.fixed_shape is None:
                shape_state[SHAPE_KEYS.index("global")] = scale
            x0 = np.concatenate([params, shape_state])
            parts = np.tile(x0, (p.n_particles, 1))
            parts[1:, :self.n_pose] += (self.rng.standard_normal((p.n_particles - 1, self.n_pose))
                                        * self._init_spread * p.anneal_scale)
            self._clip(parts)
            self.hypotheses.append(Hypothesis(heading=float(h), particles=parts, estimate=x0))
        self.frames_done = 0

    def search_headings(self, obs: Observation, hull: Hull, pelvis_y: float, scale0: float,
                        n_headings: int = 8, keep: int = 2,
                        min_separation: float = np.deg2rad(60.0),
                        required: tuple = ()) -> list:
        """The ``keep`` most likely ``(heading, pose (D,))`` of a person standing in the hull,
        plus the ``required`` headings: :func:`~.startup_pose.search_headings` with this
        estimator's proposer, shape and random generator."""
        return search_headings(self.fitness, obs, hull, pelvis_y, scale0, self.rng,
                               proposer=self.proposer, fixed_shape=self.fixed_shape,
                               n_headings=n_headings, keep=keep,
                               min_separation=min_separation, required=required)

    def grow_to(self, hull: Hull, margin: float, column: float = 0.0) -> list:
        """Make each hypothesis whose body estimate stands more than ``margin`` metres below
        the visual hull's top on this frame taller by their ratio: the global scale and the
        pelvis height of its particles and estimate grow, clipped to ``scale_limits``.

        The start-up scales the body to one frame's hull height (sec. 2.3.4); when the
        segmentation lost the head in that frame, a later start-up frame's hull stands taller
        than the body, and the body's height is taken from it. Only growing: a lower hull is
        a bent pose or a lost head. ``column``: where the tops are read
        (:func:`body_and_hull_tops`); a hypothesis whose column holds no hull voxel is left
        as it is. Returns the factors applied (1.0 for hypotheses left as they were)."""
        if not self.estimate_shape or not self.hypotheses:
            return []
        est = np.stack([h.estimate for h in self.hypotheses])
        body_top, hull_top = body_and_hull_tops(self.model, est, hull, column)
        g = self.n_pose + SHAPE_KEYS.index("global")
        ty = int(self.skel.translation_dofs[1])
        lo, hi = self.params.scale_limits
        factors = []
        for hyp, have, top in zip(self.hypotheses, body_top, hull_top):
            if top is None or top - float(have) <= margin:
                factors.append(1.0)
                continue
            scale = float(hyp.estimate[g])
            f = float(np.clip(scale * top / float(have), lo, hi)) / scale
            for x in (hyp.particles, hyp.estimate[None]):
                x[:, g] *= f
                x[:, ty] *= f
            hyp.particles[:, g] = np.clip(hyp.particles[:, g], lo, hi)
            factors.append(f)
        return factors

    @property
    def done(self) -> bool:
        return self.frames_done >= max(self.params.frames, 1)

    def step(self, obs: Observation) -> list:
        """One table 2.2 layered-filtering run per hypothesis on this frame; diagnostics."""
        lpf = self._filters[min(self.frames_done, len(self._filters) - 1)]
        diags = []
        for hyp in self.hypotheses:
            if self.proposer is not None and self.params.proposal_fraction > 0.0:
                pose = hyp.particles[:, :self.n_pose]
                rest = self.fitness.rest(self._shape_of(hyp.estimate))
                self.proposer.apply(pose, hyp.estimate[:self.n_pose], rest, obs,
                                    self.fitness.faces, self.params.proposal_fraction, self.rng,
                                    cost_fn=lambda x, rest=rest: self.fitness.costs(x, obs, rest))
                hyp.particles[:, :self.n_pose] = pose
            res = lpf_run(hyp.particles, lpf, self._weight_fn(obs), self.rng)
            hyp.particles = res.particles
            hyp.estimate = res.estimate
            fit = float(self.fitness.costs(res.estimate[None, :self.n_pose], obs,
                                           self._shape_of(res.estimate))[0])
            hyp.costs.append(fit)
            diags.append(res)
        self.frames_done += 1
        return diags

    def best(self) -> Hypothesis:
        return min(self.hypotheses, key=lambda h: h.score)

    def shape(self) -> BodyShape:
        """The estimated shape (the fixed one when the shape is not estimated)."""
        if self.fixed_shape is not None:
            return self.fixed_shape
        return shape_from_state(self.best().estimate[self.n_pose:])

    def pose_particles(self) -> np.ndarray:
        """Pose part (N, D) of the best hypothesis' particles."""
        return self.best().particles[:, :self.n_pose].copy()
