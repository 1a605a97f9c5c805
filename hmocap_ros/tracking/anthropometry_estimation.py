"""Automatic start and anthropometry estimation from multi-view silhouettes (thesis sec. 2.3.3-2.3.4).

Pipeline, per person appearing in the room:

1. Visual hull (:mod:`.visual_hull`): the model is put at the hull centroid, standing, turned
   to the hull's heading, and scaled to the hull height (sec. 2.3.4).
2. Powell refinement (``scipy.optimize.minimize(method="Powell")``) of the global scale and the
   root (6 DoF), then of each limb separately (shoulder swing and elbow per arm, hip swing and
   knee per leg: "we split the variables of each limb in separate optimization steps").
   Silhouettes cannot tell a person's front from their back in every pose, so both headings
   of the hull's axis are refined, and kept as two hypotheses (below).
3. Layered filtering over shape and pose ``X = Phi u Theta`` with the layering of table 2.2:
   four annealing layers over head, upper arms, shoulder height and the whole pose (annealing
   rates 0.1, 0.3, 0.8, 1.0), then head and root, upper arms, lower arms, legs length and upper
   legs, lower legs, torso / legs / hip width, then a final layer over everything. The shape
   dimensions move with the rejection-sampling kernel of eq. 2.13
   (:func:`~hmocap_ros.lpf.kernels.rejection_kernel`, tau = 0.7, table 2.1 priors via
   :func:`~hmocap_ros.body.anthropometry.shape_log_prior`), the pose dimensions with a
   Gaussian kernel within the joint limits; the weighting is the silhouette XOR (eq. 2.8).
   It runs once per frame over the first ``frames`` frames (the subject moves, the shape does
   not), then each hypothesis' estimate is scored by its mean final cost and the better one
   wins.

Choices where the thesis is vague:

* Shape state: the global scale and the factors of :data:`SHAPE_PARAMS` (bone length and
  girth of the entities a silhouette can see at the working resolution; hands and feet stay
  at the model's proportions). Aggregates (shoulder height) and their parts (torso, legs) are
  separate factors multiplied together, as in :mod:`hmocap_ros.body.anthropometry`.
* Annealing rates: table 2.2's rates are read as the exponents ``beta`` of eq. 2.9 *relative*
  to the exponent that keeps half of the particles (``rate * beta_50``): the thesis' XOR cost
  and ours differ in scale, and a rate of 1 then means a normal selective layer.
* Eq. 2.13's acceptance test compares the candidate with the current particle:
  ``P(candidate) >= tau P(current)``; at most ``rejection_trials`` draws. The prior is
  evaluated on the subject's proportions (entity sizes at global scale 1): the global scale
  is measured (visual hull height), and table 2.1's absolute sizes would otherwise pull every
  entity of a tall or short subject back to the population mean.
* The global scale comes from the hull height (the subject is assumed upright at the start,
  as the thesis assumes a known pose); Powell refines the root and the limbs but not the
  scale (``powell_scale``), because a bent pose and a smaller body fit the same silhouette.
* Kernel order: as in :mod:`.body_layers`, the kernel of layer ``l`` diffuses the sub-state
  of layer ``l + 1`` (partitioned sampling), with the annealing layers' std decaying by
  ``sqrt(0.5)`` per layer (eq. 2.10, alpha = 0.5); over the frames the diffusion decays by
  ``frame_decay``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np
from scipy.optimize import minimize

from hmocap_ros.body.anthropometry import (ENTITY_NAMES, BodyShape, entity_sizes,
                                           shape_log_prior)
from hmocap_ros.tracking.body_fitness import Observation, SilhouetteFitness
from hmocap_ros.tracking.body_layers import body_sigma0, clip_body_pose, root_room_limits
from hmocap_ros.lpf.kernels import rejection_kernel
from hmocap_ros.tracking.limb_proposals import LimbProposalParams
from hmocap_ros.lpf.layered_filter import (Layer, LayeredFilter, beta_for_survival_rate,
                                                lpf_run)
from hmocap_ros.tracking.visual_hull import Hull

__all__ = [
    "SHAPE_PARAMS", "TABLE_2_2", "AnthropometryEstimator", "EstimationParams", "Hypothesis",
    "entity_size_errors", "initial_pose", "powell_fit", "shape_from_state", "shape_to_state",
]

#: Shape state: ("global", "") or (entity, "bone" | "radial").
SHAPE_PARAMS = (
    ("global", ""), ("shoulder_height", "bone"), ("head", "bone"), ("head", "radial"),
    ("clavicles", "bone"), ("upperarms", "bone"), ("upperarms", "radial"),
    ("lowerarms", "bone"), ("lowerarms", "radial"), ("legs", "bone"), ("legs", "radial"),
    ("lowerlegs", "bone"), ("torso", "bone"), ("hip_width", "bone"),
    ("torso_width", "radial"), ("torso_depth", "radial"),
)

#: Table 2.2: (label, shape parameters, pose DoF groups or DoF names, annealing rate).
#: "all" = every pose DoF (Theta); "root" = xi_0 (the root's 6 DoF).
_ANNEALED = ("head:bone", "upperarms:bone", "shoulder_height:bone")
TABLE_2_2 = (
    ("Psi_0 head, upper arms, shoulder height and Theta", _ANNEALED, "all", 0.1),
    ("Psi_1 (annealing)", _ANNEALED, "all", 0.3),
    ("Psi_2 (annealing)", _ANNEALED, "all", 0.8),
    ("Psi_3 (annealing)", _ANNEALED, "all", 1.0),
    ("Psi_4 head and xi_0", ("head:bone", "head:radial"), ("root",), 1.0),
    ("Psi_5 upper arms anthropometry and pose", ("upperarms:bone", "upperarms:radial",
                                                 "clavicles:bone"),
     ("l_shoulder", "r_shoulder", "l_elbow", "r_elbow"), 1.0),
    ("Psi_6 lower arms anthropometry and pose", ("lowerarms:bone", "lowerarms:radial"),
     ("l_elbow", "r_elbow"), 1.0),
    ("Psi_7 legs length and upper legs pose", ("legs:bone",),
     ("l_hip_flex", "l_hip_abd", "l_hip_twist", "r_hip_flex", "r_hip_abd", "r_hip_twist"), 1.0),
    ("Psi_8 lower legs anthropometry and pose", ("lowerlegs:bone",),
     ("l_knee_flex", "l_ankle_flex", "r_knee_flex", "r_ankle_flex"), 1.0),
    ("Psi_9 torso, legs and hip width", ("torso:bone", "hip_width:bone", "torso_width:radial",
                                         "torso_depth:radial", "legs:radial"),
     ("spine_flex", "spine_bend", "spine_twist", "neck_flex", "neck_bend", "neck_twist"), 1.0),
)

#: Coarser limb proposals for the heading search (10 headings x 4 limbs at start-up).
HEADING_SEARCH_SIZES = LimbProposalParams(n_swing=240, top_swings=6, n_distal=40, screen=16,
                                          top_configs=4)

ROOT_DOFS = ("root_tx", "root_ty", "root_tz", "root_yaw", "root_pitch", "root_roll")
LIMB_STEPS = (
    ("l_shoulder_flex", "l_shoulder_abd", "l_shoulder_twist", "l_elbow_flex"),
    ("r_shoulder_flex", "r_shoulder_abd", "r_shoulder_twist", "r_elbow_flex"),
    ("l_hip_flex", "l_hip_abd", "l_knee_flex"),
    ("r_hip_flex", "r_hip_abd", "r_knee_flex"),
)
#: Initial pose spread (metres / degrees) around the Powell fit, per generic DoF.
INIT_SPREAD = {
    "root_tx": 0.04, "root_ty": 0.03, "root_tz": 0.04, "root_yaw": 10.0, "root_pitch": 4.0,
    "root_roll": 4.0, "spine_flex": 6.0, "spine_bend": 4.0, "spine_twist": 6.0,
    "neck_flex": 8.0, "neck_bend": 5.0, "neck_twist": 10.0, "shoulder_flex": 20.0,
    "shoulder_abd": 15.0, "shoulder_twist": 20.0, "elbow_flex": 20.0, "hip_flex": 12.0,
    "hip_abd": 6.0, "hip_twist": 10.0, "knee_flex": 15.0, "ankle_flex": 8.0,
}


def _key(entity: str, kind: str) -> str:
    return f"{entity}:{kind}" if kind else entity


SHAPE_KEYS = tuple(_key(e, k) for e, k in SHAPE_PARAMS)


def shape_from_state(state: np.ndarray) -> BodyShape:
    """BodyShape of shape-state vectors (S,) or (N, S) (see :data:`SHAPE_PARAMS`)."""
    s = np.asarray(state, dtype=np.float64)
    batch = s.shape[:-1]
    e = len(ENTITY_NAMES)
    bone = np.ones(batch + (e,))
    radial = np.ones(batch + (e,))
    glob = np.ones(batch)
    for k, (entity, kind) in enumerate(SHAPE_PARAMS):
        if kind == "":
            glob = s[..., k]
        elif kind == "bone":
            bone[..., ENTITY_NAMES.index(entity)] = s[..., k]
        else:
            radial[..., ENTITY_NAMES.index(entity)] = s[..., k]
    glob = float(glob) if np.ndim(glob) == 0 else glob
    return BodyShape(bone, radial, glob)


def shape_to_state(shape: BodyShape) -> np.ndarray:
    """Shape-state vector (S,) of a single BodyShape (other entities are dropped)."""
    out = np.empty(len(SHAPE_PARAMS))
    for k, (entity, kind) in enumerate(SHAPE_PARAMS):
        if kind == "":
            out[k] = float(shape.global_scale)
        else:
            b, r = shape.entity(entity)
            out[k] = float(b if kind == "bone" else r)
    return out


def entity_size_errors(model, estimate: BodyShape | None, truth: BodyShape) -> dict:
    """Per-entity size error (metres, estimate - truth) via :func:`entity_sizes`."""
    est = entity_sizes(model, estimate)
    true = entity_sizes(model, truth)
    return {n: float(a - b) for n, a, b in zip(ENTITY_NAMES, est, true)}


@dataclass(frozen=True)
class EstimationParams:
    """Tunables of the start-up (see the module docstring)."""

    n_particles: int = 250
    frames: int = 4
    estimate_shape: bool = True
    survival_rate: float = 0.5
    rejection_tau: float = 0.7
    rejection_trials: int = 8
    shape_bone_std: float = 0.04
    shape_radial_std: float = 0.06
    global_std: float = 0.015
    init_spread_scale: float = 1.0
    anneal_scale: float = 0.25
    part_scale: float = 0.5
    frame_decay: float = 0.7
    anneal_alpha: float = 0.5
    powell_scale: bool = False
    prior_on_proportions: bool = True
    powell_maxfev: int = 120
    limb_maxfev: int = 30
    scale_limits: tuple = (0.8, 1.2)
    shape_limits: tuple = (0.7, 1.4)
    proposal_fraction: float = 0.0
    #: > 0 (stop 26): the first scale reads the head's top (:meth:`Hull.head_top` over the
    #: trunk's axis, column ``head_column``, this layer fraction) instead of the hull's top
    head_fraction: float = 0.0
    head_column: float = 0.15


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


def initial_pose(model, hull: Hull, heading: float, pelvis_y: float) -> np.ndarray:
    """Rest pose (D,) standing at the hull centroid, turned to ``heading``, with the pelvis
    at height ``pelvis_y`` (the shaped model's rest pelvis height)."""
    skel = model.skeleton
    p = np.zeros(skel.n_dofs)
    p[skel.translation_dofs] = [hull.centroid[0], pelvis_y, hull.centroid[2]]
    p[skel.dof_index("root_yaw")] = heading
    return p


#: Coarse grid (degrees) per limb DoF for the multi-start of each limb's Powell step.
LIMB_GRID = {
    "shoulder_flex": (-40, 0, 40, 80, 120), "shoulder_abd": (-60, -20, 20, 60, 100),
    "shoulder_twist": (-60, -20, 20, 60), "elbow_flex": (-40, 0, 40, 80),
    "hip_flex": (-20, 10, 40, 70), "hip_abd": (-20, 0, 20), "knee_flex": (0, 30, 60, 90),
}


def _best_on_grid(fitness: SilhouetteFitness, obs: Observation, params: np.ndarray,
                  idx: list, shape: BodyShape, rng: np.random.Generator | None = None,
                  keep: int = 8, rounds: tuple = (15.0, 8.0, 4.0), samples: int = 24,
                  extra: np.ndarray | None = None, grid: bool = True) -> np.ndarray:
    """Multi-start for one limb: the best of :data:`LIMB_GRID` after a local search.

    All grid points (and the current values) are weighed in one batch (eq. 2.8, the rest of
    the body as in ``params``); the ``keep`` best each get ``samples`` Gaussian perturbations
    per round (std in degrees per round), keeping their best; the winner is returned. The
    local search matters: on a coarse grid an arm hidden inside the torso silhouette costs
    less than a visible arm a few tens of degrees off, and only the refined candidates show
    which basin holds the true pose. ``extra``: more candidate parameter vectors (K, D) to
    weigh with the grid (the limb proposals of :mod:`.limb_proposals`); ``grid=False``
    starts from them (and the current values) alone.
    """
    skel = fitness.model.skeleton
    rng = rng if rng is not None else np.random.default_rng(0)
    axes = []
    for i in idx:
        name = skel.dof_names[i]
        name = name[2:] if name[:2] in ("l_", "r_") else name
        axes.append(np.deg2rad(LIMB_GRID[name]) if name in LIMB_GRID else np.array([params[i]]))
    points = (np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(idx)) if grid
              else np.empty((0, len(idx))))
    cand = np.tile(params, (len(points) + 1, 1))
    cand[1:, idx] = points
    if extra is not None and len(extra):
        cand = np.concatenate([cand, np.asarray(extra, dtype=np.float64)])
    clip_body_pose(skel, cand)
    costs = fitness.costs(cand, obs, shape)
    order = np.argsort(costs)[:keep]
    best, best_cost = cand[order], costs[order]
    for std in rounds:
        trial = np.repeat(best, samples, axis=0)
        trial[:, idx] += rng.standard_normal((len(trial), len(idx))) * np.deg2rad(std)
        clip_body_pose(skel, trial)
        c = fitness.costs(trial, obs, shape).reshape(len(best), samples)
        j = np.argmin(c, axis=1)
        better = c[np.arange(len(best)), j] < best_cost
        best[better] = trial.reshape(len(best), samples, -1)[np.flatnonzero(better), j[better]]
        best_cost[better] = c[np.flatnonzero(better), j[better]]
    return best[int(np.argmin(best_cost)), idx]


