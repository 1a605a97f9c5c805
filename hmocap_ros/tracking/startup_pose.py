"""First pose of the start-up: hull placement, heading search, Powell fit (thesis sec. 2.3.3-2.3.4).

"The initial position is computed from the visual hull centroid [...] and the model is scaled
to fit the visual hull height" (sec. 2.3.4): :func:`initial_pose` stands the model at the
hull centroid, turned to a heading. Then "a sequence of optimization steps using Powell's
method [...] to adjust the pose and global scale of the model [...]; we split the variables of
each limb in separate optimization steps" (sec. 2.3.3): :func:`powell_fit` refines the root
(and optionally the global scale), then each limb (shoulder swing and elbow per arm, hip swing
and knee per leg), every cost the silhouette XOR of eq. 2.8.

Choices where the thesis is vague:

* Headings: silhouettes cannot tell a person's front from their back in every pose, and the
  thesis' subject faces a predefined direction. :func:`search_headings` poses the model at
  several headings with its limbs set by silhouette-driven proposals (:mod:`.limb_proposals`)
  and keeps the cheapest distinct ones, each refined and filtered as its own hypothesis.
* Limb multi-start: each limb's Powell step starts from the best of a coarse grid over its
  DoFs, refined locally (:func:`best_on_grid`), since a silhouette leaves an arm's twist and
  elbow flexion multimodal.
* The global scale is the hull height over the model's (the subject is assumed upright at
  the start, as the thesis assumes a known pose); Powell refines the root and the limbs but,
  by default, not the scale, because a bent pose and a smaller body fit the same silhouette.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from hmocap_ros.body.anthropometry import ENTITY_NAMES, BodyShape
from hmocap_ros.detection.visual_hull import Hull
from hmocap_ros.tracking.anthropometry_state import ROOT_DOFS
from hmocap_ros.tracking.body_fitness import Observation, SilhouetteFitness
from hmocap_ros.tracking.body_layers import clip_body_pose
from hmocap_ros.tracking.limb_proposals import LimbProposalParams

__all__ = ["HEADING_SEARCH_SIZES", "LIMB_GRID", "LIMB_STEPS", "best_on_grid", "initial_pose",
           "powell_fit", "search_headings"]

#: Coarser limb proposals for the heading search (10 headings x 4 limbs at start-up).
HEADING_SEARCH_SIZES = LimbProposalParams(n_swing=240, top_swings=6, n_distal=40, screen=16,
                                          top_configs=4)

#: The limbs' separate Powell steps (sec. 2.3.3), in order.
LIMB_STEPS = (
    ("l_shoulder_flex", "l_shoulder_abd", "l_shoulder_twist", "l_elbow_flex"),
    ("r_shoulder_flex", "r_shoulder_abd", "r_shoulder_twist", "r_elbow_flex"),
    ("l_hip_flex", "l_hip_abd", "l_knee_flex"),
    ("r_hip_flex", "r_hip_abd", "r_knee_flex"),
)

#: Coarse grid (degrees) per limb DoF for the multi-start of each limb's Powell step.
LIMB_GRID = {
    "shoulder_flex": (-40, 0, 40, 80, 120), "shoulder_abd": (-60, -20, 20, 60, 100),
    "shoulder_twist": (-60, -20, 20, 60), "elbow_flex": (-40, 0, 40, 80),
    "hip_flex": (-20, 10, 40, 70), "hip_abd": (-20, 0, 20), "knee_flex": (0, 30, 60, 90),
}


def initial_pose(model, hull: Hull, heading: float, pelvis_y: float) -> np.ndarray:
    """Rest pose (D,) standing at the hull centroid, turned to ``heading``, with the pelvis
    at height ``pelvis_y`` (the shaped model's rest pelvis height)."""
    skel = model.skeleton
    p = np.zeros(skel.n_dofs)
    p[skel.translation_dofs] = [hull.centroid[0], pelvis_y, hull.centroid[2]]
    p[skel.dof_index("root_yaw")] = heading
    return p


def best_on_grid(fitness: SilhouetteFitness, obs: Observation, params: np.ndarray,
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


def _limb_proposals(fitness: SilhouetteFitness, obs: Observation, params: np.ndarray,
                    rest, limb: str, proposer, rng: np.random.Generator) -> np.ndarray:
    """Candidate parameter vectors (K, D): ``params`` with one limb set to each of the
    proposer's silhouette-driven configurations."""
    support, residual = proposer.evidence(obs, params, rest, fitness.faces)
    values, _ = proposer.candidates(limb, params, rest, obs, support, residual, rng,
                                    cost_fn=lambda x, rest=rest: fitness.costs(x, obs, rest))
    extra = np.repeat(params[None], len(values), axis=0)
    extra[:, proposer.dofs(limb)] = values
    return extra


def powell_fit(fitness: SilhouetteFitness, obs: Observation, params0: np.ndarray,
               scale0: float, base_shape: BodyShape | None = None, *,
               fit_scale: bool = True, maxfev: int = 400, limb_maxfev: int = 120,
               scale_limits: tuple = (0.8, 1.2),
               limb_grid: bool = True, proposer=None,
               rng: np.random.Generator | None = None) -> tuple[np.ndarray, float, float]:
    """Powell refinement of (global scale,) root, then each limb (sec. 2.3.3 "To initialize").

    Each limb's Powell step starts from the best point of a coarse grid over its DoFs
    (``limb_grid``, :func:`best_on_grid`; one vectorised batch). ``proposer`` (a
    :class:`~.limb_proposals.LimbProposer`) replaces the grid of its limbs by its
    silhouette-driven candidates: a grid at 40 degree steps misses an arm held straight out,
    which the proposals find.
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
            extra = _limb_proposals(fitness, obs, params, fitness.rest(shaped(scale)), limb,
                                    proposer, rng)
        if limb_grid or extra is not None:
            params[idx] = best_on_grid(fitness, obs, params, idx, shaped(scale), rng,
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


def _chosen_headings(cands: np.ndarray, costs: list, poses: list, n_searched: int,
                     keep: int, min_separation: float) -> list:
    """The ``keep`` cheapest of the first ``n_searched`` candidates at least ``min_separation``
    apart, then every candidate after them: ``[(heading, pose (D,)), ...]``."""
    chosen: list = []
    for i in np.argsort(costs[:n_searched]):
        d = np.abs((cands[i] - np.array([h for h, _ in chosen]) + np.pi) % (2 * np.pi) - np.pi)
        if not chosen or d.min() >= min_separation:
            chosen.append((float(cands[i]), poses[i]))
        if len(chosen) == keep:
            break
    return chosen + [(float(cands[i]), poses[i]) for i in range(n_searched, len(cands))]


def search_headings(fitness: SilhouetteFitness, obs: Observation, hull: Hull, pelvis_y: float,
                    scale0: float, rng: np.random.Generator, *, proposer=None,
                    fixed_shape: BodyShape | None = None, n_headings: int = 8, keep: int = 2,
                    min_separation: float = np.deg2rad(60.0), required: tuple = ()) -> list:
    """The ``keep`` most likely ``(heading, pose (D,))`` of a person standing in the hull.

    Without a limb proposer: the hull's two headings (its chest axis normals). With one:
    ``n_headings`` headings around the circle, plus the hull's pair, each posed at the
    hull centroid (:func:`initial_pose`) with every limb set to the best of its
    silhouette-driven candidates (one batch of weightings per limb, eq. 2.8); the cheapest
    headings at least ``min_separation`` apart are kept. The chest-axis guess alone fails
    when the arms are held out at chest height, and is ambiguous front/back anyway.
    ``required`` headings are posed the same way and kept in addition, whatever their cost.
    The body is ``fixed_shape``, else the model's proportions at global scale ``scale0``.
    """
    model = fitness.model
    required = tuple(float(h) for h in required)
    if proposer is None:
        return [(h, initial_pose(model, hull, h, pelvis_y))
                for h in (hull.heading, hull.heading + np.pi) + required]
    shape = (fixed_shape if fixed_shape is not None
             else BodyShape(np.ones(len(ENTITY_NAMES)), np.ones(len(ENTITY_NAMES)), scale0))
    rest = fitness.rest(shape)
    cands = np.concatenate([hull.heading + np.array([0.0, np.pi]),
                            hull.heading + np.pi / n_headings
                            + np.arange(n_headings) * 2 * np.pi / n_headings,
                            np.asarray(required, dtype=float)])
    costs, poses = [], []
    for h in cands:
        pose = initial_pose(model, hull, h, pelvis_y)
        support, residual = proposer.evidence(obs, pose, rest, fitness.faces)
        for limb in proposer.limbs:
            values, c = proposer.candidates(
                limb, pose, rest, obs, support, residual, rng,
                cost_fn=lambda x, rest=rest: fitness.costs(x, obs, rest),
                sizes=HEADING_SEARCH_SIZES)
            c0 = float(fitness.costs(pose[None], obs, rest)[0])
            if len(values) and c[0] < c0:
                pose = pose.copy()
                pose[proposer.dofs(limb)] = values[0]
        costs.append(float(fitness.costs(pose[None], obs, shape)[0]))
        poses.append(pose)
    return _chosen_headings(cands, costs, poses, len(cands) - len(required), keep,
                            min_separation)
