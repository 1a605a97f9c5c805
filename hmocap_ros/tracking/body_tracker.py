"""Markerless body tracker: foreground masks of a calibrated rig in, a 3D body pose out.

One :class:`BodyTracker` per rig; ``update(masks, stamp_ns)`` per synchronised frame set. No
rclpy: the ``body_tracker`` node, the bag evaluator (``hmocap eval mocap``) and the tests call
the same method. States:

``searching``
    no person: too little foreground in too few views, or no visual hull. No pose.
``initialising``
    a person appeared: visual hull, Powell fit and the layered anthropometry estimation of
    thesis sec. 2.3 (:mod:`.anthropometry_estimation`) over the first ``shape_frames`` frames
    (or a pose-only start when the shape is given or already known). A pose is reported.
``tracking``
    layered particle filtering per frame with the chosen schedule (:mod:`.body_layers`: APF,
    HPF, or HPF with approximate partitioning of observations, sec. 2.4) and the silhouette
    XOR weighting (:mod:`.body_fitness`, eq. 2.8 / 2.15). ``dd-hpf`` (sec. 2.5) also takes
    per-view detector maps (``update(masks, stamp, detector_maps)``): hands and head are
    located in 3D (:mod:`.extremity_detection`), IK particles put the arms where the hands
    are (:mod:`.ik_proposals`) and the final layer adds the detection cost of eq. 2.20-2.21.
``lost``
    the fit cost of the estimate stayed above ``lost_cost`` for ``lost_frames`` frames; the
    next frame starts again from the visual hull (keeping the estimated shape).

Robustness: a mask that is None or of the wrong size drops that view for the frame (the cost
sums over the others); an empty frame set resets to ``searching``; weighting errors (no
finite cost) count as a collapsed fit. The estimated shape is kept while the person is away
for fewer than ``forget_shape_frames`` frames, then estimated anew for the next person.

Inter-frame prediction: the thesis' kernel is a zero-mean Gaussian around the last estimate.
Here, before the filter runs, the particles of ``velocity_dofs`` (default the pelvis position)
are shifted by ``velocity_gain`` times the estimate's last frame-to-frame change: a
constant-velocity prior (gain 1.0; 0.8, a damped one, until stop 12). A walking or running
person moves 5-12 cm per frame, several times the Gaussian's std; limbs reverse too quickly
for it to help them (see docs/tracking.md for the comparisons on the tuning clips).

Mesh: the particles are rendered with ``mesh``: the 2,400-triangle ``tracking`` body by
default, or ``tracking_coarse``, the same joints, skinning and DoFs on 1,000 triangles. At
the working resolution a person covers a few hundred pixels per view, so most triangles of
the finer mesh are smaller than a pixel; the coarse one takes about half the time per frame
and cost 2.8 mm on the tuning clips (docs/tracking.md, stop 14), so it is an option, not the
default.
"""
from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np

from hmocap_ros.body.anthropometry import BodyShape
from hmocap_ros.tracking.anthropometry_estimation import AnthropometryEstimator, EstimationParams
from hmocap_ros.render.silhouette import observed_counts, render_silhouettes
from hmocap_ros.tracking.body_fitness import Observation, SilhouetteFitness, serial_below
from hmocap_ros.tracking.body_layers import METHODS, BodySchedule, make_schedule
from hmocap_ros.tracking.extremity_detection import (Extremities, ExtremityDetector,
                                                     ExtremityParams, detection_cost)
from hmocap_ros.tracking.ik_proposals import IKProposer
from hmocap_ros.lpf.layered_filter import LayerDiagnostics, lpf_run
from hmocap_ros.tracking.limb_proposals import LimbProposer
from hmocap_ros.tracking.body_layers import BODY_BLOCKS
from hmocap_ros.tracking.observation_boxes import (LAYER_ANCHORS, chain_lengths, faces_of_blocks,
                                                   layer_boxes,
                                                   layer_vertex_indices, part_boxes_3d,
                                                   reach_box)
from hmocap_ros.tracking.visual_hull import room_bounds, visual_hull

__all__ = ["STATES", "BodyTracker", "TrackResult", "TrackerParams"]

log = logging.getLogger(__name__)

STATES = ("searching", "initialising", "tracking", "lost")
#: Shipped meshes a tracker can render its particles with (``TrackerParams.mesh``).
TRACKER_MESHES = ("tracking_coarse", "tracking")


#: How far (m, on the floor) the tracked person's hull (start-up) or a fresh search's pose
#: (``research_every``) may lie from where the person was; farther is somebody else.
SAME_PERSON_RADIUS = 0.5
#: 3x3 structuring element: another person's rendered body grows by one working pixel
_RING = np.ones((3, 3), np.uint8)


def _param(default, description: str):
    return dataclasses.field(default=default, metadata={"description": description,
                                                        "read_only": False})