def powell_fit(fitness: SilhouetteFitness, obs: Observation, params0: np.ndarray,
               scale0: float, base_shape: BodyShape | None = None, *,
               fit_scale: bool = True, maxfev: int = 400, limb_maxfev: int = 120,
               scale_limits: tuple = (0.8, 1.2),
               limb_grid: bool = True, proposer=None,
               rng: np.random.Generator | None = None) -> tuple[np.ndarray, float, float]:
    """Powell refinement of (global scale,) root, then each limb (sec. 2.3.3 "To initialize").

    Each limb's Powell step starts from the best point of a coarse grid over its DoFs
    (``limb_grid``; one vectorised batch): silhouettes leave an arm's twist and elbow flexion
    multimodal, and a single start from the rest pose often ends in the wrong mode.
    ``proposer`` (a :class:`~.limb_proposals.LimbProposer`) adds its silhouette-driven
    candidates of each limb to the grid: a grid at 40 degree steps misses an arm held
    straight out, which the proposals find.
    Returns ``(params (D,), global scale, eq. 2.8 cost)``. ``base_shape`` is the shape whose
    global scale is refined (neutral by default).
    """
    skel = fitness.model.skeleton
    base = BodyShape.neutral() if base_shape is None else base_shape
    root = [skel.dof_index(n) for n in ROOT_DOFS]
    params = np.array(params0, dtype=np.float64)
    lo_s, hi_s = scale_limits

    def shaped(scale: float) -> BodyShape:
        return BodyShape(base.bone_scale, base.radial_scale, float(np.clip(scale, lo_s, hi_s)))

    def cost_of(p: np.ndarray, scale: float) -> float:
        q = clip_body_pose(skel, p[None].copy())
        return float(fitness.costs(q, obs, shaped(scale))[0])

    # Root and global scale, in units where one step moves things comparably.
    unit = np.array([0.1, 0.1, 0.1, 0.3, 0.2, 0.2])

    def f_root(z: np.ndarray) -> float:
        p = params.copy()
        p[root] = params0[root] + z[:6] * unit
        s = scale0 * (1.0 + 0.1 * z[6]) if fit_scale else scale0
        return cost_of(p, s)

    z0 = np.zeros(7 if fit_scale else 6)
    res = minimize(f_root if fit_scale else (lambda z: f_root(np.append(z, 0.0))), z0,
                   method="Powell", options={"maxfev": maxfev, "xtol": 1e-2, "ftol": 1e-4})
    z = np.append(res.x, 0.0) if not fit_scale else res.x
    params[root] = params0[root] + z[:6] * unit
    scale = float(np.clip(scale0 * (1.0 + 0.1 * z[6]), lo_s, hi_s)) if fit_scale else scale0
    rng = rng if rng is not None else np.random.default_rng(0)
    for names in LIMB_STEPS:
        idx = [skel.dof_index(n) for n in names]
        extra = None
        limb = f"{names[0][:2]}{'arm' if 'shoulder' in names[0] else 'leg'}"
        if proposer is not None and limb in proposer.limbs:
            rest = fitness.rest(shaped(scale))
            support, residual = proposer.evidence(obs, params, rest, fitness.faces)
            values, _ = proposer.candidates(limb, params, rest, obs, support, residual, rng,
                                            cost_fn=lambda x, rest=rest: fitness.costs(x, obs, rest))
            extra = np.repeat(params[None], len(values), axis=0)
            extra[:, proposer.dofs(limb)] = values
        if limb_grid or extra is not None:
            params[idx] = _best_on_grid(fitness, obs, params, idx, shaped(scale), rng,
                                        extra=extra, grid=extra is None,
                                        samples=24 if extra is None else 12)
        start = params[idx].copy()

        def f_limb(z: np.ndarray, idx=idx, start=start) -> float:
            p = params.copy()
            p[idx] = start + 0.3 * z
            return cost_of(p, scale)

        r = minimize(f_limb, np.zeros(len(idx)), method="Powell",
                     options={"maxfev": limb_maxfev, "xtol": 1e-2, "ftol": 1e-4})
        params[idx] = start + 0.3 * r.x
    params = clip_body_pose(skel, params[None].copy())[0]
    return params, scale, cost_of(params, scale)


