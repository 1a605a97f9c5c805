"""Markerless body tracker: foreground masks of a calibrated rig in, a 3D body pose out.

One :class:`BodyTracker` per rig; ``update(masks, stamp_ns)`` per synchronised frame set. No
rclpy: the ``body_tracker`` node, the bag evaluator (``hmocap eval mocap``) and the tests call
the same method. The tracker is a state machine (:class:`~.result.TrackerState`):

``searching``
    no person: too little foreground in too few views, or no visual hull. No pose.
``initialising``
    a person appeared: visual hull, Powell fit and the layered anthropometry estimation of
    thesis sec. 2.3 over the first ``startup.frames`` frames (:mod:`.startup`). A pose is
    reported.
``tracking``
    layered particle filtering per frame with the method's schedule (:mod:`.methods`,
    :mod:`.body_layers`) and the silhouette XOR weighting (:mod:`.body_fitness`, eq. 2.8 /
    2.15). ``dd-hpf`` (sec. 2.5) also takes the frame set's 3D detections
    (:mod:`hmocap_ros.detection`): they are assigned to the body (:mod:`.detector_driven`),
    IK particles put the arms where the hands are (:mod:`.ik_proposals`), each layer weighs
    its joints' labelled detections and the final layer adds eq. 2.20-2.21.
    Fresh searches (:mod:`.research`) re-seed the filter when they find a better pose.
``lost``
    the fit cost of the estimate stayed above ``lost.cost`` for ``lost.frames`` frames; the
    next frame starts again from the visual hull (keeping the estimated shape).

Robustness: a mask that is None or of the wrong size drops that view for the frame (the cost
sums over the others); an empty frame set resets to ``searching``; weighting errors (no
finite cost) count as a collapsed fit. The estimated shape is kept while the person is away
for fewer than ``lost.forget_shape_frames`` frames, then estimated anew for the next person.

Inter-frame prediction: the thesis' kernel is a zero-mean Gaussian around the last estimate.
Before the filter runs, the particles' pelvis position is shifted by :data:`VELOCITY_GAIN`
times the estimate's last frame-to-frame displacement: a constant-velocity prior. A walking
or running person moves 5-12 cm per frame, several times the Gaussian's std; limbs reverse
too quickly for such a prior to help them.

Time between frame sets: a live node that cannot keep up tracks the newest frame set and
skips the others, so the frame sets a tracker processes may lie several camera frames
apart. The frame period comes from the stamps (:class:`~hmocap_ros.frame_sets.FramePeriod`: the median difference
of consecutive stamps, those of frame sets seen but skipped included, see :meth:`saw`); the
time between two processed frame sets counts in whole periods ``k`` (at least 1), and:

- the velocity step is scaled by ``k_now / k_before``, the periods since the last processed
  frame set over the periods between the two before it (the displacement of the last
  estimate spans ``k_before`` periods);
- the inter-frame diffusion, whose stds (``sigma0``, :mod:`.body_layers`) are the motion of
  one 25 fps frame, grows with ``k_now``: every layer's kernel std is scaled by ``k_now``,
  and the blocks that the last frame's inter-frame kernel already diffused (the torso for
  the hierarchical schedules, every DoF for the APF) get the rest of their ``k_now *
  sigma0`` before the filter runs. Over a few frames a body's motion is smooth (a limb keeps
  its velocity), so its change grows with the time itself, not with its square root.

Both use ``min(k_now, MAX_ELAPSED_PERIODS)`` (4 periods, 160 ms at 25 fps): beyond that a
velocity extrapolation and a wider search place more particles where the body is not than
they recover; a track lost over a long gap starts again from the visual hull. With a frame
set every period (``k = 1``) both are exactly the thesis' model: the same numbers and the
same random draws.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from typing import Sequence

import numpy as np

from hmocap_ros.body.anthropometry import BodyShape
from hmocap_ros.detection.detections import MODEL_JOINT, Detections
from hmocap_ros.detection.visual_hull import room_bounds
from hmocap_ros.frame_sets import FramePeriod
from hmocap_ros.geometry.pinhole_camera import PinholeCamera
from hmocap_ros.geometry.rig import Rig
from hmocap_ros.lpf.layered_filter import LayeredFilter, lpf_run
from hmocap_ros.tracking.body_fitness import Observation, SilhouetteFitness
from hmocap_ros.tracking.body_frames import joint_spread, joint_transforms
from hmocap_ros.tracking.body_layers import (
    JUMP_FRACTION,
    JUMP_SCALE,
    RESEED_FRACTION,
    SURVIVAL_RATE,
    BodySchedule,
    pose_kernel,
    root_room_limits,
)
from hmocap_ros.tracking.detection_assignment import EFFECTOR_LABELS, Assigned
from hmocap_ros.tracking.keypoint_anthropometry import KeypointShape, size_corrections
from hmocap_ros.tracking.keypoint_first import BLOCK_KEYPOINTS, KeypointFirst
from hmocap_ros.tracking.keypoint_fit import FitResult, load_keypoint_model
from hmocap_ros.tracking.layer_weighting import fit_cost, layer_vertices, layer_weight_fn, warm_up
from hmocap_ros.tracking.limb_proposals import PROPOSAL_FRACTION, LimbProposer
from hmocap_ros.tracking.params import TRACKER_MESHES, TrackerParams
from hmocap_ros.tracking.research import ResearchPolicy, fresh_search
from hmocap_ros.tracking.result import STATES, TrackerState, TrackResult, stage_timings
from hmocap_ros.tracking.schedules import schedule_for
from hmocap_ros.tracking.startup import SAME_PERSON_RADIUS, HullFinder, StartUp

__all__ = ["MAX_ELAPSED_PERIODS", "SAME_PERSON_RADIUS", "STATES", "VELOCITY_GAIN", "BodyTracker",
           "TrackResult", "TrackerParams", "TrackerState"]

log = logging.getLogger(__name__)

#: Stages timed per frame (``TrackResult.timings``), besides the weighting's own.
STAGES = ("observe", "hull", "init", "filter", "proposals", "detection", "fit")
#: Spread (m) reported for a joint no keypoint places in a frame set where no filter ran: its
#: confidence is then exp(-3), whatever the other joints' fit
UNSEEN_SPREAD = 0.15
#: Most frame periods between two processed frame sets that the motion model accounts for
#: (velocity extrapolation and diffusion; module docstring).
MAX_ELAPSED_PERIODS = 4
#: seconds (of frame stamps, a person in view) kf-hpf given a keypoint detector's frame sets
#: waits for keypoints that start a track before it starts one from the silhouettes (sec. 2.3):
#: the detector's region needs a few frames to find a person who just came in, and a silhouette
#: start-up costs seconds of CPU per frame, which a live tracker cannot spend
KEYPOINT_START_WAIT_S = 2.0
#: Growth (m per second without keypoints) of the joints' spread while a live keypoint-first
#: track goes on from its prediction (:meth:`BodyTracker.update` with a budget): the
#: confidence exp(-spread / 0.05) of a joint fitted to 1 cm falls below 0.1 within 0.3 s
COAST_SPREAD_M_PER_S = 0.4
#: Share of the estimate's last frame-to-frame pelvis displacement added to the particles
#: before filtering (module docstring): 1, a constant-velocity prior for the pelvis, where the
#: thesis' kernel is a zero-velocity Gaussian; a walking person's 5-12 cm per frame are
#: several times that Gaussian's std.
VELOCITY_GAIN = 1.0


def working_scale(cameras, width: int) -> float:
    """The image scale that takes the widest camera to ``width`` pixels, at most 1."""
    return min(1.0, float(width) / max(c.width for c in cameras))


class BodyTracker:
    """Layered-filter body tracker for one rig (see the module docstring).

    model: ``load_body_model("tracking")`` (rendered with ``weighting.mesh``; another model,
    e.g. from ``read_body_model``, is rendered as it is). rig: the calibrated cameras (a Rig or
    list of PinholeCamera at the masks' resolution). params: :class:`TrackerParams`. rng: the
    only source of randomness (seed it for repeatable runs). shape: a known body shape (skips
    the anthropometry estimation).
    """

    def __init__(self, model, rig: Rig | Sequence[PinholeCamera], params: TrackerParams | None = None,
                 rng: np.random.Generator | None = None, shape: BodyShape | None = None):
        self.cameras = tuple(rig)
        if not self.cameras:
            raise ValueError("the rig has no cameras")
        self.params = p = params or TrackerParams()
        self.method = p.tracking_method
        # a shipped tracking body is swapped for weighting.mesh (same joints and DoFs; a
        # shape's factors then scale that mesh's surface); any other model is rendered as it is
        if model.name in TRACKER_MESHES:
            model = model.with_mesh(p.weighting.mesh)
        self.model = model
        self.skel = model.skeleton
        self.rng = rng if rng is not None else np.random.default_rng()
        self.given_shape = shape
        scale = working_scale(self.cameras, p.weighting.working_width)
        shape_scale = working_scale(self.cameras, p.startup.working_width)
        self.fitness = SilhouetteFitness(model, self.cameras, scale)
        self.shape_fitness = (self.fitness if shape_scale == scale else
                              SilhouetteFitness(model, self.cameras, shape_scale))
        self.room = room_bounds(self.cameras)
        self.finder = HullFinder(p, self.room)
        self.schedule: BodySchedule = schedule_for(p, self.skel, self.room[0], self.room[1])
        self._layer_vertices = layer_vertices(model, self.schedule)
        self.proposer = LimbProposer(model, ("l_arm", "r_arm"))
        self.start_proposer = LimbProposer(model, ("l_arm", "r_arm", "l_leg", "r_leg"))
        self.research = ResearchPolicy(p.research)
        self.keypoint_first: KeypointFirst | None = None
        if self.method.keypoint_first:
            lo, hi = root_room_limits(*self.room)
            kernel = pose_kernel(self.skel, lo, hi, JUMP_FRACTION, JUMP_SCALE, RESEED_FRACTION)
            landmarks = load_keypoint_model()
            self.keypoint_first = KeypointFirst(model, p.keypoints,
                                                self.schedule.n_particles, SURVIVAL_RATE,
                                                kernel, (lo, hi), landmarks["offsets"])
            self._size_corrections = size_corrections(landmarks["size_corrections"])
        #: what makes the detections drive propagation (dd-hpf), else None
        self.driven = self.method.detection_driver(model, self.schedule.layer_blocks)
        #: why the last frame set ran the silhouette filter instead of the keypoint-first one
        self.fallback_reason = ""
        self._fallback_logged = False
        self.frame_period = FramePeriod()
        self._stamps: tuple = ()  # stamps of the last two frame sets processed
        self._elapsed = (1, 1)    # periods between those two, and from the last to this one
        self._scaled_filters: dict[int, LayeredFilter] = {}
        #: per joint, the body block that places it: the block of the nearest ancestor with
        #: DoFs (a wrist's is its elbow's)
        groups = {int(j): g for j, g in zip(self.skel.dof_joint, self.skel.dof_groups)}
        parents = np.asarray(model.parents)
        self._joint_blocks = []
        for j in range(self.skel.n_joints):
            a = int(parents[j]) if j else 0
            while a > 0 and a not in groups:
                a = int(parents[a])
            self._joint_blocks.append(groups.get(a, "torso"))
        #: the last keypoint-first frame: (labels fitted, labels dropped, uncertain blocks)
        self.last_keypoints: tuple = ((), (), ())
        #: running mean of the seconds one weight evaluation takes (the live budget's unit)
        self._seconds_per_evaluation = 2e-4
        self.reset()

    # ------------------------------------------------------------------ state

    def reset(self, forget_shape: bool = True) -> None:
        """Back to ``searching``; optionally forget the estimated shape."""
        self.state = TrackerState.SEARCHING
        self.particles: np.ndarray | None = None
        self.estimate: np.ndarray | None = None
        self._previous_estimate: np.ndarray | None = None
        self._startup: StartUp | None = None
        self._bad_frames = 0
        self._absent_frames = 0
        self._keypoints_awaited_since: int | None = None
        #: stamp of the first frame set a live track went on without keypoints (None: it has them)
        self._coasting_since: int | None = None
        #: the joints' spread of the last frame set fitted to keypoints
        self._last_spread: np.ndarray | None = None
        self.research.reset()
        if self.driven is not None:
            self.driven.reset()
        if forget_shape:
            self.shape: BodyShape | None = self.given_shape
            self.keypoint_shape = (KeypointShape(self.model, self._size_corrections,
                                                 self.keypoint_first.fitter)
                                   if self.keypoint_first is not None
                                   and self.given_shape is None else None)

    @property
    def shape_known(self) -> bool:
        return self.shape is not None

    @property
    def position(self) -> np.ndarray | None:
        """Where the followed person's pelvis is (room, metres), or None when not following
        anybody (searching or lost)."""
        if not self.state.follows_person or self.estimate is None:
            return None
        return self.estimate[self.skel.translation_dofs].copy()

    def mesh(self) -> np.ndarray | None:
        """The followed body's mesh vertices (V, 3) at its current estimate (room, metres), or
        None when not following anybody."""
        if not self.state.follows_person or self.estimate is None:
            return None
        return self.model.forward(self.estimate[None], self._current_shape()).vertices[0]

    def _current_shape(self) -> BodyShape | None:
        if self.shape is not None:
            return self.shape
        if self._startup is not None:
            return self._startup.estimator.shape()
        return None

    def saw(self, stamp_ns: int) -> None:
        """A frame set of ``stamp_ns`` came but is not processed (a node that keeps up by
        skipping sets): its stamp still measures the frame period."""
        self.frame_period.add(stamp_ns)

    def warm_up(self) -> float:
        """Compile the weighting's numba kernels (:func:`~.layer_weighting.warm_up`);
        returns the seconds it took."""
        return warm_up(self.fitness, self.proposer, self.model)

    # ------------------------------------------------------------------ weighting

    def weight_fn(self, obs: Observation, shape: BodyShape | None,
                  assigned: Assigned | None = None):
        """The schedule's weighting (:func:`~.layer_weighting.layer_weight_fn`): eq. 2.8, or
        eq. 2.15 in the layer's observation boxes; with detections, each layer adds its
        joints' detection term and the final layer is the refinement layer of eq. 2.21."""
        rest = self.fitness.rest(shape)
        terms = self.driven.layer_terms(assigned, rest) if self.driven is not None else None
        return layer_weight_fn(self.fitness, self.model, self.schedule, self._layer_vertices,
                               obs, rest, terms)

    # ------------------------------------------------------------------ update

    def update(self, masks: Sequence[np.ndarray | None], stamp_ns: int,
               detections: Detections | None = None,
               exclude: np.ndarray | None = None,
               budget_s: float | None = None) -> TrackResult:
        """Process one frame set: one foreground mask per rig camera (None where missing).

        detections: the extremity detector's 3D detections of this frame set
        (:class:`~hmocap_ros.detection.detections.Detections`) or None; used by methods that
        use a detector (``dd-hpf``), which without them run as their boxed schedule. exclude: (K, 3) room
        points where people followed by other trackers stand
        (:class:`~.people_tracker.PeopleTracker`): a start never takes a person within
        :data:`SAME_PERSON_RADIUS` of one of them. budget_s: seconds this frame set may
        take (a live node's frame period); ``kf-hpf`` then spends on its filter only the
        weight evaluations that fit in it (:mod:`.keypoint_first`); None: no limit.
        """
        t_start = time.perf_counter()
        self._note_stamp(int(stamp_ns))
        self.fitness.times.reset()
        if self.shape_fitness is not self.fitness:
            self.shape_fitness.times.reset()
        timings = dict.fromkeys(STAGES, 0.0)
        masks = list(masks) if masks is not None else [None] * len(self.cameras)
        if len(masks) != len(self.cameras):
            log.error("expected %d masks, got %d: frame skipped", len(self.cameras), len(masks))
            masks = (masks + [None] * len(self.cameras))[:len(self.cameras)]
        t0 = time.perf_counter()
        obs = self.fitness.observe(masks, stamp_ns)
        seeing = int(np.sum(obs.counts >= self.params.startup.min_foreground))
        timings["observe"] = time.perf_counter() - t0
        if obs.dropped:
            log.debug("frame %d: views %s missing or invalid", stamp_ns, obs.dropped)
        if seeing == 0 or (self.state.looking and seeing < self.params.startup.min_views):
            self._person_absent()
            return self._result(stamp_ns, obs, t_start, timings)
        self._absent_frames = 0
        if self.state.looking and self.keypoint_first is not None:
            t0 = time.perf_counter()
            fit = self._start_from_keypoints(detections, exclude)
            timings["fit"] = time.perf_counter() - t0
            if fit is not None:
                assert detections is not None  # a fit is made of the frame set's keypoints
                self._keypoints_awaited_since = None
                return self._result(stamp_ns, obs, t_start, timings, self._fit_cost(obs),
                                    extremities=self._keypoint_assigned(fit, detections),
                                    spread=self._fit_spread(fit))
            if detections is not None:
                if self._keypoints_awaited_since is None:
                    self._keypoints_awaited_since = stamp_ns
                if stamp_ns - self._keypoints_awaited_since < KEYPOINT_START_WAIT_S * 1e9:
                    return self._result(stamp_ns, obs, t_start, timings)
            if budget_s is not None:  # live: a track starts from keypoints, never from a
                self._fall_back("no keypoints to start a track", "none starts")  # silhouette start-up
                return self._result(stamp_ns, obs, t_start, timings)
        if self.state.looking:
            t0 = time.perf_counter()
            started = self._start(masks, obs, stamp_ns, exclude)
            timings["hull"] = time.perf_counter() - t0
            if not started:
                self.state = TrackerState.SEARCHING
                return self._result(stamp_ns, obs, t_start, timings)
        if self.state == TrackerState.INITIALISING:
            return self._initialise(masks, obs, stamp_ns, t_start, timings)
        if self.keypoint_first is not None:
            return self._track_keypoints(detections, obs, stamp_ns, t_start, timings, budget_s)
        return self._track(detections, obs, stamp_ns, t_start, timings)

    # ------------------------------------------------------------------ keypoint-first

    def _start_from_keypoints(self, detections: Detections | None,
                              exclude: np.ndarray | None) -> FitResult | None:
        """A track started on the body fitted to the keypoints alone (:mod:`.keypoint_fit`),
        or None (no keypoints, no hips, fewer than ``keypoints.min_start_keypoints`` fitted,
        or a person another tracker follows)."""
        if detections is None or not len(detections):
            return None
        kf = self.keypoint_first
        assert kf is not None  # called for a keypoint-first method only
        self._measure_shape(detections, ())
        fit = kf.fitter.fit(detections, self.fitness.rest(self.shape))
        if fit is None or len(fit.labels) < self.params.keypoints.min_start_keypoints:
            return None
        pelvis = fit.params[self.skel.translation_dofs]
        if exclude is not None and len(exclude) and np.min(np.linalg.norm(
                (np.asarray(exclude) - pelvis)[:, [0, 2]], axis=1)) < SAME_PERSON_RADIUS:
            return None
        region = self.params.startup.track_region
        if region and not (region[0] <= pelvis[0] <= region[2]
                           and region[1] <= pelvis[2] <= region[3]):
            return None
        self.estimate = fit.params.copy()
        self._previous_estimate = None
        self.particles = np.repeat(fit.params[None], self.schedule.n_particles, axis=0)
        self._bad_frames = 0
        self.research.reset()
        self.state = TrackerState.TRACKING
        log.info("track started from %d keypoints at (%.2f, %.2f) m", len(fit.labels),
                 pelvis[0], pelvis[2])
        return fit

    def _track_keypoints(self, detections: Detections | None, obs: Observation, stamp_ns: int,
                         t_start: float, timings: dict,
                         budget_s: float | None = None) -> TrackResult:
        """One keypoint-first frame (:mod:`.keypoint_first`): fit, check, the filter on what
        stays uncertain. Without keypoints, the silhouette filter; live (with a budget), the
        prediction (:meth:`_coast`)."""
        kf = self.keypoint_first
        assert kf is not None  # called for a keypoint-first method only
        if detections is None or not len(kf.fitter.targets(detections)[0]):
            if budget_s is not None:
                return self._coast(obs, stamp_ns, t_start, timings)
            self._fall_back("no keypoints in the frame set")
            return self._track(None, obs, stamp_ns, t_start, timings)
        self._coasting_since = None
        t0 = time.perf_counter()
        reference = self._predict()
        periods = min(self._elapsed[1], MAX_ELAPSED_PERIODS)
        rest = self.fitness.rest(self.shape)
        fit, dropped = kf.fit(detections, rest, obs, reference, periods)
        timings["fit"] = time.perf_counter() - t0
        if self._measure_shape(detections, dropped):
            rest = self.fitness.rest(self.shape)
        if self.fallback_reason:
            log.info("keypoints again: keypoint-first tracking")
            self.fallback_reason = ""
        t0 = time.perf_counter()
        uncertain = kf.uncertain_blocks(fit, detections)
        evaluations = None
        if budget_s is not None:
            left = budget_s - (time.perf_counter() - t_start)
            evaluations = max(left, 0.0) / self._seconds_per_evaluation
        n = kf.layer_particles(uncertain, evaluations)
        schedule = kf.frame_filter(uncertain, periods, n) if n else None
        res = None
        if schedule is None:
            if not uncertain or self.particles is None:
                self.particles = np.repeat(fit.params[None], self.schedule.n_particles, axis=0)
            estimate = fit.params.copy()
        else:
            particles = kf.frame_particles(fit.params, self.particles, uncertain, periods,
                                           self.rng, n)
            particles = kf.first_diffusion(particles, uncertain, periods, self.rng)
            weight = layer_weight_fn(self.fitness, self.model, schedule,
                                     kf.layer_vertices(schedule), obs, rest,
                                     kf.terms(schedule, fit, detections, rest))
            try:
                res = lpf_run(particles, schedule.filter, weight, self.rng)
            except ValueError as err:
                log.warning("frame %d: filter failed (%s); keeping the keypoint fit", stamp_ns,
                            err)
            if res is not None:
                self.particles = res.particles
                estimate = res.estimate.copy()
            else:
                estimate = fit.params.copy()
        timings["filter"] = time.perf_counter() - t0
        if self.fitness.times.evaluations:
            spent = self.fitness.times.weighting_seconds() / self.fitness.times.evaluations
            self._seconds_per_evaluation = 0.8 * self._seconds_per_evaluation + 0.2 * spent
        self._previous_estimate = self.estimate
        self.estimate = estimate
        spread = (joint_spread(self.model, res.weighted_particles, res.weights, rest.joints)
                  if res is not None else self._fit_spread(fit))
        fit_cost = self._fit_cost(obs)
        self._check_loss(fit_cost, stamp_ns)
        self._last_spread = spread
        self.last_keypoints = (tuple(fit.labels), tuple(dropped), tuple(uncertain))
        return self._result(stamp_ns, obs, t_start, timings, fit_cost,
                            res.layers if res is not None else (),
                            self._keypoint_assigned(fit, detections), spread)

    def _coast(self, obs: Observation, stamp_ns: int, t_start: float,
               timings: dict) -> TrackResult:
        """A live keypoint-first track without keypoints (the keypoint stage late, absent or
        crashed): the pose goes on from its prediction, the velocity step once and then held,
        and every joint's spread grows by :data:`COAST_SPREAD_M_PER_S` per second from the
        last keypoint frame's, so its confidence falls; no silhouette filter runs (its seconds
        per frame set would stall a live room). Said once; the next frame set with keypoints
        fits them again. Design choice where the thesis has no keypoints: the loss check is
        left to the frame sets with keypoints (a stale pose is marked by its confidence)."""
        if self._coasting_since is None:
            self._coasting_since = stamp_ns
        self._fall_back("no keypoints (live)", "the pose goes on from its prediction, its "
                        "confidence falling,")
        predicted = self._predict()
        if predicted is not None:
            self._previous_estimate = self.estimate = predicted  # the velocity step taken once
        seconds = max(stamp_ns - self._coasting_since, 0) * 1e-9
        base = (self._last_spread if self._last_spread is not None
                else np.full(self.skel.n_joints, UNSEEN_SPREAD))
        period = self.frame_period.period_ns or 0.0
        spread = base + COAST_SPREAD_M_PER_S * (seconds + period * 1e-9)
        return self._result(stamp_ns, obs, t_start, timings, self._fit_cost(obs), spread=spread)

    def _measure_shape(self, detections: Detections | None, dropped) -> bool:
        """Measure the keypoints of a new track's first ``keypoints.shape_frames`` frame sets
        (:mod:`.keypoint_anthropometry`) and solve the shape again whenever their count
        doubles; True when the shape changed."""
        ks = self.keypoint_shape
        limit = self.params.keypoints.shape_frames
        if ks is None or len(ks) >= limit or detections is None or not len(detections):
            return False
        if dropped:
            keep = [i for i, lab in enumerate(detections.labels) if lab not in dropped]
            detections = Detections(detections.detector, tuple(detections.labels[i] for i in keep),
                                    detections.positions[keep], detections.scores[keep])
        ks.add(detections)
        n = len(ks)
        if n & (n - 1) and n != limit:  # solved at 1, 2, 4, 8, ... and at the limit
            return False
        shape = ks.shape()
        if shape is None:
            return False
        self.shape = shape
        return True

    def _fall_back(self, reason: str, doing: str = "tracking on the silhouettes alone") -> None:
        """Note (once per cause, in the log and ``fallback_reason``) that a frame set is not
        tracked on keypoints, and what it does instead."""
        if reason != self.fallback_reason:
            log.warning("%s: %s until keypoints come back", reason, doing)
        self.fallback_reason = reason

    def _keypoint_assigned(self, fit: FitResult, detections: Detections) -> Assigned:
        """The fitted keypoints as the tracker's per-joint detections (confidence, diagnostics)."""
        names = list(self.model.joint_names)
        joints = np.full((len(names), 3), np.nan)
        scores = np.zeros(len(names))
        effectors = np.full((len(EFFECTOR_LABELS), 3), np.nan)
        for label in fit.labels:
            pos = detections.position(label)
            score = max(float(s) for lab, s in zip(detections.labels, detections.scores)
                        if lab == label)
            joint = MODEL_JOINT.get(label)
            if joint in names:
                joints[names.index(joint)], scores[names.index(joint)] = pos, score
            if label in EFFECTOR_LABELS:
                effectors[EFFECTOR_LABELS.index(label)] = pos
        return Assigned(detections.positions, effectors, joints, scores)

    def _fit_spread(self, fit: FitResult) -> np.ndarray:
        """Per joint, the RMS residual (m) of the fitted keypoints of its body block: how far
        the keypoints and the body disagree, in place of the particles' spread where no filter
        ran. A joint whose block has no keypoint (a leg out of view) is held at its prediction
        and gets :data:`UNSEEN_SPREAD`, a low confidence."""
        resid = dict(zip(fit.labels, fit.residuals))
        out = np.full(self.skel.n_joints, UNSEEN_SPREAD)
        for j, group in enumerate(self._joint_blocks):
            own = [resid[k] for k in BLOCK_KEYPOINTS.get(group, ()) if k in resid]
            if own:
                out[j] = float(np.sqrt(np.mean(np.square(own))))
        return out

    def _check_loss(self, fit_cost: float, stamp_ns: int) -> None:
        lost = self.params.lost
        if not np.isfinite(fit_cost) or fit_cost > lost.cost:
            self._bad_frames += 1
        else:
            self._bad_frames = 0
        if self._bad_frames >= lost.frames:
            log.info("frame %d: fit cost %.2f above %.2f for %d frames: track lost", stamp_ns,
                     fit_cost, lost.cost, self._bad_frames)
            self.state = TrackerState.LOST
            self._bad_frames = 0

    def _initialise(self, masks, obs: Observation, stamp_ns: int, t_start: float,
                    timings: dict) -> TrackResult:
        """One start-up frame (sec. 2.3)."""
        t0 = time.perf_counter()
        startup = self._startup
        assert startup is not None  # set by _start, which makes the state initialising
        if startup.estimator.frames_done > 0:
            startup.follow(obs, self.finder, self.skel.translation_dofs)
        diags = startup.estimator.step(self._shape_obs(masks, obs, stamp_ns))
        layers = diags[0].layers if diags else ()
        if startup.estimator.done:
            self._finish_start()
        else:
            self.estimate = startup.estimator.best().estimate[:self.skel.n_dofs].copy()
        timings["init"] = time.perf_counter() - t0
        return self._result(stamp_ns, obs, t_start, timings, self._fit_cost(obs), layers)

    def _track(self, detections: Detections | None, obs: Observation, stamp_ns: int, t_start: float,
               timings: dict) -> TrackResult:
        """One tracked frame: prediction, proposals, detections, the layered filter, the
        fresh-search policy and the loss check."""
        t0 = time.perf_counter()
        extremities = None
        try:
            reference = self._predict()
            periods = min(self._elapsed[1], MAX_ELAPSED_PERIODS)
            self._diffuse_elapsed(periods)
            if PROPOSAL_FRACTION > 0.0 and reference is not None:  # None iff no estimate
                timings["proposals"] = self._propose(obs, reference)
            if self.driven is not None and detections is not None and reference is not None:
                t1 = time.perf_counter()
                extremities = self.driven.detect(self.fitness, self.fitness.rest(self.shape),
                                                 detections, reference, self.particles,
                                                 self.rng)
                timings["detection"] = time.perf_counter() - t1
            assert self.particles is not None  # a tracked body has particles
            res = lpf_run(self.particles, self._filter_for(periods),
                          self.weight_fn(obs, self.shape, extremities), self.rng)
            if self.driven is not None:
                self.driven.learn(res, extremities, self.fitness.rest(self.shape))
        except ValueError as err:
            log.warning("frame %d: filter failed (%s); restarting from the visual hull",
                        stamp_ns, err)
            self.state = TrackerState.LOST
            self.particles = None
            return self._result(stamp_ns, obs, t_start, timings)
        spread = joint_spread(self.model, res.weighted_particles, res.weights,
                              self.fitness.rest(self.shape).joints)
        timings["filter"] = time.perf_counter() - t0
        self.particles = res.particles
        self._previous_estimate = self.estimate
        self.estimate = res.estimate.copy()
        self._search_if_due(obs, stamp_ns, timings)
        fit_cost = self._fit_cost(obs)
        self._check_loss(fit_cost, stamp_ns)
        return self._result(stamp_ns, obs, t_start, timings, fit_cost, res.layers, extremities,
                            spread)

    # ------------------------------------------------------------------ time

    def _note_stamp(self, stamp_ns: int) -> None:
        """Count the frame periods since the last processed frame set (module docstring)."""
        self.frame_period.add(stamp_ns)
        before = now = 1
        if self._stamps:
            now = self.frame_period.periods(stamp_ns - self._stamps[-1])
        if len(self._stamps) == 2:
            before = self.frame_period.periods(self._stamps[1] - self._stamps[0])
        self._elapsed = (before, now)
        self._stamps = (self._stamps + (stamp_ns,))[-2:]

    def _filter_for(self, periods: int) -> LayeredFilter:
        """The schedule's filter with every layer's kernel std times ``periods`` (the final
        layer's inter-frame kernel, which diffuses for the next frame set, unchanged)."""
        lpf = self.schedule.filter
        if periods <= 1:
            return lpf
        scaled = self._scaled_filters.get(periods)
        if scaled is None:
            layers = tuple(dataclasses.replace(layer, std=periods * lpf.stds[k])
                           for k, layer in enumerate(lpf.layers))
            scaled = self._scaled_filters[periods] = dataclasses.replace(lpf, layers=layers)
        return scaled

    def _diffuse_elapsed(self, periods: int) -> None:
        """After ``periods`` > 1 frame periods, the rest of the inter-frame diffusion of the
        blocks the last frame's inter-frame kernel diffused: std ``sigma * sqrt(periods^2 -
        1)`` on top of its ``sigma``, so that their std is ``periods * sigma``."""
        if periods <= 1 or self.particles is None:
            return
        lpf = self.schedule.filter
        std = lpf.stds[-1] * np.sqrt(periods * periods - 1.0)
        self.particles = lpf.final.kernel(self.particles, std, self.rng)

    # ------------------------------------------------------------------ steps

    def _propose(self, obs: Observation, reference: np.ndarray) -> float:
        """Silhouette-driven arm proposals for part of the particles; returns the seconds of
        their own search (the re-ranking's skinning and XOR count under those stages)."""
        t1 = time.perf_counter()
        spent = self.fitness.times.weighting_seconds()
        rest = self.fitness.rest(self.shape)
        assert self.particles is not None  # called while tracking
        # scored where the body is predicted to be (pelvis moved by its velocity), not where
        # the last frame left it: a runner's hips are 12 cm further on
        self.proposer.apply(self.particles, reference, rest, obs, self.fitness.faces,
                            PROPOSAL_FRACTION, self.rng,
                            cost_fn=lambda x: self.fitness.costs(x, obs, rest))
        return time.perf_counter() - t1 - (self.fitness.times.weighting_seconds() - spent)

    def _search_if_due(self, obs: Observation, stamp_ns: int, timings: dict) -> None:
        """Ask the fresh-search policy (:mod:`.research`) and run the search it asks for."""
        assert self.estimate is not None and self.particles is not None  # after a filter run
        pelvis = self.estimate[self.skel.translation_dofs][[0, 2]]
        yaw = float(self.estimate[self.skel.dof_index("root_yaw")])
        due = self.research.after_frame(pelvis, yaw)
        if due is None:
            return
        t1 = time.perf_counter()
        if due.reason == "backwards":
            log.info("stamp %d ns: the body faces more than %g degrees away from its travel: "
                     "fresh search", stamp_ns, self.params.research.facing_limit)
        elif due.reason == "travel":
            log.info("stamp %d ns: the body travels: fresh search with its travel heading",
                     stamp_ns)
        found = fresh_search(self.params, self.fitness, self.finder, self.rng, self.room,
                             self.shape, self.start_proposer, obs, self.estimate,
                             self._previous_estimate, len(self.particles), stamp_ns,
                             heading=due.heading)
        if found is not None:
            self.estimate, self.particles, self._previous_estimate = found
        self.research.searched()
        timings["research"] = time.perf_counter() - t1

    def _person_absent(self) -> None:
        self._absent_frames += 1
        self._keypoints_awaited_since = None
        forget = self._absent_frames >= self.params.lost.forget_shape_frames
        if self.state != TrackerState.SEARCHING or forget:
            self.reset(forget_shape=forget)

    def _shape_obs(self, masks, obs: Observation, stamp_ns: int) -> Observation:
        """The start-up's observation (at ``startup.working_width``)."""
        if self.shape_fitness is self.fitness:
            return obs
        return self.shape_fitness.observe(masks, stamp_ns)

    def _start(self, masks, obs: Observation, stamp_ns: int,
               exclude: np.ndarray | None = None) -> bool:
        """Visual hull and Powell fit; True when a person was found and the start-up began."""
        near = self.estimate[self.skel.translation_dofs] if self.estimate is not None else None
        hull = self.finder.person_to_start(obs, near, exclude)
        if hull is None:
            return False
        shape_obs = self._shape_obs(masks, obs, stamp_ns)
        self._startup = StartUp(self.params, self.shape_fitness, self.rng, self.room,
                                self.shape, self.start_proposer, shape_obs, hull)
        self.estimate = self._startup.first_estimate(self.shape_fitness, shape_obs, self.shape)
        self._previous_estimate = None
        self.state = TrackerState.INITIALISING
        return True

    def _finish_start(self) -> None:
        startup = self._startup
        assert startup is not None  # called while initialising
        if self.shape is None:
            self.shape = startup.estimator.shape()
        (self.estimate, self.particles, self._previous_estimate,
         pelvis_track) = startup.finish(self.schedule.n_particles, self.rng, self.skel)
        self._startup = None
        self._bad_frames = 0
        self.research.reset(pelvis_track)
        self.state = TrackerState.TRACKING

    def _predict(self) -> np.ndarray | None:
        """Apply the velocity prediction to the particles' pelvis, scaled to the time since
        the last processed frame set; returns the predicted pose."""
        if self.estimate is None:
            return None
        predicted = self.estimate.copy()
        gain = VELOCITY_GAIN
        if self._previous_estimate is None or gain <= 0.0:
            return predicted
        dofs = self.skel.translation_dofs
        assert self.particles is not None  # a track with two estimates has particles
        step = self.estimate - self._previous_estimate
        before, now = self._elapsed
        now = min(now, MAX_ELAPSED_PERIODS)
        if now != before:  # the last step spans ``before`` periods, this one ``now``
            step = step * (now / before)
        self.particles[:, dofs] += gain * step[dofs]
        predicted[dofs] += gain * step[dofs]
        return predicted

    def _fit_cost(self, obs: Observation) -> float:
        return fit_cost(self.fitness, self.estimate, self._current_shape(), obs)

    def _result(self, stamp_ns: int, obs: Observation, t_start: float, timings: dict,
                fit_cost: float = float("nan"), layers: tuple = (),
                extremities: Assigned | None = None,
                spread: np.ndarray | None = None) -> TrackResult:
        extra = self.shape_fitness.times if self.shape_fitness is not self.fitness else None
        timings = stage_timings(timings, t_start, self.fitness.times, extra)
        params = joints = transforms = None
        shape = self._current_shape()
        if self.state.follows_person and self.estimate is not None:
            params = self.estimate.copy()
            transforms = joint_transforms(self.model, params, self.fitness.rest(shape).joints)
            joints = transforms[:, :3, 3].copy()
        else:
            spread = None
        return TrackResult(stamp_ns=int(stamp_ns), state=self.state, params=params,
                           joints=joints, joint_names=tuple(self.model.joint_names), shape=shape,
                           fit_cost=fit_cost, views=tuple(int(v) for v in obs.views),
                           dropped=tuple(obs.dropped), layers=tuple(layers), timings=timings,
                           extremities=extremities, transforms=transforms, joint_spread=spread)