@dataclass(frozen=True)
class TrackerParams:
    """Tunables of :class:`BodyTracker` (each field's metadata has a ``description`` for the
    ROS node's parameter declarations). Defaults: 4 cameras at 640x480, 25 fps."""

    method: str = _param("dd-hpf", "Layered filter: 'apf' (annealing, 14 x 250), 'hpf' "
                                    "(hierarchical, 7 x 500 in one sweep, 14 x 250 in two, "
                                    "hpf_sweeps), 'hpf-apo' (hierarchical with approximate "
                                    "partitioning of observations, 8 x 438 in one sweep, "
                                    "15 x 234 in two) or 'dd-hpf' (hpf-apo driven by hand "
                                    "detections: IK particles and the refinement layer, sec. "
                                    "2.5; needs detector maps).")
    n_particles: int = _param(0, "Particles per layer; 0 uses the method's default (about 3500 "
                                 "weight evaluations per frame).")
    n_layers: int = _param(0, "Layers of the APF; 0 uses the default (14). The hierarchical "
                              "methods have one layer per body part.")
    working_scale: float = _param(0.25, "Image scale at which silhouettes are compared "
                                        "(0.25: 640x480 -> 160x120).")
    mesh: str = _param("tracking", "Body mesh the particles are rendered with (same joints "
                                   "and DoFs): 'tracking' (2,400 triangles) or "
                                   "'tracking_coarse' (1,000, about one per silhouette pixel "
                                   "at 160x120: about twice as fast per frame, and 2.8 mm "
                                   "worse on the tuning clips).")
    sigma_scale: float = _param(1.0, "Factor on the per-DoF inter-frame motion std sigma0 "
                                     "(motion statistics, see body_layers).")
    survival_rate: float = _param(0.3, "Particle survival rate that sets each layer's annealing "
                                       "exponent beta (eq. 2.9); 0.3 (0.5 until stop 18) "
                                       "gained 2.1 mm on 90 tuning runs.")
    apf_alpha: float = _param(0.7, "APF variance decay rate per layer (eq. 2.10).")
    refine_nu: float = _param(0.25, "HPF decay of the re-diffusion of already filtered blocks "
                                    "(alg. 3); 0 disables it.")
    jump_fraction: float = _param(0.1, "Fraction of the particles that each kernel diffuses "
                                       "with jump_scale times the std (a scale mixture that "
                                       "lets joints leave a wrong mode of the silhouette cost); "
                                       "0: plain Gaussian.")
    jump_scale: float = _param(4.0, "Std factor of the wide component of the kernel.")
    reseed_fraction: float = _param(0.1, "Fraction of the particles whose limb DoFs being "
                                          "diffused are drawn uniformly within the joint "
                                          "limits (lets a lost limb be found again).")
    velocity_gain: float = _param(1.0, "Fraction of the estimate's last frame-to-frame "
                                       "change of velocity_dofs added to the particles before "
                                       "filtering (1: constant-velocity prediction, below 1 "
                                       "damped; 0: zero-velocity Gaussian as in the thesis).")
    velocity_dofs: str = _param("root_position", "DoFs the velocity prediction moves: "
                                                 "'root_position' (pelvis), 'root' (pelvis "
                                                 "and its rotation) or 'all'.")
    hpf_sweeps: int = _param(2, "Hierarchical methods: passes over the kinematic tree's "
                                "blocks per frame. 2 (since stop 27, tuning rule F: -7.7 mm "
                                "on 24 runner runs) weighs every block again after the others "
                                "were filtered, at half the kernel std, with the particles "
                                "per layer cut so the evaluations per frame stay the same "
                                "(hpf-apo 15 x 234); 1: the thesis' one layer per block.")
    arm_chain: bool = _param(True, "Hierarchical methods: each shoulder layer samples its "
                                    "elbow too (the elbow layer then refines it).")
    box_reach: float = _param(1.05, "Observation boxes of the limb layers: half-size as a "
                                    "multiple of the length of the chain the layer moves, "
                                    "around the joint it rotates (eq. 2.15); 0: boxes around "
                                    "the particles' parts instead.")
    box_spread: float = _param(2.0, "Observation boxes around parts (torso layer): standard "
                                    "deviations of the particles' part positions added "
                                    "around the mean part.")
    box_margin: float = _param(0.05, "Observation boxes: margin in metres around the parts.")
    proposal_fraction: float = _param(0.35, "Fraction of the particles that, per limb and "
                                           "frame, take their limb DoFs from silhouette-driven "
                                           "proposals (limb_proposals); 0: Gaussian only.")
    proposal_limbs: str = _param("arms", "Limbs that get proposals: 'arms', 'legs' or 'all'.")
    refine_kappa: float = _param(2.0, "dd-hpf: weight kappa (per metre) of the detection "
                                      "cost of eq. 2.20 in the refinement layer (eq. 2.21).")
    dd_feet: bool = _param(False, "dd-hpf: also locate the feet (geodesic extrema of the visual "
                                  "hull) and draw IK particles for the legs (off: it cost 10-20 "
                                  "mm on the tuning clips, see docs/tracking.md); False: hands "
                                  "only, as the thesis' skin detector.")
    dd_reacquire: bool = _param(True, "dd-hpf: a hand that eq. 2.19 leaves unassigned (the arm "
                                      "lost by more than 35 cm) takes a skin cluster within "
                                      "arm's reach of its shoulder, on its own side, so that IK "
                                      "particles can draw a lost arm back (tuning clips, two "
                                      "tracker seeds: 84.0 against 85.5 mm without).")
    render_filtered_parts: bool = _param(False, "Hierarchical methods: each layer renders only "
                                              "the body parts filtered so far (sec. 2.4); "
                                              "False renders the whole body at its predicted "
                                              "pose.")
    estimator: str = _param("mean", "Pose estimate: 'mean' (weighted mean of the final layer) "
                                    "or 'max' (its best particle).")
    min_views: int = _param(2, "Views with enough foreground needed to start (and to carve "
                               "the visual hull).")
    min_full_views: int = _param(3, "Views that must see the whole visual hull (inside the image) "
                                    "before a track starts: a person half out of view gives a "
                                    "wrong height and a wrong first pose.")
    min_foreground: int = _param(40, "Foreground pixels at the working resolution for a view "
                                     "to count as seeing a person.")
    track_region: list[float] = dataclasses.field(default_factory=list, metadata={
        "read_only": False,
        "description": "Floor box [x_min, z_min, x_max, z_max] (m, room frame) where a track may "
                       "start: only a person whose visual hull centroid stands in it is "
                       "followed (e.g. the interaction area in front of a display, so that "
                       "people passing by are ignored); once started, the track follows the "
                       "person anywhere. Empty: the whole room, the best-seen person."})
    voxel_size: float = _param(0.03, "Voxel edge (m) of the fine visual hull grid.")
    min_hull_height: float = _param(0.9, "Smallest hull top (m) accepted as a person.")
    hull_max_misses: int = _param(0, "Views in which a hull voxel may project onto background "
                                     "(tolerates holes in the foreground).")
    hull_bridge_misses: int = _param(1, "Views more than hull_max_misses in which a voxel may "
                                        "project onto background and still join the hull's "
                                        "parts into one person (the hull keeps only the "
                                        "hull_max_misses voxels): a band of the body lost in "
                                        "one view, such as a shirt the colour of the wall, "
                                        "then does not cut the person in two. 1 (0 until stop "
                                        "22) gained 5.8 mm on 24 tuning runs and 71 mm on a "
                                        "camouflaged runner.")
    ignore_other_people: bool = _param(False, "With several people followed (max_people > "
                                              "1): each tracker's silhouette XOR leaves out "
                                              "the foreground under the other trackers' "
                                              "bodies (their latest estimates rendered in "
                                              "every view, one working pixel wider), so a "
                                              "bystander next to or behind "
                                              "the subject neither pulls nor pushes its "
                                              "limbs. No effect on a single tracker.")
    start_height_margin: float = _param(0.03, "During the start-up's shape frames: when the "
                                              "followed visual hull's top stands more than "
                                              "this many metres above the top of a start-up "
                                              "hypothesis' body (both read over its head, "
                                              "start_height_column), its global scale and "
                                              "pelvis height grow by their ratio (the "
                                              "segmentation can lose the head in the frame a "
                                              "track starts on); 0: off. 0.03 since stop 25 "
                                              "(tuning rules B and D).")
    start_height_column: float = _param(0.15, "With start_height_margin > 0: the radius "
                                              "(m, on the floor) of the column around each "
                                              "start-up hypothesis' head top in which the "
                                              "hull's top and the body's are read, so a hand "
                                              "raised beside the head tops neither (stop "
                                              "24's held-out laugh grew by 10 % on its whole "
                                              "hull); 0: the hull's and the body's highest "
                                              "points (stops 23-24).")
    start_head_fraction: float = _param(0.0, "> 0 (with start_height_column > 0): the "
                                             "start-up reads the head's top, not the hull's "
                                             "highest voxel, for the first frame's body "
                                             "scale (over the trunk's axis) and for the "
                                             "growth (over each hypothesis' head): from the "
                                             "column's top down, the first voxel layer "
                                             "holding this fraction of the voxels of its "
                                             "fullest layer within 0.3 m of the top, so a "
                                             "hand held over or beside the head is passed "
                                             "over (stop 26); 0: the hull's top, the "
                                             "default (tuning rule E: it mends the "
                                             "arm_up bags, but the scale falls on most "
                                             "others).")
    estimate_shape: bool = _param(True, "Estimate the anthropometry at start (sec. 2.3); "
                                        "False keeps the model's proportions, scaled to the "
                                        "visual hull.")
    shape_frames: int = _param(4, "Frames of layered filtering over shape and pose at start.")
    shape_particles: int = _param(250, "Particles per layer of the start-up filter.")
    shape_working_scale: float = _param(0.5, "Image scale of the start-up (anthropometry) "
                                             "weighting.")
    rejection_tau: float = _param(0.7, "Acceptance ratio tau of the rejection-sampling shape "
                                       "kernel (eq. 2.13).")
    rejection_trials: int = _param(8, "Trials of the rejection-sampling kernel per layer.")
    lost_cost: float = _param(0.6, "Mean per-view silhouette XOR / foreground, counted in a box "
                                   "around the estimated body (eq. 2.8 divided by the views), "
                                   "above which a frame counts as a failed fit.")
    lost_frames: int = _param(8, "Consecutive failed fits after which the track is lost and "
                                 "restarts from the visual hull.")
    research_every: int = _param(25, "While tracking, every this many frames a fresh start-up "
                                    "search (heading search with limb proposals and Powell "
                                    "from the visual hull, at the estimated shape) is weighed "
                                    "against the frame's estimate, and the filter is re-seeded "
                                    "from it when it fits better: a way out of a wrong pose the "
                                    "per-frame filter cannot leave (costs 1.5-2 s on that "
                                    "frame on 2 cores); 0: off.")
    backwards_frames: int = _param(5, "Frames over which the tracked pelvis' travel is "
                                      "measured: when it moved more than backwards_step per "
                                      "frame over them and the body faces away from the "
                                      "travel (by more than facing_limit, 90 degrees), a fresh "
                                      "search (as research_every) runs at once, so that a "
                                      "runner started back to front is put right within a "
                                      "few frames rather than at the next periodic search "
                                      "(the start-up's visual hull travel counts as the "
                                      "pelvis'); 0: off.")
    backwards_step: float = _param(0.05, "Mean pelvis travel per frame (m) above which "
                                         "backwards_frames checks the facing (0.05 m: 1.25 m/s "
                                         "at 25 frames/s).")
    facing_limit: float = _param(90.0, "Degrees between the body's facing direction (root yaw) "
                                       "and its travel (backwards_frames) above which the "
                                       "fresh search of backwards_frames runs: 90 catches a "
                                       "body tracked back to front; a smaller angle also a "
                                       "pelvis turned away from the way it runs, with the "
                                       "legs twisted to make up for it (people walk and run "
                                       "facing within about 10 degrees of their travel).")
    facing_cooldown: int = _param(0, "Frames after a fresh search during which the "
                                     "backwards_frames check does not run (a search that did "
                                     "not put the facing right is not repeated at once); 0: "
                                     "research_every (at least backwards_frames).")
    travel_research_every: int = _param(0, "While the tracked pelvis travels faster than "
                                           "backwards_step (backwards_frames > 0), a fresh "
                                           "search (as research_every, with the travel "
                                           "heading if travel_heading) runs every this many "
                                           "tracked frames after the last one: a runner's "
                                           "legs change fast and the per-frame filter loses "
                                           "them more often (about 3 s per search on 2 "
                                           "cores); 0: off.")
    travel_heading: bool = _param(True, "With backwards_frames > 0 (inert at 0): while the "
                                        "tracked pelvis travels faster than backwards_step, a "
                                        "fresh search also fits a pose facing the travel "
                                        "direction (people walk and run facing forward), and "
                                        "one such search runs as soon as the travel is first "
                                        "measured after a start (the start-up's hull travel "
                                        "counts), so a runner's start-up heading is checked on "
                                        "its second tracked frame.")
    forget_shape_frames: int = _param(50, "Frames without a person after which the estimated "
                                          "shape is forgotten.")

    def __post_init__(self):
        # a list from ROS or the command line; kept as a tuple so the params stay immutable
        object.__setattr__(self, "track_region", tuple(float(v) for v in self.track_region))
        checks = [
            (self.method in METHODS, f"method must be one of {METHODS}"),
            (self.n_particles >= 0 and self.n_layers >= 0, "n_particles, n_layers must be >= 0"),
            (self.hpf_sweeps >= 1, "hpf_sweeps must be >= 1"),
            (0.0 < self.working_scale <= 1.0, "working_scale must lie in (0, 1]"),
            (self.mesh in TRACKER_MESHES, f"mesh must be one of {TRACKER_MESHES}"),
            (0.0 < self.shape_working_scale <= 1.0, "shape_working_scale must lie in (0, 1]"),
            (self.sigma_scale > 0.0, "sigma_scale must be > 0"),
            (0.0 < self.survival_rate <= 1.0, "survival_rate must lie in (0, 1]"),
            (0.0 < self.apf_alpha <= 1.0, "apf_alpha must lie in (0, 1]"),
            (0.0 <= self.refine_nu < 1.0, "refine_nu must lie in [0, 1)"),
            (0.0 <= self.jump_fraction <= 1.0 and self.jump_scale >= 1.0,
             "need 0 <= jump_fraction <= 1 and jump_scale >= 1"),
            (0.0 <= self.reseed_fraction <= 1.0, "reseed_fraction must lie in [0, 1]"),
            (0.0 <= self.velocity_gain <= 1.0, "velocity_gain must lie in [0, 1]"),
            (self.velocity_dofs in ("root_position", "root", "all"),
             "velocity_dofs must be 'root_position', 'root' or 'all'"),
            (self.estimator in ("mean", "max"), "estimator must be 'mean' or 'max'"),
            (0.0 <= self.proposal_fraction <= 1.0, "proposal_fraction must lie in [0, 1]"),
            (self.proposal_limbs in ("arms", "legs", "all"),
             "proposal_limbs must be 'arms', 'legs' or 'all'"),
            (self.min_views >= 1, "min_views must be >= 1"),
            (self.start_height_margin >= 0.0, "start_height_margin must be >= 0"),
            (self.start_height_column >= 0.0, "start_height_column must be >= 0"),
            (0.0 <= self.start_head_fraction <= 1.0
             and (self.start_head_fraction == 0.0 or self.start_height_column > 0.0),
             "start_head_fraction must be in [0, 1] and needs start_height_column > 0"),
            (self.hull_max_misses >= 0 and self.hull_bridge_misses >= 0,
             "hull_max_misses and hull_bridge_misses must be >= 0"),
            (0.0 < self.rejection_tau <= 1.0, "rejection_tau must lie in (0, 1]"),
            (self.shape_frames >= 1 and self.shape_particles >= 2, "shape_frames >= 1, "
                                                                   "shape_particles >= 2"),
            (self.lost_frames >= 1, "lost_frames must be >= 1"),
            (self.research_every >= 0, "research_every must be >= 0 (0: off)"),
            (0.0 < self.facing_limit <= 180.0, "facing_limit must lie in (0, 180] degrees"),
            (self.facing_cooldown >= 0, "facing_cooldown must be >= 0 (0: research_every)"),
            (self.travel_research_every >= 0, "travel_research_every must be >= 0 (0: off)"),
            (self.backwards_frames >= 0 and self.backwards_step > 0.0,
             "need backwards_frames >= 0 (0: off) and backwards_step > 0"),
            (not self.track_region
             or (len(self.track_region) == 4 and np.isfinite(self.track_region).all()
                 and self.track_region[0] < self.track_region[2]
                 and self.track_region[1] < self.track_region[3]),
             "track_region must be empty or [x_min, z_min, x_max, z_max] with min < max"),
            (self.refine_kappa >= 0.0, "refine_kappa must be >= 0"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"TrackerParams: {message}")


@dataclass(frozen=True, eq=False)
class TrackResult:
    """What one ``update`` produced.

    state: one of :data:`STATES` after this frame.
    params: (D,) pose parameters (tracking DoF set) or None; joints: (J, 3) joint positions in
    metres in the room frame or None; joint_names: their names; shape: the body shape used.
    fit_cost: eq. 2.8 cost of the estimate divided by the number of views (NaN without pose).
    views: rig indices used; dropped: rig indices whose mask was missing or invalid.
    layers: per-layer diagnostics (ESS, beta, times) of the filter run, if one ran.
    timings: seconds per stage ("total", "observe", "hull", "init", "filter", "skinning",
    "projection", "xor", "detection") and "evaluations".
    extremities: dd-hpf's hand and head detections of this frame (None otherwise).
    """

    stamp_ns: int
    state: str
    params: np.ndarray | None = None
    joints: np.ndarray | None = None
    joint_names: tuple = ()
    shape: BodyShape | None = None
    fit_cost: float = float("nan")
    views: tuple = ()
    dropped: tuple = ()
    layers: tuple = ()
    timings: dict = field(default_factory=dict)
    extremities: Extremities | None = None

    @property
    def has_pose(self) -> bool:
        return self.joints is not None

    @property
    def ess(self) -> tuple:
        return tuple(d.ess for d in self.layers)


class BodyTracker:
    """Layered-filter body tracker for one rig (see the module docstring).

    model: ``load_body_model("tracking")`` (rendered with ``params.mesh``; another model, e.g.
    from ``read_body_model``, is rendered as it is). rig: the calibrated cameras (a Rig or list of
    PinholeCamera at the masks' resolution). params: :class:`TrackerParams`. rng: the only
    source of randomness (seed it for repeatable runs). shape: a known body shape (skips the
    anthropometry estimation).
    """

    def __init__(self, model, rig: Sequence, params: TrackerParams | None = None,
                 rng: np.random.Generator | None = None, shape: BodyShape | None = None):
        self.cameras = tuple(rig)
        if not self.cameras:
            raise ValueError("the rig has no cameras")
        self.params = params or TrackerParams()
        # a shipped tracking body is swapped for params.mesh (same joints and DoFs; a shape's
        # factors then scale that mesh's surface); any other model is rendered as it is
        if model.name in TRACKER_MESHES:
            model = model.with_mesh(self.params.mesh)
        self.model = model
        self.skel = model.skeleton
        self.rng = rng if rng is not None else np.random.default_rng()
        self.given_shape = shape
        p = self.params
        self.fitness = SilhouetteFitness(model, self.cameras, p.working_scale)
        self.shape_fitness = (self.fitness if p.shape_working_scale == p.working_scale else
                              SilhouetteFitness(model, self.cameras, p.shape_working_scale))
        self.room = room_bounds(self.cameras)
        self.schedule: BodySchedule = make_schedule(
            p.method, self.skel, n_particles=p.n_particles or None, n_layers=p.n_layers or None,
            sigma_scale=p.sigma_scale, survival_rate=p.survival_rate, apf_alpha=p.apf_alpha,
            refine_nu=p.refine_nu, jump_fraction=p.jump_fraction, jump_scale=p.jump_scale,
            reseed_fraction=p.reseed_fraction, arm_chain=p.arm_chain, room_lo=self.room[0],
            room_hi=self.room[1], sweeps=p.hpf_sweeps)
        self._layer_vertices = [layer_vertex_indices(model, blocks) if boxed else None
                                for blocks, boxed in zip(self.schedule.layer_blocks,
                                                         self.schedule.boxed)]
        # per weighting: the triangles it renders (None: the whole mesh)
        self._layer_faces = [None] * len(self.schedule.layer_blocks)
        if p.render_filtered_parts and p.method != "apf":
            for l, blocks in enumerate(self.schedule.layer_blocks):
                if blocks and l < len(self.schedule.layer_blocks) - 1:
                    upto = BODY_BLOCKS[:BODY_BLOCKS.index(blocks[0]) + 1]
                    self._layer_faces[l] = faces_of_blocks(model, upto)
        limbs = {"arms": ("l_arm", "r_arm"), "legs": ("l_leg", "r_leg"),
                 "all": ("l_arm", "r_arm", "l_leg", "r_leg")}[p.proposal_limbs]
        self.proposer = LimbProposer(model, limbs)
        self.start_proposer = LimbProposer(model, ("l_arm", "r_arm", "l_leg", "r_leg"))
        self.detector = self.ik = None
        if p.method == "dd-hpf":
            self.detector = ExtremityDetector(self.cameras, ExtremityParams(
                feet=p.dd_feet, reacquire=p.dd_reacquire))
            self.ik = IKProposer(model)
            names = list(model.joint_names)
            #: per side, (shoulder, elbow, wrist) joint indices: the arm's reach (dd_reacquire)
            self._arms = np.array([[names.index(f"{s}_{n}") for n in ("shoulder", "elbow", "wrist")]
                                   for s in "lr"])
        self.reset()

    # ------------------------------------------------------------------ state

    def reset(self, forget_shape: bool = True) -> None:
        """Back to ``searching``; optionally forget the estimated shape."""
        self.state = "searching"
        self._others: tuple = ()
        self.particles: np.ndarray | None = None
        self.estimate: np.ndarray | None = None
        self._previous_estimate: np.ndarray | None = None
        self._estimator: AnthropometryEstimator | None = None
        self._hull_centroid = np.zeros(3)
        self._hull_step = np.zeros(3)
        self._hull_track: list = []  # the hull centroid's (x, z) during the start-up
        self._bad_frames = 0
        self._absent_frames = 0
        self._tracked_frames = 0
        self._pelvis_track: list = []  # the estimate's pelvis (x, z) of the last frames
        self._research_cooldown = 0
        self._travel_checked = False  # travel_heading: the start-up heading checked once
        self._last_search = 0  # _tracked_frames at the last fresh search
        if self.ik is not None:
            self.ik.reset()
        if forget_shape:
            self.shape: BodyShape | None = self.given_shape

    @property
    def shape_known(self) -> bool:
        return self.shape is not None

    @property
    def position(self) -> np.ndarray | None:
        """Where the followed person's pelvis is (room, metres), or None when not following
        anybody (searching or lost)."""
        if self.state not in ("initialising", "tracking") or self.estimate is None:
            return None
        return self.estimate[self.skel.translation_dofs].copy()

    def _without_others(self, obs: Observation) -> Observation:
        """``obs`` with the foreground under the other people's bodies left out of the XOR
        (``ignore_other_people``; ``self._others`` is set per frame by :meth:`update`)."""
        if not self._others or obs.n_views == 0:
            return obs
        bodies = [b for b in (t.silhouettes(obs) for t in self._others) if b is not None]
        if not bodies:
            return obs
        # one pixel wider: the other tracker's fit is not exact, and its fringe would be
        # foreground left for this body to explain
        grown = [cv2.dilate(view, _RING) for view in np.bitwise_or.reduce(bodies)]
        return obs.without(np.stack(grown))

    def _shape_obs(self, masks, obs: Observation, stamp_ns: int) -> Observation:
        """The start-up's observation (at ``shape_working_scale``)."""
        if self.shape_fitness is self.fitness:
            return obs
        return self._without_others(self.shape_fitness.observe(masks, stamp_ns))

    def silhouettes(self, obs: Observation) -> np.ndarray | None:
        """The body of the latest estimate rendered in the views of ``obs`` at its working
        resolution ((M, h, w) uint8), or None when not following anybody."""
        if self.state not in ("initialising", "tracking") or self.estimate is None:
            return None
        verts, _ = self.fitness.pose(self.estimate[None], self._current_shape())
        uv = self.fitness.project(verts, obs)
        return render_silhouettes(uv[0], self.fitness.faces, obs.height, obs.width,
                                  front_only=self.fitness.front_only)

    def warm_up(self) -> float:
        """Compile every numba kernel of the weighting (serial and parallel variants) on a
        dummy frame; returns the seconds it took. A fresh install has no numba cache: without
        this, the first frames with a person would stall for seconds while they compile."""
        t0 = time.perf_counter()
        w = self.fitness.working[0]
        masks = [np.zeros((c.height, c.width), np.uint8) for c in self.fitness.working]
        obs = self.fitness.observe(masks)
        rest_params = self.model.rest_pose(None)[None]
        for n in (1, 128):  # serial and parallel paths
            params = np.repeat(rest_params, n, axis=0)
            self.fitness.costs(params, obs)
            verts, _ = self.fitness.pose(params)
            self.fitness.costs_from_verts(verts, obs, np.array([[0, 0, w.width, w.height]] * obs.n_views))
            self.fitness.costs_from_uv(self.fitness.project(verts, obs), obs)
        self.proposer.evidence(obs, rest_params[0], self.fitness.rest(None), self.fitness.faces)
        self.fitness.times.reset()
        return time.perf_counter() - t0

    # ------------------------------------------------------------------ weighting

    def weight_fn(self, obs: Observation, shape: BodyShape,
                  extremities: Extremities | None = None):
        """The schedule's weighting: eq. 2.8, or eq. 2.15 in the layer's observation boxes.

        extremities: dd-hpf's detections; with any hand (or foot) detected, the final layer
        becomes the refinement layer of eq. 2.21: cost + kappa * D(C_t, x), D of eq. 2.20.
        """
        rest = self.fitness.rest(shape)
        sched, p = self.schedule, self.params
        lengths = chain_lengths(self.model, rest)
        last = sched.n_weightings - 1
        refine = (extremities is not None and len(extremities.detections) > 0
                  and p.refine_kappa > 0 and self.ik is not None)

        def weight(particles: np.ndarray, layer: int) -> np.ndarray:
            verts, joints = self.fitness.pose(particles, rest)
            boxes = None
            if sched.boxed[layer]:
                block = sched.layer_blocks[layer][0]
                if block in LAYER_ANCHORS and p.box_reach > 0:
                    anchor = joints[:, self.model.joint_index(LAYER_ANCHORS[block][0])]
                    lo, hi = reach_box(anchor.mean(axis=0), lengths[block], p.box_reach,
                                       p.box_margin)
                else:
                    lo, hi = part_boxes_3d(verts, self._layer_vertices[layer], p.box_spread,
                                           p.box_margin)
                boxes = layer_boxes(lo, hi, obs.K, obs.R, obs.t, obs.D, obs.width, obs.height)
            cost = self.fitness.costs_from_verts(verts, obs, boxes, self._layer_faces[layer])
            if refine and layer == last:
                cost = cost + p.refine_kappa * detection_cost(
                    extremities.assigned, self.ik.end_effectors(particles, rest))
            return cost

        return weight

    # ------------------------------------------------------------------ update

    def update(self, masks: Sequence[np.ndarray | None], stamp_ns: int,
               detector_maps: Sequence[np.ndarray | None] | None = None,
               exclude: np.ndarray | None = None,
               others: Sequence["BodyTracker"] = ()) -> TrackResult:
        """Process one frame set: one foreground mask per rig camera (None where missing).

        detector_maps: per camera the extremity detector's probability map (uint8, 255 = 1,
        any resolution; ``segmentation.skin``) or None; used by ``dd-hpf`` only, which
        without them runs as ``hpf-apo``. exclude: (K, 3) room points where people followed
        by other trackers stand (:class:`~.people_tracker.PeopleTracker`): a start never
        takes a person within :data:`SAME_PERSON_RADIUS` of one of them. others: the
        trackers of the other people; with ``ignore_other_people`` the foreground under their
        bodies (:meth:`silhouettes`) is left out of this tracker's XOR.
        """
        t_start = time.perf_counter()
        self.fitness.times.reset()
        if self.shape_fitness is not self.fitness:
            self.shape_fitness.times.reset()
        timings = {"observe": 0.0, "hull": 0.0, "init": 0.0, "filter": 0.0, "proposals": 0.0,
                   "detection": 0.0}
        masks = list(masks) if masks is not None else [None] * len(self.cameras)
        if len(masks) != len(self.cameras):
            log.error("expected %d masks, got %d: frame skipped", len(self.cameras), len(masks))
            masks = (masks + [None] * len(self.cameras))[:len(self.cameras)]
        t0 = time.perf_counter()
        obs = self.fitness.observe(masks, stamp_ns)
        seeing = int(np.sum(obs.counts >= self.params.min_foreground))
        self._others = tuple(others) if self.params.ignore_other_people else ()
        obs = self._without_others(obs)
        timings["observe"] = time.perf_counter() - t0
        if obs.dropped:
            log.debug("frame %d: views %s missing or invalid", stamp_ns, obs.dropped)
        result_layers: tuple = ()
        if seeing == 0 or (self.state in ("searching", "lost") and seeing < self.params.min_views):
            self._person_absent()
            return self._result(stamp_ns, obs, t_start, timings)
        self._absent_frames = 0
        if self.state in ("searching", "lost"):
            t0 = time.perf_counter()
            started = self._start(masks, obs, stamp_ns, exclude)
            timings["hull"] = time.perf_counter() - t0
            if not started:
                self.state = "searching"
                return self._result(stamp_ns, obs, t_start, timings)
        if self.state == "initialising":
            t0 = time.perf_counter()
            if self._estimator.frames_done > 0:
                self._follow_hull(obs)
            diags = self._estimator.step(self._shape_obs(masks, obs, stamp_ns))
            result_layers = diags[0].layers if diags else ()
            if self._estimator.done:
                self._finish_start()
            else:
                best = self._estimator.best()
                self.estimate = best.estimate[:self.skel.n_dofs].copy()
            timings["init"] = time.perf_counter() - t0
            fit_cost = self._fit_cost(obs)
            return self._result(stamp_ns, obs, t_start, timings, fit_cost, result_layers)
        # tracking
        t0 = time.perf_counter()
        extremities = None
        try:
            reference = self._predict()
            if self.params.proposal_fraction > 0.0 and self.estimate is not None:
                t1 = time.perf_counter()
                spent = self.fitness.times.weighting_seconds()
                rest = self.fitness.rest(self.shape)
                # scored where the body is predicted to be (pelvis moved by its velocity), not
                # where the last frame left it: a runner's hips are 12 cm further on
                self.proposer.apply(self.particles, reference, rest, obs, self.fitness.faces,
                                    self.params.proposal_fraction, self.rng,
                                    cost_fn=lambda x: self.fitness.costs(x, obs, rest))
                # their own search only: the re-ranking's skinning and XOR count under those
                timings["proposals"] = (time.perf_counter() - t1
                                        - (self.fitness.times.weighting_seconds() - spent))
            if self.detector is not None and detector_maps is not None and reference is not None:
                t1 = time.perf_counter()
                extremities = self._detect(masks, detector_maps, reference)
                timings["detection"] = time.perf_counter() - t1
            res = lpf_run(self.particles, self.schedule.filter,
                          self.weight_fn(obs, self.shape, extremities), self.rng)
            if extremities is not None:
                self.ik.update_fraction(res.weighted_particles, res.weights,
                                        extremities.assigned, self.fitness.rest(self.shape))
        except ValueError as err:
            log.warning("frame %d: filter failed (%s); restarting from the visual hull",
                        stamp_ns, err)
            self.state = "lost"
            self.particles = None
            return self._result(stamp_ns, obs, t_start, timings)
        timings["filter"] = time.perf_counter() - t0
        self.particles = res.particles
        self._previous_estimate = self.estimate
        if self.params.estimator == "max":
            self.estimate = res.weighted_particles[int(np.argmax(res.weights))].copy()
        else:
            self.estimate = res.estimate.copy()
        self._tracked_frames += 1
        every = self.params.research_every
        travel = self._travel()
        backwards = self._facing_away_from_travel(travel)
        first_travel = (self.params.travel_heading and travel is not None
                        and not self._travel_checked and self._research_cooldown == 0)
        travel_due = self._travel_search_due(travel)
        if ((every > 0 and self._tracked_frames % every == 0) or backwards or first_travel
                or travel_due):
            t1 = time.perf_counter()
            if backwards:
                log.info("stamp %d ns: the body faces more than %g degrees away from its "
                         "travel: fresh search", stamp_ns, self.params.facing_limit)
            elif first_travel or travel_due:
                log.info("stamp %d ns: the body travels: fresh search with its travel heading",
                         stamp_ns)
            heading = None
            if self.params.travel_heading and travel is not None:
                heading = float(np.arctan2(travel[0], travel[1]))
                self._travel_checked = True
            self._research(obs, stamp_ns, travel_heading=heading)
            self._pelvis_track.clear()
            self._research_cooldown = self._cooldown_after_search()
            self._last_search = self._tracked_frames
            timings["research"] = time.perf_counter() - t1
        fit_cost = self._fit_cost(obs)
        if not np.isfinite(fit_cost) or fit_cost > self.params.lost_cost:
            self._bad_frames += 1
        else:
            self._bad_frames = 0
        if self._bad_frames >= self.params.lost_frames:
            log.info("frame %d: fit cost %.2f above %.2f for %d frames: track lost", stamp_ns,
                     fit_cost, self.params.lost_cost, self._bad_frames)
            self.state = "lost"
            self._bad_frames = 0
        return self._result(stamp_ns, obs, t_start, timings, fit_cost, res.layers, extremities)

    # ------------------------------------------------------------------ steps

    def _detect(self, masks, detector_maps, reference: np.ndarray) -> Extremities:
        """Sec. 2.5.1 around the predicted pose, then IK particles for the detected hands."""
        maps = list(detector_maps)
        if len(maps) != len(self.cameras):
            log.error("expected %d detector maps, got %d: none used", len(self.cameras), len(maps))
            maps = [None] * len(self.cameras)
        rest = self.fitness.rest(self.shape)
        _, joints = self.fitness.pose(reference[None], rest)
        targets = self.ik.end_effectors(reference[None], rest)[0]
        ok_masks = [m if m is not None and np.shape(m) == (c.height, c.width) else None
                    for m, c in zip(masks, self.cameras)]
        j = np.asarray(joints[0])
        chain = np.concatenate([j[self._arms], targets[:2, None]], axis=1)  # (2, 4, 3)
        shoulders = chain[:, 0]
        reach = np.linalg.norm(np.diff(chain, axis=1), axis=2).sum(axis=1) + 0.05
        extremities = self.detector.detect(ok_masks, maps, j, targets, shoulders=shoulders,
                                           reach=reach)
        self.ik.apply(self.particles, extremities.assigned, reference, rest, self.rng)
        return extremities

    def _person_absent(self) -> None:
        self._absent_frames += 1
        forget = self._absent_frames >= self.params.forget_shape_frames
        if self.state != "searching" or forget:
            self.reset(forget_shape=forget)

    def _start(self, masks, obs: Observation, stamp_ns: int,
               exclude: np.ndarray | None = None) -> bool:
        """Visual hull and Powell fit; True when a person was found and the start-up began."""
        p = self.params
        near = self.estimate[self.skel.translation_dofs] if self.estimate is not None else None
        hull = self._hull(obs, near=near, region=p.track_region or None, exclude=exclude)
        if hull is None or hull.top < p.min_hull_height:
            return False
        if self._views_seeing_whole(hull, obs) < min(p.min_full_views, obs.n_views):
            return False
        self._hull_centroid = hull.centroid.copy()
        self._hull_step = np.zeros(3)
        self._hull_track = [hull.centroid[[0, 2]].copy()]
        shape_obs = self._shape_obs(masks, obs, stamp_ns)
        est_params = EstimationParams(
            n_particles=p.shape_particles,
            frames=p.shape_frames if (p.estimate_shape and self.shape is None) else 1,
            estimate_shape=p.estimate_shape, rejection_tau=p.rejection_tau,
            rejection_trials=p.rejection_trials, survival_rate=p.survival_rate,
            proposal_fraction=p.proposal_fraction, head_fraction=p.start_head_fraction,
            head_column=p.start_height_column)
        self._estimator = AnthropometryEstimator(self.shape_fitness, est_params, self.rng,
                                                 room=self.room, fixed_shape=self.shape,
                                                 proposer=self.start_proposer if p.proposal_fraction > 0 else None)
        self._estimator.start(shape_obs, hull)
        best = min(self._estimator.hypotheses,
                   key=lambda h: float(self.shape_fitness.costs(
                       h.estimate[None, :self.skel.n_dofs], shape_obs,
                       self.shape if self.shape is not None else None)[0]))
        self.estimate = best.estimate[:self.skel.n_dofs].copy()
        self._previous_estimate = None
        self.state = "initialising"
        return True

    @staticmethod
    def _views_seeing_whole(hull, obs: Observation, margin_px: float = 1.0) -> int:
        """Number of views whose image holds the whole hull (its box's 8 corners)."""
        half = 0.5 * hull.voxel_size
        boxes = layer_boxes(hull.points.min(axis=0) - half, hull.points.max(axis=0) + half,
                            obs.K, obs.R, obs.t, obs.D, obs.width, obs.height, pad_px=0.0)
        inside = ((boxes[:, 0] >= margin_px) & (boxes[:, 1] >= margin_px)
                  & (boxes[:, 2] <= obs.width - margin_px) & (boxes[:, 3] <= obs.height - margin_px))
        return int(inside.sum())

    def _hull(self, obs: Observation, near: np.ndarray | None = None, region=None,
              exclude: np.ndarray | None = None):
        """The visual hull of the person (sec. 2.3.4) at the tracker's settings."""
        p = self.params
        return visual_hull(obs.masks, obs.K, obs.R, obs.t, obs.D, self.room,
                           fine_voxel=p.voxel_size, min_views=min(p.min_views, obs.n_views),
                           max_misses=p.hull_max_misses, near=near, region=region,
                           exclude=exclude, exclude_radius=SAME_PERSON_RADIUS,
                           bridge_misses=p.hull_bridge_misses)

    def _same_person_hull(self, obs: Observation, point: np.ndarray):
        """The hull of the person at ``point`` (room, 3), or None when the hull nearest it
        lies farther than :data:`SAME_PERSON_RADIUS` on the floor (``visual_hull``'s
        ``near`` falls back to the best-seen person, who may be somebody else)."""
        hull = self._hull(obs, near=point)
        if hull is None or np.linalg.norm((hull.centroid - point)[[0, 2]]) > SAME_PERSON_RADIUS:
            return None
        return hull

    def _follow_hull(self, obs: Observation) -> None:
        """During the start-up: move the hypotheses with the visual hull's centroid (a runner
        crosses a metre during a four-frame start-up, far beyond the start-up's diffusion)."""
        hull = self._same_person_hull(obs, self._hull_centroid)
        if hull is None:
            self._hull_step = np.zeros(3)
            self._hull_track = []  # a gap: no travel measured across it
            return
        step = np.zeros(3)
        step[[0, 2]] = (hull.centroid - self._hull_centroid)[[0, 2]]
        self._hull_centroid = hull.centroid.copy()
        self._hull_step = step
        self._hull_track.append(hull.centroid[[0, 2]].copy())
        t = self.skel.translation_dofs
        for hyp in self._estimator.hypotheses:
            hyp.particles[:, t] += step
            hyp.estimate[t] += step
        if self.params.start_height_margin > 0.0:
            grown = self._estimator.grow_to(hull, self.params.start_height_margin,
                                            self.params.start_height_column,
                                            self.params.start_head_fraction)
            if any(f != 1.0 for f in grown):
                log.info("start-up: the visual hull's top stands above the body (%s; the "
                         "whole hull's top %.2f m); scale x %s",
                         "its head's" if self.params.start_head_fraction > 0.0
                         else "over its head" if self.params.start_height_column > 0.0
                         else "highest points", hull.top,
                         ", ".join(f"{f:.3f}" for f in grown))

    def _finish_start(self) -> None:
        est = self._estimator
        best = est.best()
        if self.shape is None:
            self.shape = est.shape()
        self.estimate = best.estimate[:self.skel.n_dofs].copy()
        n = self.schedule.n_particles
        pose = est.pose_particles()
        idx = self.rng.choice(len(pose), size=n, replace=len(pose) < n)
        self.particles = pose[idx]
        # the hull's last step seeds the pelvis velocity of the first tracked frame
        self._previous_estimate = self.estimate.copy()
        self._previous_estimate[self.skel.translation_dofs] -= self._hull_step
        self._estimator = None
        self._bad_frames = 0
        self._tracked_frames = 0
        # the start-up's hull travel stands for the pelvis' (moved to end at the estimate),
        # so that backwards_frames / travel_heading can judge the start-up's heading on the
        # first tracked frames rather than backwards_frames frames later
        pelvis = self.estimate[self.skel.translation_dofs][[0, 2]]
        self._pelvis_track = ([c - self._hull_track[-1] + pelvis for c in self._hull_track]
                              if self._hull_track else [])
        self._research_cooldown = 0
        self._travel_checked = False
        self._last_search = 0
        self.state = "tracking"

    def _travel(self) -> np.ndarray | None:
        """The estimate's pelvis travel (x, z) over the last ``backwards_frames`` frames, or
        None while it is off, not yet measured, or slower than ``backwards_step`` per frame.
        Records this frame's pelvis."""
        n = self.params.backwards_frames
        if n <= 0:
            return None
        self._pelvis_track.append(self.estimate[self.skel.translation_dofs][[0, 2]].copy())
        del self._pelvis_track[:-(n + 1)]
        if len(self._pelvis_track) <= n:
            return None
        travel = self._pelvis_track[-1] - self._pelvis_track[0]
        if np.linalg.norm(travel) <= n * self.params.backwards_step:
            return None
        return travel

    def _travel_search_due(self, travel: np.ndarray | None) -> bool:
        """``travel_research_every``: True when the pelvis travels (:meth:`_travel`) and that
        many tracked frames have passed since the last fresh search (or the start)."""
        n = self.params.travel_research_every
        return n > 0 and travel is not None and self._tracked_frames - self._last_search >= n

    def _cooldown_after_search(self) -> int:
        """Frames the ``backwards_frames`` check waits after a fresh search
        (``facing_cooldown``, 0: ``research_every``), at least ``backwards_frames``: the
        pelvis track is cleared by the search and needs that many frames again."""
        p = self.params
        return max(p.facing_cooldown or p.research_every, p.backwards_frames)

    def _facing_away_from_travel(self, travel: np.ndarray | None) -> bool:
        """``backwards_frames``: True when the pelvis travels (:meth:`_travel`) and the
        estimate's facing direction (the root yaw: +Z turned towards +X) points more than
        ``facing_limit`` degrees (90: back to front) away from that travel, outside the
        cool-down after a search. People walk and run facing forward, and the silhouettes
        of a body seen from the front and from the back differ little, so a start-up can take
        one for the other (docs/tracking.md, the 02_03 seed-28 runner); a smaller limit also
        catches a pelvis turned 30 degrees off with the legs twisted to make up for it (the
        02_03 seed-27 runner)."""
        if self._research_cooldown > 0:
            self._research_cooldown -= 1
            return False
        if travel is None:
            return False
        yaw = self.estimate[self.skel.dof_index("root_yaw")]
        along = float(np.sin(yaw) * travel[0] + np.cos(yaw) * travel[1])
        if self.params.facing_limit == 90.0:
            return along < 0.0  # exactly (cos 90 degrees is 6e-17 in floating point)
        return along < np.cos(np.deg2rad(self.params.facing_limit)) * float(np.linalg.norm(travel))

    def _research(self, obs: Observation, stamp_ns: int,
                  travel_heading: float | None = None) -> bool:
        """A fresh start-up search on this frame at the estimated shape (``research_every``).

        The start-up's heading search and Powell fits (sec. 2.3.4) run from the visual hull of
        the person being tracked; when one of their poses has a lower whole-body cost (eq.
        2.8) than the filter's estimate of this frame, it becomes the estimate and the
        particles are drawn from its hypothesis. The per-frame filter only explores around
        its last estimate, so a wrong pose whose parts compensate each other (a pelvis turned
        with the legs bent to make up for it, legs swapped) is never left otherwise, although
        the silhouettes prefer the truth (``tools/failure_split.py``). Returns True when the
        filter was re-seeded. travel_heading: a heading (root yaw) searched and fitted in
        addition to the search's own (``travel_heading``).
        """
        p = self.params
        n = self.skel.n_dofs
        pelvis = self.estimate[self.skel.translation_dofs]
        hull = self._same_person_hull(obs, pelvis)  # the person tracked, nobody else
        if hull is None or hull.top < p.min_hull_height:
            return False
        search = AnthropometryEstimator(
            self.fitness, EstimationParams(n_particles=p.shape_particles, frames=1,
                                           estimate_shape=False,
                                           proposal_fraction=p.proposal_fraction),
            self.rng, room=self.room, fixed_shape=self.shape,
            proposer=self.start_proposer if p.proposal_fraction > 0 else None)
        search.start(obs, hull, also=() if travel_heading is None else (travel_heading,))
        poses = np.stack([self.estimate] + [h.estimate[:n] for h in search.hypotheses])
        costs = self.fitness.costs(poses, obs, self.fitness.rest(self.shape))
        near = np.linalg.norm((poses[:, self.skel.translation_dofs] - pelvis)[:, [0, 2]],
                              axis=1) <= SAME_PERSON_RADIUS
        costs = np.where(near, costs, np.inf)
        best = int(np.argmin(costs))
        if best == 0:
            return False
        log.info("stamp %d ns: a fresh search fits better (cost %.3f against %.3f): filter "
                 "re-seeded", stamp_ns, costs[best], costs[0])
        particles = search.hypotheses[best - 1].particles[:, :n]
        idx = self.rng.choice(len(particles), size=len(self.particles),
                              replace=len(particles) < len(self.particles))
        self.particles = particles[idx].copy()
        # the person keeps moving: the frame's step carries over to the new estimate, so the
        # velocity prediction of the next frame still has it (a runner moves 12 cm a frame)
        if self._previous_estimate is not None:
            self._previous_estimate = poses[best] - (self.estimate - self._previous_estimate)
        self.estimate = poses[best].copy()
        return True

    def _predict(self) -> np.ndarray | None:
        """Apply the velocity prediction to the particles; returns the predicted pose."""
        if self.estimate is None:
            return None
        predicted = self.estimate.copy()
        if self._previous_estimate is None or self.params.velocity_gain <= 0.0:
            return predicted
        step = self.estimate - self._previous_estimate
        dofs = {"root_position": self.skel.translation_dofs,
                "root": np.arange(6), "all": np.arange(self.skel.n_dofs)}[self.params.velocity_dofs]
        self.particles[:, dofs] += self.params.velocity_gain * step[dofs]
        predicted[dofs] += self.params.velocity_gain * step[dofs]
        return predicted

    def _fit_cost(self, obs: Observation) -> float:
        """Eq. 2.8 of the estimate, counted inside a box around its body (10 cm margin) and
        averaged over the views: a second person or a door elsewhere in the images does not
        make a good fit look collapsed."""
        if self.estimate is None or obs.n_views == 0:
            return float("nan")
        shape = self.shape if self.shape is not None else (
            self._estimator.shape() if self._estimator is not None else None)
        verts, _ = self.fitness.pose(self.estimate[None], shape)
        lo, hi = part_boxes_3d(verts, np.arange(verts.shape[1]), 0.0, 0.10)
        boxes = layer_boxes(lo, hi, obs.K, obs.R, obs.t, obs.D, obs.width, obs.height)
        with serial_below(obs.n_views):
            xor = self.fitness.view_xor_from_verts(verts, obs, boxes)[0]
        inside = observed_counts(obs.masks if obs.ignore is None else
                                 (obs.masks != 0) & ~obs.ignore, boxes)
        return float(np.mean(xor / np.maximum(inside, self.fitness.min_count)))

    def _current_shape(self) -> BodyShape | None:
        if self.shape is not None:
            return self.shape
        if self._estimator is not None:
            return self._estimator.shape()
        return None

    def _result(self, stamp_ns: int, obs: Observation, t_start: float, timings: dict,
                fit_cost: float = float("nan"), layers: tuple = (),
                extremities: Extremities | None = None) -> TrackResult:
        times = self.fitness.times
        extra = self.shape_fitness.times if self.shape_fitness is not self.fitness else None
        timings = dict(timings)
        timings["skinning"] = times.skinning + (extra.skinning if extra else 0.0)
        timings["projection"] = times.projection + (extra.projection if extra else 0.0)
        timings["xor"] = times.xor + (extra.xor if extra else 0.0)
        timings["evaluations"] = times.evaluations + (extra.evaluations if extra else 0)
        timings["total"] = time.perf_counter() - t_start
        params = joints = None
        shape = self._current_shape()
        if self.state in ("initialising", "tracking") and self.estimate is not None:
            params = self.estimate.copy()
            _, j = self.fitness.pose(params[None], shape)
            joints = np.asarray(j[0], dtype=np.float64)
        return TrackResult(stamp_ns=int(stamp_ns), state=self.state, params=params,
                           joints=joints, joint_names=tuple(self.model.joint_names), shape=shape,
                           fit_cost=fit_cost, views=tuple(int(v) for v in obs.views),
                           dropped=tuple(obs.dropped), layers=tuple(layers), timings=timings,
                           extremities=extremities)
