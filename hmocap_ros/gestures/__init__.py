"""Gesture localization on depth images with random forests (thesis ch. 3, sec. 3.2).

- :mod:`~hmocap_ros.gestures.depth_features`: depth binary tests, plain (eq. 3.3) and
  depth-clipped (eq. 3.6), and raw depth -> metres (or compact millimetres for training).
- :mod:`~hmocap_ros.gestures.patches`: patch (sample) collection from annotated frames, and
  hard negative mining by detection on the training frames.
- :mod:`~hmocap_ros.gestures.trees`: the forest model (flat node arrays), shared with online forests.
- :mod:`~hmocap_ros.gestures.tree_growth`: growth of one offline tree by information gain
  (sec. 3.2.1, eq. 3.2).
- :mod:`~hmocap_ros.gestures.forest`: offline forest training: boosted tree-by-tree learning
  (sec. 3.2.3) and hard negative mining rounds.
- :mod:`~hmocap_ros.gestures.detection`: per-frame localization: votes, Parzen density,
  temporal smoothing (eq. 3.4), volume test (eq. 3.5).
- :mod:`~hmocap_ros.gestures.forest_file`: the versioned ``.npz`` forest file format.
- :mod:`~hmocap_ros.gestures.online_forest` and :mod:`~hmocap_ros.gestures.online_statistics`:
  online random forests (sec. 3.3.1, alg. 6): Poisson bagging, leaf statistics, splits.
- :mod:`~hmocap_ros.gestures.hard_negatives`: hard negatives mined on the fly (sec. 3.3.2).
- :mod:`~hmocap_ros.gestures.trainer`: the interactive trainer's state machine (sec. 3.4.1).
- :mod:`~hmocap_ros.gestures.trainer_feedback`: the trainer's feedback picture (fig. 3.11).
- :mod:`~hmocap_ros.gestures.file_watch`: a forest file replaced on disk, noticed by the detector.
- :mod:`~hmocap_ros.gestures.depth_units`: whether a depth stream is in the unit it is read with.

Typical use::

    params = TrainParams().for_focal(camera_fx)  # pixel sizes are given for f = 525 px
    forest = train_forest(depth_frames, labels, params, np.random.default_rng(0))
    forest.meta["training"]["focal_px"] = camera_fx  # lets detectors rescale to other cameras
    save_forest(forest, "gestures.forest.npz")
    detector = GestureDetector(load_forest("gestures.forest.npz"), DetectorParams(), focal_px=camera_fx)
    for depth, stamp_ns in stream:
        for det in detector.update(depth, stamp_ns):
            print(det.name, det.u, det.v, det.depth_m, det.score)
"""

from hmocap_ros.gestures.depth_features import depth_to_metres, evaluate_tests, random_offsets
from hmocap_ros.gestures.detection import Detection, GestureDetector
from hmocap_ros.gestures.forest import TreeReport, train_forest, train_forest_on_frames, train_forest_on_samples
from hmocap_ros.gestures.forest_file import ForestFileError, load_forest, read_header, save_forest
from hmocap_ros.gestures.online_forest import OnlineForest, train_online_on_frames
from hmocap_ros.gestures.params import (
    DepthFormat,
    DetectorParams,
    FeatureParams,
    ForestParams,
    OnlineParams,
    OnlineTrainParams,
    PatchParams,
    TrainParams,
)
from hmocap_ros.gestures.patches import SampleSet, collect_samples, mine_hard_negatives
from hmocap_ros.gestures.tree_growth import grow_tree
from hmocap_ros.gestures.trees import Forest, PendingTests, Tree

__all__ = [
    "DepthFormat", "Detection", "DetectorParams", "FeatureParams", "Forest", "ForestFileError", "ForestParams",
    "GestureDetector", "OnlineForest", "OnlineParams", "OnlineTrainParams", "PatchParams", "PendingTests", "SampleSet",
    "TrainParams", "Tree", "TreeReport",
    "collect_samples", "depth_to_metres", "evaluate_tests", "grow_tree", "load_forest", "mine_hard_negatives",
    "random_offsets", "read_header", "save_forest", "train_forest", "train_forest_on_frames",
    "train_forest_on_samples", "train_online_on_frames",
]
