"""Settings of the body tracker: one frozen dataclass of groups, each handed down whole.

:class:`TrackerParams` holds the method and seven groups of what a room's user sets
(budgets, working resolutions, start and loss rules); the ``body_tracker`` node declares
every leaf by its dotted name (``startup.min_views``), the evaluator takes ``--param
filter.sweeps=1``. The method's own settings, which no room changes, are constants beside
the code that uses them, each with its reason (:mod:`.body_layers`, :mod:`.observation_boxes`,
:mod:`.limb_proposals`, :mod:`.detector_driven`, :mod:`.startup`, :mod:`.body_tracker`).
Defaults: 4 cameras at 640x480, 25 fps, about 3,500 weight evaluations per frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hmocap_ros.params import group, param
from hmocap_ros.tracking.keypoint_first import KeypointFirstParams
from hmocap_ros.tracking.methods import get_method, method_names

__all__ = ["EstimationParams", "FilterParams", "HullParams", "LostParams", "ResearchParams",
           "StartupParams", "TRACKER_MESHES", "TrackerParams", "WeightingParams"]

#: Shipped meshes a tracker can render its particles with (``weighting.mesh``).
TRACKER_MESHES = ("tracking_coarse", "tracking")


def _check(checks) -> None:
    for ok, message in checks:
        if not ok:
            raise ValueError(f"TrackerParams: {message}")


@dataclass(frozen=True)
class FilterParams:
    """The layered particle filter's budget (alg. 1-5); its kernels and annealing are the
    constants of :mod:`.body_layers`."""

    particles: int = param(0, "Particles per layer; 0: the method's budget (about 3,500 weight "
                              "evaluations per frame over its layers).")
    layers: int = param(0, "Annealing layers of the APF; 0: 14. The hierarchical methods have "
                           "one layer per body part and sweep.")
    sweeps: int = param(2, "Hierarchical methods: passes over the kinematic tree's blocks per "
                           "frame (>= 1). A second pass weighs every block again once the "
                           "others are filtered, at half the kernel std, with the particles "
                           "per layer cut so the evaluations per frame stay the same "
                           "(hpf-apo: 15 x 234); 1: one layer per block as in the thesis.")

    def __post_init__(self):
        _check([
            (self.particles >= 0 and self.layers >= 0, "filter.particles, filter.layers must "
                                                       "be >= 0"),
            (self.sweeps >= 1, "filter.sweeps must be >= 1"),
        ])


@dataclass(frozen=True)
class WeightingParams:
    """The silhouette weighting (eq. 2.8); the observation boxes (eq. 2.15) are
    :mod:`.observation_boxes`' constants."""

    working_width: int = param(160, "Width (pixels, >= 16) at which silhouettes are compared: "
                                    "the masks are reduced by the scale that takes the rig's "
                                    "widest camera to it (640x480 -> 160x120, 1280x720 -> "
                                    "160x90), and kept whole when narrower.")
    mesh: str = param("tracking", "Body mesh the particles are rendered with (same joints "
                                  "and DoFs): 'tracking' (2,400 triangles) or "
                                  "'tracking_coarse' (1,000, about one per silhouette pixel "
                                  "at 160x120: about twice as fast per frame, a few mm less "
                                  "accurate).")

    def __post_init__(self):
        _check([
            (self.working_width >= 16, "weighting.working_width must be >= 16"),
            (self.mesh in TRACKER_MESHES, f"weighting.mesh must be one of {TRACKER_MESHES}"),
        ])


@dataclass(frozen=True)
class StartupParams:
    """Finding a person and the start-up: visual hull, pose and anthropometry (sec. 2.3)."""

    min_views: int = param(2, "Views with enough foreground needed to start (and to carve the "
                              "visual hull), >= 1.")
    min_full_views: int = param(3, "Views that must see the whole visual hull inside the image "
                                   "before a track starts: a person half out of view gives a "
                                   "wrong height and a wrong first pose.")
    min_foreground: int = param(40, "Foreground pixels at the working resolution for a view to "
                                    "count as seeing a person.")
    track_region: list[float] = param([], "Floor box [x_min, z_min, x_max, z_max] (m, room "
                                          "frame) where a track may start: only a person "
                                          "whose visual hull centroid stands in it is followed "
                                          "(e.g. the interaction area in front of a display); "
                                          "once started, the track follows the person "
                                          "anywhere. Empty: the whole room, the best-seen "
                                          "person.")
    estimate_shape: bool = param(True, "Estimate the anthropometry at start (sec. 2.3); false "
                                       "keeps the model's proportions, scaled to the visual "
                                       "hull.")
    frames: int = param(4, "Frames (>= 1) of layered filtering over shape and pose at start.")
    particles: int = param(250, "Particles per layer (>= 2) of the start-up filter.")
    working_width: int = param(320, "Width (pixels, >= 16) of the start-up weighting's "
                                    "silhouettes (as weighting.working_width).")

    def __post_init__(self):
        # a list from ROS or the command line; kept as a tuple so the params stay immutable
        object.__setattr__(self, "track_region", tuple(float(v) for v in self.track_region))
        r = self.track_region
        _check([
            (self.min_views >= 1, "startup.min_views must be >= 1"),
            (self.frames >= 1 and self.particles >= 2,
             "startup.frames >= 1, startup.particles >= 2"),
            (self.working_width >= 16, "startup.working_width must be >= 16"),
            (not r or (len(r) == 4 and np.isfinite(r).all() and r[0] < r[2] and r[1] < r[3]),
             "startup.track_region must be empty or [x_min, z_min, x_max, z_max] with "
             "min < max"),
        ])


