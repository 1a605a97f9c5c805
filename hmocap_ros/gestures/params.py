"""Parameters of gesture localization (thesis sec. 3.2): frozen dataclasses, one per concern.

- :class:`DepthFormat`: how a camera's raw depth image maps to metres (unit, invalid value, range).
- :class:`FeatureParams`: the depth binary tests (eq. 3.3 / clipped eq. 3.6); stored in the forest.
- :class:`PatchParams`: patch (sample) collection from annotated frames (sec. 3.2.3, "Patch collection").
- :class:`ForestParams`: offline forest growth and boosted tree-by-tree learning (sec. 3.2.1, 3.2.3).
- :class:`TrainParams`: the four above, what :func:`hmocap_ros.gestures.train_forest` takes.
- :class:`DetectorParams`: per-frame localization (sec. 3.2.4), what the node declares.
- :class:`OnlineParams`: online forest growth (sec. 3.3.1, alg. 6) and on-the-fly negatives (sec. 3.3.2).
- :class:`OnlineTrainParams`: depth, tests, patches and online parameters: what the online trainer takes.

The fields carry a ``description`` in their metadata, so a node can declare them as ROS
parameters without this module importing rclpy. Lengths are metres; offsets and radii that
scale with depth are in pixel*metres ("pixels at 1 m": at depth d they span value/d pixels).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from hmocap_ros.params import param

FEATURE_TYPES = ("clipped", "plain")
OUTSIDE_MODES = ("border", "background")
#: Focal length (px) of the camera the pixel sizes of the defaults are given for: a 640x480
#: Kinect-like depth camera (sec. 3.2.6 uses 85x85 px patches and a 10 px criterion at 640x480).
REFERENCE_FOCAL_PX = 525.0


def _check(checks, name):
    for ok, message in checks:
        if not ok:
            raise ValueError(f"{name}: {message}")


@dataclass(frozen=True)
class DepthFormat:
    """How raw depth images of one camera become metres (float32) for the forest.

    A pixel is invalid when it equals ``invalid_value``, is NaN/inf, or its depth lies outside
    ``[min_depth_m, max_depth_m]``; invalid pixels are never reference pixels and read as the
    forest's ``background_depth_m`` when a test probes them (see ``depth_features``).
    """

    unit_m: float = param(
        0.0, "Metres per raw depth unit (>= 0): 0.001 for millimetres (16UC1), 0.000125 for 1/8 mm, "
             "1.0 for metres (32FC1); 0 = REP 118: integer images in mm, float images in m.")
    invalid_value: float = param(
        0.0, "Raw value that marks a pixel without depth (NaN and inf are always invalid).")
    min_depth_m: float = param(
        0.3, "Nearer depths (metres, > 0) are invalid: the sensor minimum; it bounds the test "
             "offsets in pixels.")
    max_depth_m: float = param(
        8.0, "Farther depths (metres) are invalid: the sensor maximum, above min_depth_m and below "
             "the forest's background_depth_m.")

    def __post_init__(self):
        _check([(self.unit_m >= 0.0, "unit_m must be >= 0 (0 = REP 118 by dtype)"),
                (0.0 < self.min_depth_m < self.max_depth_m, "need 0 < min_depth_m < max_depth_m")],
               "DepthFormat")

    def unit_for(self, dtype) -> float:
        """Metres per unit for images of ``dtype`` (resolves ``unit_m = 0`` by REP 118)."""
        if self.unit_m > 0.0:
            return float(self.unit_m)
        return 0.001 if np.issubdtype(np.dtype(dtype), np.integer) else 1.0


@dataclass(frozen=True)
class FeatureParams:
    """The depth binary tests of the forest (thesis eq. 3.3 and 3.6); saved in the forest file."""

    feature_type: str = param(
        "clipped", "'clipped': depth-clipped pixel-pair tests (eq. 3.6); 'plain': eq. 3.3.")
    kappa_m: float = param(
        0.15, "Clipping parameter kappa (eq. 3.6) in metres, > 0: probe depths are clipped to "
              "d(x) +- kappa. Ignored by plain tests.")
    patch_half_size_px_m: float = param(
        85.0, "Half side of the square of test offsets u, v in pixel*metres, > 0: at reference "
              "depth d the probes lie within +-value/d pixels (85 = an 85x85 px patch at 2 m).")
    background_depth_m: float = param(
        10.0, "Depth in metres (> 0, beyond every valid depth) read by a probe that falls on an "
              "invalid pixel (or outside the image, with outside = 'background'): far background "
              "(with clipping it reads d(x) + kappa like any far clutter).")
    outside: str = param(
        "border", "What a probe outside the image reads: 'border' = the nearest image pixel (the "
                  "scene goes on beyond the frame), 'background' = background_depth_m.")

    def __post_init__(self):
        _check([(self.feature_type in FEATURE_TYPES, f"feature_type must be one of {FEATURE_TYPES}"),
                (self.kappa_m > 0.0, "kappa_m must be > 0"),
                (self.patch_half_size_px_m > 0.0, "patch_half_size_px_m must be > 0"),
                (self.background_depth_m > 0.0, "background_depth_m must be > 0"),
                (self.outside in OUTSIDE_MODES, f"outside must be one of {OUTSIDE_MODES}")],
               "FeatureParams")

    @property
    def clipped(self) -> bool:
        return self.feature_type == "clipped"

    @property
    def border(self) -> bool:
        return self.outside == "border"


@dataclass(frozen=True)
class PatchParams:
    """Patch collection from annotated frames (thesis sec. 3.2.3, "Patch collection")."""

    n_positive: int = param(
        64, "N+: positive samples per gesture frame (>= 1), drawn in the box around the annotated "
            "point.")
    n_negative: int = param(
        256, "N-: negative samples per frame (>= 0): outside the box in gesture frames, anywhere "
             "in negative frames.")
    box_half_size_px_m: float = param(
        20.0, "Half side of the positive box in pixel*metres (> 0), scaled by the annotated "
              "point's depth (20 = +-10 px at 2 m).")
    positive_depth_tolerance_m: float = param(
        0.10, "Box pixels whose depth differs from the annotated point's by more (metres, >= 0) "
              "are not positives (background seen through the box); 0 disables the check.")
    negative_exclusion_scale: float = param(
        1.0, "Negatives of gesture frames are drawn outside the box scaled by this factor "
             "(>= 1; 1 = just outside the box).")
    n_negative_near: int = param(
        256, "Extra negatives per gesture frame (>= 0) drawn outside the (scaled) box but inside "
             "the square of half side near_half_size_px_m / d around the annotated point: the rest "
             "of the hand, the arm, the face, which a detector sees next to the gesture.")
    near_half_size_px_m: float = param(
        85.0, "Half side of the near-negative square in pixel*metres (> 0; 85 = the test patch).")
    n_near_miss: int = param(
        128, "Negatives per near-miss frame (>= 0; a background frame annotated with the point of "
             "the gesture it misses) drawn in the box around that point, on the hand (depth within "
             "positive_depth_tolerance_m): where a near miss differs from its gesture. The frame "
             "also gives n_negative_near negatives in the near square around the box and n_negative "
             "anywhere.")

    def __post_init__(self):
        _check([(self.n_positive >= 1 and self.n_negative >= 0, "need n_positive >= 1, n_negative >= 0"),
                (self.box_half_size_px_m > 0.0, "box_half_size_px_m must be > 0"),
                (self.positive_depth_tolerance_m >= 0.0, "positive_depth_tolerance_m must be >= 0"),
                (self.negative_exclusion_scale >= 1.0, "negative_exclusion_scale must be >= 1"),
                (self.n_negative_near >= 0 and self.n_near_miss >= 0, "need n_negative_near, n_near_miss >= 0"),
                (self.near_half_size_px_m > 0.0, "near_half_size_px_m must be > 0")],
               "PatchParams")


@dataclass(frozen=True)
class ForestParams:
    """Offline forest growth (sec. 3.2.1) and boosted tree-by-tree learning (sec. 3.2.3)."""

    n_trees: int = param(15, "Trees M of the forest (>= 1).")
    max_depth: int = param(20, "Maximum depth D of a tree (root = 0), 1 to 64.")
    n_tests: int = param(
        100, "Random candidate tests (offset pairs u, v) drawn per node (>= 1).")
    n_thresholds: int = param(
        16, "Random thresholds per candidate test (>= 1), drawn among the node's feature values.")
    min_samples_leaf: int = param(5, "A split must leave at least this many samples (>= 1) on each side.")
    min_gain: float = param(1e-4, "Nodes whose best information gain (eq. 3.2, nats, >= 0) is lower stay "
                                  "leaves.")
    samples_per_class: int = param(
        10000, "Balanced bag: samples of each class drawn with replacement per tree (>= 1).")
    boosted: bool = param(
        True, "Boosted learning (sec. 3.2.3): the out-of-bag samples a tree misclassifies join "
              "the next tree's bag; false = independent balanced bags.")
    max_boost_fraction: float = param(
        0.5, "Cap on the misclassified out-of-bag samples carried to the next tree, as a "
             "fraction of the balanced bag size, 0 to 10.")
    mining_rounds: int = param(
        1, "Rounds of hard negative mining (>= 0): the trained forest votes on its training "
           "frames like the detector; pixels voting for a gesture away from the annotated one "
           "join the samples as background and the forest is trained again (0 = none).")
    mining_per_frame: int = param(256, "At most this many mined negatives per frame and round (>= 1).")
    mining_stride: int = param(
        4, "Grid step (pixels, 1 to 64) of the mining votes, as the detector's stride.")
    mining_exclusion_scale: float = param(
        2.0, "Votes within this many positive boxes (>= 1) of the annotated point are not mined.")
    located_share: float = param(
        1.0, "The located near-miss negatives (drawn on and around the hand of a near-miss frame, and "
             "mined there) form a stratum of each tree's bag of their own: located_share x "
             "samples_per_class of them per tree, beside the other background samples (>= 0; 0 = "
             "they are drawn as any background sample).")

    def __post_init__(self):
        _check([(self.n_trees >= 1, "n_trees must be >= 1"),
                (self.located_share >= 0.0, "located_share must be >= 0"),
                (1 <= self.max_depth <= 64, "max_depth must be in [1, 64]"),
                (self.n_tests >= 1 and self.n_thresholds >= 1, "need n_tests, n_thresholds >= 1"),
                (self.min_samples_leaf >= 1, "min_samples_leaf must be >= 1"),
                (self.min_gain >= 0.0, "min_gain must be >= 0"),
                (self.samples_per_class >= 1, "samples_per_class must be >= 1"),
                (0.0 <= self.max_boost_fraction <= 10.0, "max_boost_fraction must be in [0, 10]"),
                (self.mining_rounds >= 0 and self.mining_per_frame >= 1, "need mining_rounds >= 0, "
                                                                         "mining_per_frame >= 1"),
                (1 <= self.mining_stride <= 64, "mining_stride must be in [1, 64]"),
                (self.mining_exclusion_scale >= 1.0, "mining_exclusion_scale must be >= 1")],
               "ForestParams")


@dataclass(frozen=True)
class TrainParams:
    """Everything :func:`hmocap_ros.gestures.train_forest` needs besides data and a Generator."""

    depth: DepthFormat = field(default_factory=DepthFormat)
    features: FeatureParams = field(default_factory=FeatureParams)
    patches: PatchParams = field(default_factory=PatchParams)
    forest: ForestParams = field(default_factory=ForestParams)

    def __post_init__(self):
        _check([(self.depth.max_depth_m < self.features.background_depth_m,
                 "depth.max_depth_m must be below features.background_depth_m")], "TrainParams")

    def for_focal(self, focal_px: float) -> "TrainParams":
        """These parameters with the pixel sizes (patch, boxes, mining stride), given for a camera
        of focal length :data:`REFERENCE_FOCAL_PX`, scaled to a camera of ``focal_px``."""
        s = float(focal_px) / REFERENCE_FOCAL_PX
        f, p, t = self.features, self.patches, self.forest
        return replace(self, features=replace(f, patch_half_size_px_m=f.patch_half_size_px_m * s),
                       patches=replace(p, box_half_size_px_m=p.box_half_size_px_m * s,
                                       near_half_size_px_m=p.near_half_size_px_m * s),
                       forest=replace(t, mining_stride=int(min(64, max(1, round(t.mining_stride * s))))))


@dataclass(frozen=True)
class DetectorParams:
    """Per-frame gesture localization (thesis sec. 3.2.4) on one depth camera."""

    depth_unit_m: float = param(
        0.0, "Metres per raw depth unit, >= 0 (0.001 = mm, 0.000125 = 1/8 mm, 1 = m); 0 = REP 118: "
             "16UC1 in mm, 32FC1 in m.")
    invalid_value: float = param(0.0, "Raw depth value of pixels without depth (NaN is always invalid).")
    min_depth_m: float = param(0.3, "Nearer depths (metres, > 0) are invalid and cast no vote.")
    max_depth_m: float = param(8.0, "Farther depths (metres, above min_depth_m and below the forest's "
                                    "background_depth_m) are invalid and cast no vote.")
    stride: int = param(
        4, "Grid step in pixels (1 to 64): the forest is evaluated at every stride-th pixel of "
           "every stride-th row (4 = 160x120 votes at 640x480).")
    vote_reach: float = param(
        0.5, "In (0, 1]: after each tree, a grid pixel whose background sum leads every gesture by "
             "more than this times the trees left stops and votes background. 1 is exact (a tree "
             "gives a class at most 1); lower is faster (wall and floor pixels stop after a few "
             "trees) at the risk of dropping a vote the last trees would have made.")
    parzen_sigma_px: float = param(
        6.0, "Standard deviation (pixels, >= 0) of the Gaussian Parzen kernel over the vote "
             "image; 0 = no smoothing.")
    alpha: float = param(
        0.8, "Adaptation rate alpha in (0, 1] of the temporal smoothing p' = alpha p + "
             "(1 - alpha) p'_prev (eq. 3.4); 1 = no smoothing.")
    volume_radius_px_m: float = param(
        20.0, "Radius of the disk S of the volume test (eq. 3.5) in pixel*metres, > 0: value/d "
              "pixels at the maximum's depth d (20 = 10 px at 2 m, about 4 cm at f = 525 px).")
    min_score: float = param(
        0.4, "A class is detected when its smoothed density (eq. 3.4) at the maximum is at least "
             "this; densities lie in [0, 1].")
    min_volume: float = param(
        0.3, "... and the mean smoothed density over the disk S (eq. 3.5 / |S|) at least this, "
             "in [0, 1].")
    suppression_radius_px_m: float = param(
        60.0, "A detection closer than value/d pixels (pixel*metres, >= 0; d its depth) to a "
              "higher-scoring detection of another class is dropped: one place shows one gesture. "
              "0 keeps all.")
    max_gap_s: float = param(
        1.0, "Seconds (> 0): the smoothing state restarts when consecutive stamps are further "
             "apart than this, or go back in time (a replayed bag looping), or the image size "
             "changes.")
    reference_focal_px: float = param(
        REFERENCE_FOCAL_PX, "Focal length (px, >= 0) the pixel sizes above (stride, parzen_sigma_px, "
                            "volume_radius_px_m, suppression_radius_px_m) are given for; they are "
                            "scaled by the camera's fx / this (525 = a 640x480 Kinect-like camera). "
                            "0 uses them as given.")

    def __post_init__(self):
        _check([(self.depth_unit_m >= 0.0, "depth_unit_m must be >= 0"),
                (0.0 < self.min_depth_m < self.max_depth_m, "need 0 < min_depth_m < max_depth_m"),
                (1 <= self.stride <= 64, "stride must be in [1, 64]"),
                (0.0 < self.vote_reach <= 1.0, "vote_reach must be in (0, 1]"),
                (self.parzen_sigma_px >= 0.0, "parzen_sigma_px must be >= 0"),
                (0.0 < self.alpha <= 1.0, "alpha must be in (0, 1]"),
                (self.volume_radius_px_m > 0.0, "volume_radius_px_m must be > 0"),
                (self.min_score >= 0.0 and self.min_volume >= 0.0, "thresholds must be >= 0"),
                (self.suppression_radius_px_m >= 0.0, "suppression_radius_px_m must be >= 0"),
                (self.max_gap_s > 0.0, "max_gap_s must be > 0"),
                (self.reference_focal_px >= 0.0, "reference_focal_px must be >= 0")],
               "DetectorParams")

    @property
    def depth_format(self) -> DepthFormat:
        return DepthFormat(unit_m=self.depth_unit_m, invalid_value=self.invalid_value,
                           min_depth_m=self.min_depth_m, max_depth_m=self.max_depth_m)

    def for_focal(self, focal_px: float | None) -> "DetectorParams":
        """These parameters with the pixel sizes scaled from ``reference_focal_px`` to a camera of
        focal length ``focal_px`` (the stride rounded, at least 1); unchanged for ``None`` or
        ``reference_focal_px = 0``."""
        if focal_px is None or self.reference_focal_px <= 0:
            return self
        s = float(focal_px) / self.reference_focal_px
        return replace(self, stride=int(min(64, max(1, round(self.stride * s)))),
                       parzen_sigma_px=self.parzen_sigma_px * s,
                       volume_radius_px_m=self.volume_radius_px_m * s,
                       suppression_radius_px_m=self.suppression_radius_px_m * s, reference_focal_px=0.0)


NEGATIVE_MODES = ("hard", "random")


@dataclass(frozen=True)
class OnlineParams:
    """Online random forest (thesis sec. 3.3.1, alg. 6) and on-the-fly negatives (sec. 3.3.2)."""

    n_trees: int = param(15, "Trees T of the forest (>= 1).")
    max_depth: int = param(20, "Maximum depth D of a tree (root = 0), 1 to 64: leaves at D keep no candidate tests.")
    n_tests: int = param(
        32, "Random offset pairs (u, v) drawn per leaf (>= 1), each with n_thresholds thresholds: "
            "the leaf's candidate tests (eq. 3.6) are n_tests x n_thresholds.")
    n_thresholds: int = param(
        4, "Random thresholds per offset pair (>= 1), uniform in +-2 kappa (the range of a clipped "
           "test, eq. 3.6).")
    alpha: float = param(
        300.0, "alpha: a leaf splits only after it has seen more than this many samples (>= 0, "
               "Poisson-weighted, its own samples, not those handed down).")
    beta: float = param(
        0.0, "beta: ... and only on a test whose information gain (eq. 3.2, nats) exceeds this (>= 0).")
    poisson_lambda: float = param(
        1.0, "lambda of online bagging (>= 0): each tree takes each sample k ~ Poisson(lambda) times "
             "(alg. 6).")
    negatives: str = param(
        "hard", "Negatives of background frames: 'hard' = drawn around each class's density maximum "
                "of the current forest (sec. 3.3.2); 'random' = as many, anywhere in the frame.")
    n_frame_negatives: int = param(
        256, "N_neg (>= 0): negatives drawn on a background frame per gesture class whose density "
             "maximum is 1; round(N_neg * max p) for a maximum max p.")
    hard_half_size_px_m: float = param(
        40.0, "Half side (pixel*metres, > 0) of the square around a density maximum m_c in which its "
              "negatives are drawn: value/d pixels at m_c's depth d (40 = +-20 px at 2 m).")
    stride: int = param(4, "Grid step (pixels, 1 to 64) of the forest votes on background frames, as the detector's.")
    parzen_sigma_px: float = param(
        6.0, "Standard deviation (pixels, >= 0) of the Parzen kernel of those votes, as the detector's.")

    def __post_init__(self):
        _check([(self.n_trees >= 1, "n_trees must be >= 1"),
                (1 <= self.max_depth <= 64, "max_depth must be in [1, 64]"),
                (self.n_tests >= 1 and self.n_thresholds >= 1, "need n_tests, n_thresholds >= 1"),
                (self.alpha >= 0.0 and self.beta >= 0.0, "need alpha >= 0 and beta >= 0"),
                (self.poisson_lambda >= 0.0, "poisson_lambda must be >= 0"),
                (self.negatives in NEGATIVE_MODES, f"negatives must be one of {NEGATIVE_MODES}"),
                (self.n_frame_negatives >= 0, "n_frame_negatives must be >= 0"),
                (self.hard_half_size_px_m > 0.0, "hard_half_size_px_m must be > 0"),
                (1 <= self.stride <= 64, "stride must be in [1, 64]"),
                (self.parzen_sigma_px >= 0.0, "parzen_sigma_px must be >= 0")],
               "OnlineParams")

    @property
    def n_candidates(self) -> int:
        """Candidate tests per leaf (offset pairs x thresholds)."""
        return self.n_tests * self.n_thresholds


@dataclass(frozen=True)
class OnlineTrainParams:
    """Everything the online trainer (:mod:`hmocap_ros.gestures.online_forest`) needs besides data."""

    depth: DepthFormat = field(default_factory=DepthFormat)
    features: FeatureParams = field(default_factory=FeatureParams)
    patches: PatchParams = field(default_factory=PatchParams)
    online: OnlineParams = field(default_factory=OnlineParams)

    def __post_init__(self):
        _check([(self.depth.max_depth_m < self.features.background_depth_m,
                 "depth.max_depth_m must be below features.background_depth_m")], "OnlineTrainParams")

    def for_focal(self, focal_px: float) -> "OnlineTrainParams":
        """These parameters with the pixel sizes, given for f = :data:`REFERENCE_FOCAL_PX`, scaled
        to a camera of focal length ``focal_px`` (as :meth:`TrainParams.for_focal`)."""
        s = float(focal_px) / REFERENCE_FOCAL_PX
        f, p, o = self.features, self.patches, self.online
        return replace(self, features=replace(f, patch_half_size_px_m=f.patch_half_size_px_m * s),
                       patches=replace(p, box_half_size_px_m=p.box_half_size_px_m * s,
                                       near_half_size_px_m=p.near_half_size_px_m * s),
                       online=replace(o, hard_half_size_px_m=o.hard_half_size_px_m * s,
                                      stride=int(min(64, max(1, round(o.stride * s)))),
                                      parzen_sigma_px=o.parzen_sigma_px * s))


def train_params_for_focal(focal_px: float, *, n_trees: int = 15, max_depth: int = 20,
                           kappa_m: float | None = 0.15, boosted: bool = True,
                           samples_per_class: int = 10000, mining_rounds: int = 1,
                           located_share: float = 1.0) -> TrainParams:
    """The default training parameters with the pixel sizes scaled from f = 525 px to
    ``focal_px`` (:meth:`TrainParams.for_focal`); ``kappa_m`` None = plain tests (eq. 3.3), else
    clipped tests (eq. 3.6)."""
    features = FeatureParams(feature_type="plain" if kappa_m is None else "clipped",
                             kappa_m=FeatureParams().kappa_m if kappa_m is None else float(kappa_m))
    forest = ForestParams(n_trees=n_trees, max_depth=max_depth, boosted=boosted,
                          samples_per_class=samples_per_class, mining_rounds=mining_rounds,
                          located_share=located_share)
    return TrainParams(features=features, forest=forest).for_focal(focal_px)