class AnthropometryEstimator:
    """Start-up of one person: Powell, then table 2.2's layered filter over a few frames.

    fitness: weighting at the start-up's working resolution. room: the room box (pelvis
    limits). fixed_shape: a known shape; then only the pose is fitted and filtered.
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
        self.room_lo, self.room_hi = (None, None) if room is None else root_room_limits(*room)
        self.n_pose = self.skel.n_dofs
        self.n_shape = len(SHAPE_PARAMS)
        self.hypotheses: list[Hypothesis] = []
        self.frames_done = 0
        self.base_shape_state = (shape_to_state(fixed_shape) if fixed_shape is not None
                                 else np.ones(self.n_shape))
        self._init_spread = np.array([
            INIT_SPREAD[n[2:] if n[:2] in ("l_", "r_") else n] * (1.0 if n.startswith("root_t") else np.pi / 180)
            for n in self.skel.dof_names]) * params.init_spread_scale
        self._shape_std = np.array([params.global_std if k == "" else
                                    params.shape_bone_std if k == "bone" else
                                    params.shape_radial_std for _, k in SHAPE_PARAMS])
        self._filters = self._build_filters()

    # ------------------------------------------------------------------ state layout

    def _shape_index(self, keys) -> np.ndarray:
        return np.array([self.n_pose + SHAPE_KEYS.index(k) for k in keys], dtype=np.intp)

    def _pose_index(self, spec) -> np.ndarray:
        if spec == "all":
            return np.arange(self.n_pose)
        out = []
        for item in spec:
            if item == "root":
                out += [self.skel.dof_index(n) for n in ROOT_DOFS]
            elif item in self.skel.dof_names:
                out.append(self.skel.dof_index(item))
            else:
                out += list(self.skel.group_dofs(item))
        return np.array(sorted(set(out)), dtype=np.intp)

    def _layer_dims(self) -> list[np.ndarray]:
        dims = []
        for _, shape_keys, pose_spec, _ in TABLE_2_2:
            pose = self._pose_index(pose_spec)
            if self.estimate_shape:
                dims.append(np.concatenate([pose, self._shape_index(shape_keys)]))
            else:
                dims.append(pose)
        return dims

    def _base_std(self) -> np.ndarray:
        std = np.concatenate([self._init_spread, self._shape_std])
        if not self.estimate_shape:
            std[self.n_pose:] = 0.0
        return std

    def _build_filters(self) -> list[LayeredFilter]:
        """One LayeredFilter per start-up frame (the diffusion decays from frame to frame).

        The annealing layers (all 30 pose DoF at once) diffuse the pose by
        ``anneal_scale * INIT_SPREAD``, decaying by ``sqrt(anneal_alpha)`` per layer; the
        per-part layers (a few DoF each) by ``part_scale * INIT_SPREAD``; shape dimensions by
        their own std, with the same decays.
        """
        p = self.params
        dims = self._layer_dims()
        base = self._base_std()
        pose = np.arange(self.n_pose)
        n_anneal = sum(1 for row in TABLE_2_2 if row[2] == "all")
        out = []
        for f in range(max(p.frames, 1)):
            scale = p.frame_decay ** f
            layers = []
            for l in range(len(TABLE_2_2)):
                std = np.zeros(self.n_pose + self.n_shape)
                nxt = l + 1
                if nxt < len(TABLE_2_2):
                    d = dims[nxt]
                    if nxt < n_anneal:
                        factor = np.sqrt(p.anneal_alpha) ** nxt
                        std[d] = base[d] * scale * factor
                        std[pose] *= p.anneal_scale
                    else:
                        std[d] = base[d] * scale
                        std[pose] *= p.part_scale
                layers.append(Layer(dims=dims[l], beta=1.0, n_particles=p.n_particles, std=std,
                                    kernel=self._kernel()))
            final_std = np.zeros(self.n_pose + self.n_shape)
            final_std[:self.n_pose] = body_sigma0(self.skel)
            if self.estimate_shape:
                final_std[self.n_pose:] = self._shape_std * scale * p.frame_decay
            final = Layer(beta=1.0, n_particles=p.n_particles, std=final_std,
                          kernel=self._kernel())
            out.append(LayeredFilter(layers=tuple(layers), sigma0=base, final=final))
        return out

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

    def _kernel(self):
        def kernel(particles, std, rng):
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
        return kernel

    def _weight_fn(self, obs: Observation):
        rates = [row[3] for row in TABLE_2_2] + [1.0]
        target = self.params.survival_rate

        def weight_fn(x: np.ndarray, layer: int) -> np.ndarray:
            shape = (self.fixed_shape if self.fixed_shape is not None
                     else shape_from_state(x[:, self.n_pose:]))
            c = self.fitness.costs(x[:, :self.n_pose], obs, shape)
            beta = beta_for_survival_rate(c, target)
            self._last_costs = c
            return c * (rates[layer] * beta)
        return weight_fn

    # ------------------------------------------------------------------ public

    def start(self, obs: Observation, hull: Hull, headings: tuple | None = None,
              also: tuple = ()) -> None:
        """Powell fits for each heading hypothesis and their initial particle sets.

        headings: the hypotheses' headings (None: :meth:`search_headings`); also: headings
        searched and kept as hypotheses in addition to the search's (e.g. the direction a
        person travels, ``BodyTracker``'s ``travel_heading``)."""
        p = self.params
        if self.fixed_shape is None:
            model_height = float(np.asarray(self.model.vertices)[:, 1].max())
            top = hull.height
            if p.head_fraction > 0.0:
                head = hull.head_top(None, p.head_column, p.head_fraction)
                top = head if head is not None else top
            scale0 = float(np.clip(top / model_height, *p.scale_limits))
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
        """The ``keep`` most likely ``(heading, pose (D,))`` of a person standing in the hull.

        Without a limb proposer: the hull's two headings (its chest axis normals). With one:
        ``n_headings`` headings around the circle, plus the hull's pair, each posed at the
        hull centroid with every limb set to the best of its silhouette-driven candidates
        (one batch of weightings per limb, eq. 2.8); the cheapest headings at least
        ``min_separation`` apart are kept. The chest-axis guess alone fails when the arms are
        held out at chest height, and is ambiguous front/back anyway. ``required`` headings
        are posed the same way and kept in addition, whatever their cost.
        """
        required = tuple(float(h) for h in required)
        if self.proposer is None:
            return [(h, initial_pose(self.model, hull, h, pelvis_y))
                    for h in (hull.heading, hull.heading + np.pi) + required]
        shape = (self.fixed_shape if self.fixed_shape is not None
                 else BodyShape(np.ones(len(ENTITY_NAMES)), np.ones(len(ENTITY_NAMES)), scale0))
        rest = self.fitness.rest(shape)
        cands = np.concatenate([hull.heading + np.array([0.0, np.pi]),
                                hull.heading + np.pi / n_headings
                                + np.arange(n_headings) * 2 * np.pi / n_headings,
                                np.asarray(required, dtype=float)])
        costs, poses = [], []
        for h in cands:
            pose = initial_pose(self.model, hull, h, pelvis_y)
            support, residual = self.proposer.evidence(obs, pose, rest, self.fitness.faces)
            for limb in self.proposer.limbs:
                values, c = self.proposer.candidates(
                    limb, pose, rest, obs, support, residual, self.rng,
                    cost_fn=lambda x, rest=rest: self.fitness.costs(x, obs, rest),
                    sizes=HEADING_SEARCH_SIZES)
                c0 = float(self.fitness.costs(pose[None], obs, rest)[0])
                if len(values) and c[0] < c0:
                    pose = pose.copy()
                    pose[self.proposer.dofs(limb)] = values[0]
            costs.append(float(self.fitness.costs(pose[None], obs, shape)[0]))
            poses.append(pose)
        chosen: list = []
        searched = len(cands) - len(required)
        for i in np.argsort(costs[:searched]):
            d = np.abs((cands[i] - np.array([h for h, _ in chosen]) + np.pi) % (2 * np.pi) - np.pi)
            if not chosen or d.min() >= min_separation:
                chosen.append((float(cands[i]), poses[i]))
            if len(chosen) == keep:
                break
        return chosen + [(float(cands[i]), poses[i]) for i in range(searched, len(cands))]

    def grow_to(self, hull: Hull, margin: float, column: float = 0.0,
                head_fraction: float = 0.0) -> list:
        """Make each hypothesis whose body estimate stands more than ``margin`` metres below
        the visual hull's top on this frame taller by their ratio: the global scale and the
        pelvis height of its particles and estimate grow, clipped to ``scale_limits``.

        The start-up scales the body to one frame's hull height (sec. 2.3.4); when the
        segmentation lost the head in that frame, a later start-up frame's hull stands taller
        than the body, and the body's height is taken from it (our addition; the thesis
        assumes one good frame). Only growing: a lower hull is a bent pose or a lost head.

        ``column`` > 0 (stop 25): both tops are read in the column of that radius (metres,
        on the floor) around the hypothesis' head top, the hull's with
        :meth:`Hull.top_within`, the body's from its vertices there; a hand raised beside
        the head then tops neither (stop 24's held-out laugh: the hull's highest voxel was
        the hand, and a body whose arm was still down grew by 10 %). A hypothesis whose
        column holds no hull voxel is left as it is. 0: the hull's and the body's highest
        points (stop 23). ``head_fraction`` > 0 with a column (stop 26): the hull's top there
        is its head's (:meth:`Hull.head_top`, a hand held over the head passed over) and the
        body's is its crown (the ``head_top`` end site), not its highest vertex in the column,
        which its own raised hand may be.
        Returns the factors applied (1.0 for hypotheses left as they were)."""
        if not self.estimate_shape or not self.hypotheses:
            return []
        est = np.stack([h.estimate for h in self.hypotheses])
        posed = self.model.forward(est[:, :self.n_pose], shape_from_state(est[:, self.n_pose:]))
        verts = posed.vertices
        if column > 0.0:
            crown = posed.end_sites[:, self.model.end_site_names.index("head_top")]
            head = crown[:, [0, 2]]
            if head_fraction > 0.0:
                body_top = crown[:, 1]
                hull_top = [hull.head_top(c, column, head_fraction) for c in head]
            else:
                d = verts[..., [0, 2]] - head[:, None]
                near = np.einsum("bvk,bvk->bv", d, d) <= column * column
                body_top = np.where(near, verts[..., 1], -np.inf).max(axis=1)
                hull_top = [hull.top_within(c, column) for c in head]
        else:
            body_top = verts[..., 1].max(axis=1)
            hull_top = [hull.top] * len(self.hypotheses)
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
                shape = (self.fixed_shape if self.fixed_shape is not None
                         else shape_from_state(hyp.estimate[self.n_pose:]))
                pose = hyp.particles[:, :self.n_pose]
                rest = self.fitness.rest(shape)
                self.proposer.apply(pose, hyp.estimate[:self.n_pose], rest, obs,
                                    self.fitness.faces, self.params.proposal_fraction, self.rng,
                                    cost_fn=lambda x, rest=rest: self.fitness.costs(x, obs, rest))
                hyp.particles[:, :self.n_pose] = pose
            res = lpf_run(hyp.particles, lpf, self._weight_fn(obs), self.rng)
            hyp.particles = res.particles
            hyp.estimate = res.estimate
            shape = (self.fixed_shape if self.fixed_shape is not None
                     else shape_from_state(res.estimate[self.n_pose:]))
            fit = float(self.fitness.costs(res.estimate[None, :self.n_pose], obs, shape)[0])
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