@dataclass(frozen=True)
class HullParams:
    """The visual hull the start-up and the fresh searches carve (sec. 2.3.4)."""

    voxel_size: float = param(0.03, "Voxel edge (m) of the fine visual hull grid.")
    min_height: float = param(0.9, "Smallest hull top (m) accepted as a person.")
    max_misses: int = param(0, "Views in which a hull voxel may project onto background "
                               "(tolerates holes in the foreground).")
    bridge_misses: int = param(1, "Views more than max_misses in which a voxel may project "
                                  "onto background and still join the hull's parts into one "
                                  "person (the hull keeps only the max_misses voxels): a band "
                                  "of the body lost in one view, such as a shirt the colour "
                                  "of the wall, then does not cut the person in two.")

    def __post_init__(self):
        _check([(self.voxel_size > 0.0, "hull.voxel_size must be > 0"),
                (self.max_misses >= 0 and self.bridge_misses >= 0,
                 "hull.max_misses and hull.bridge_misses must be >= 0")])


@dataclass(frozen=True)
class ResearchParams:
    """Fresh searches while tracking: a way out of a wrong pose the filter cannot leave."""

    every: int = param(25, "Every this many tracked frames a fresh start-up search (heading "
                           "search with limb proposals and Powell fits from the visual hull, "
                           "at the estimated shape) is weighed against the frame's estimate; "
                           "the filter is re-seeded from it when it fits better (the search "
                           "costs seconds on that frame: docs/tracking.md, section 3.2); 0: off.")
    backwards_frames: int = param(5, "Frames over which the pelvis' travel is measured: when it "
                                     "moved faster than backwards_step and the body faces away "
                                     "from the travel by more than facing_limit, a fresh "
                                     "search runs at once; while the body travels, searches "
                                     "also fit a pose facing the travel, and one runs as soon "
                                     "as the travel is first measured after a start; 0: off.")
    backwards_step: float = param(0.05, "Mean pelvis travel per frame (m, > 0) above which the "
                                        "body counts as travelling (0.05: 1.25 m/s at 25 fps).")
    facing_limit: float = param(90.0, "Degrees in (0, 180] between the body's facing "
                                      "direction (root yaw) and its travel above which a "
                                      "fresh search runs: 90 catches a body tracked back to "
                                      "front; a smaller angle also a pelvis turned away from "
                                      "the way it runs (people walk and run facing within "
                                      "about 10 degrees of their travel).")

    def __post_init__(self):
        _check([
            (self.every >= 0, "research.every must be >= 0 (0: off)"),
            (self.backwards_frames >= 0 and self.backwards_step > 0.0,
             "need research.backwards_frames >= 0 (0: off) and research.backwards_step > 0"),
            (0.0 < self.facing_limit <= 180.0,
             "research.facing_limit must lie in (0, 180] degrees"),
        ])


@dataclass(frozen=True)
class LostParams:
    """When a track counts as lost, and when a person's shape is forgotten."""

    cost: float = param(0.6, "Mean per-view silhouette XOR / foreground, counted in a box "
                             "around the estimated body (eq. 2.8 divided by the views), above "
                             "which a frame counts as a failed fit.")
    frames: int = param(8, "Consecutive failed fits (>= 1) after which the track is lost and "
                           "restarts from the visual hull.")
    forget_shape_frames: int = param(50, "Frames without a person after which the estimated "
                                         "shape is forgotten.")

    def __post_init__(self):
        _check([(self.frames >= 1, "lost.frames must be >= 1")])


@dataclass(frozen=True)
class EstimationParams:
    """Settings of the start-up (:mod:`.anthropometry_estimation` and :mod:`.anthropometry_layers`, thesis sec. 2.3)."""

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


@dataclass(frozen=True)
class TrackerParams:
    """Settings of :class:`~hmocap_ros.tracking.body_tracker.BodyTracker`: the method and the
    groups, each handed whole to the part that uses it."""

    method: str = param("kf-hpf", "Layered filter (tracking.methods): 'kf-hpf' (keypoint-first: "
                                  "the body fitted to the extremity node's labelled keypoints, "
                                  "the filter only on the blocks they leave uncertain), or the "
                                  "thesis' 'apf' (annealing, 14 x 250), 'hpf' (hierarchical, "
                                  "14 x 250 in two sweeps), 'hpf-apo' (hierarchical with "
                                  "approximate partitioning of observations, 15 x 234 in two "
                                  "sweeps), 'dd-hpf' (hpf-apo driven by hand detections: IK "
                                  "particles and the refinement layer, sec. 2.5). kf-hpf and "
                                  "dd-hpf take the extremity detections.")
    filter: FilterParams = group(FilterParams, "layered particle filter budget")
    weighting: WeightingParams = group(WeightingParams, "silhouette weighting")
    keypoints: KeypointFirstParams = group(KeypointFirstParams, "keypoint-first tracking")
    startup: StartupParams = group(StartupParams, "start-up and anthropometry")
    hull: HullParams = group(HullParams, "visual hull")
    research: ResearchParams = group(ResearchParams, "fresh searches while tracking")
    lost: LostParams = group(LostParams, "track loss")

    def __post_init__(self):
        _check([(self.method in method_names(), f"method must be one of {method_names()}")])

    @property
    def tracking_method(self):
        """The registered :class:`~hmocap_ros.tracking.methods.TrackingMethod`."""
        return get_method(self.method)
