"""``hmocap eval gestures``: precision-recall and average precision per gesture on a depth bag.

Runs :class:`~hmocap_ros.gestures.GestureDetector` (the code of the ``gesture_detection`` node)
over the frames of an annotated bag in stamp order and scores its detections as in thesis
sec. 3.2.6: a detection is correct when it has the ground-truth class and lies within 10 pixels
of the annotated reference point. The 10 px are those of a 640x480 image; at other sizes the
tolerance scales with the image width (5 px at 320x240). Frames whose reference point is
hidden (``position_valid`` false) neither reward nor penalise: their detections are ignored.

Per gesture, the detections of all frames are ranked by score (the smoothed vote density at
the maximum, sec. 3.2.4); sweeping the score threshold gives the precision-recall curve, and
the average precision is its all-point interpolated area (precision made monotone from the
right, summed over the recall steps). A detection in a frame of another gesture or of no
gesture (including the transitions between gestures) is a false positive; a frame's gesture
found by no correct detection is a miss. The detector runs with ``min_score`` and
``min_volume`` lowered (:data:`SWEEP_MIN_SCORE`) so the sweep reaches low thresholds;
everything else is the node's defaults, with the forest's offsets and the pixel sizes
rescaled to the bag's focal length (``GestureDetector(..., focal_px=...)``), so one forest
serves 320x240 and 640x480 cameras.

Also here: :func:`read_gesture_bag` / :func:`read_gesture_bags`, the one reader of annotated
depth bags that training (``hmocap train gestures``) shares.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hmocap_ros.gestures.detection import GestureDetector
from hmocap_ros.gestures.forest_file import ForestFileError, load_forest
from hmocap_ros.gestures.params import DetectorParams
from hmocap_ros.gestures.trees import Forest
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader, BagReadError
from hmocap_ros.io.conversions import image_to_numpy

__all__ = ["DEFAULT_MODEL", "GestureBag", "GestureBagError", "SWEEP_MIN_SCORE", "average_precision",
           "evaluate_gestures", "read_gesture_bag", "read_gesture_bags", "add_arguments", "main_from_args"]

DEFAULT_MODEL = Path(__file__).resolve().parents[1] / "data" / "gesture_forest.npz"
REFERENCE_WIDTH = 640
#: Localization tolerance of thesis sec. 3.2.6, in pixels of a 640x480 image.
TOLERANCE_PX_640 = 10.0
#: Detector thresholds during evaluation: low, so the score sweep covers the whole curve.
SWEEP_MIN_SCORE = 0.02


class GestureBagError(ValueError):
    """An annotated depth bag that cannot be read (missing topics, no camera_info, mixed sizes)."""


@dataclass
class GestureBag:
    """Depth frames of one camera with their gesture ground truth, in stamp order.

    ``depth`` (F, H, W) raw images as stored (16UC1 mm); ``labels[i]`` ``(class_id, u, v)`` or
    None (background); ``visible[i]`` false where a gesture's reference point is hidden.
    """

    depth: np.ndarray
    stamps_ns: np.ndarray
    labels: list
    visible: np.ndarray
    focal_px: float
    class_names: tuple
    sources: list

    @property
    def height(self) -> int:
        return int(self.depth.shape[1])

    @property
    def width(self) -> int:
        return int(self.depth.shape[2])

    @property
    def trainable(self) -> np.ndarray:
        """Frames usable for training and scoring: background or a visible reference point."""
        return self.visible.copy()


def _class_names(names_by_id: dict) -> tuple:
    from hmocap_ros.sim.gesture_set import GESTURE_CLASSES

    n = max([len(GESTURE_CLASSES)] + list(names_by_id))
    return ("background",) + tuple(names_by_id.get(c, GESTURE_CLASSES[c - 1] if c <= len(GESTURE_CLASSES)
                                                    else f"gesture_{c}") for c in range(1, n + 1))


def read_gesture_bag(path, frame_fn: Callable[[np.ndarray], np.ndarray] | None = None) -> GestureBag:
    """Depth frames, camera focal length and gesture ground truth of one bag (``hmocap sim gestures``
    layout), matched by ``header.stamp``; see :func:`read_gesture_bags` for ``frame_fn``."""
    return read_gesture_bags([path], frame_fn)


def _depth_count(path: Path) -> int:
    with BagReader(path) as reader:
        info = reader.topics().get(topics.DEPTH_IMAGE)
        return info.count if info is not None else 0


def read_gesture_bags(paths, frame_fn: Callable[[np.ndarray], np.ndarray] | None = None) -> GestureBag:
    """Several bags of one camera (same size and focal length) concatenated in the given order.

    The frames go into one array allocated once (from the bags' message counts): a training set
    of thousands of 640x480 frames is held once, never copied. ``frame_fn``, when given, maps
    each raw image as it is read (e.g. to float32 metres for training, so the raw stack is
    never held at all); ``depth`` then holds its results.
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise GestureBagError("no bag given")
    wanted = [topics.DEPTH_IMAGE, topics.DEPTH_INFO, topics.GT_GESTURES]
    depth = None
    n = 0
    stamps, labels, visible, names, focal, sources = [], [], [], {}, None, []
    first_path = None
    try:
        capacity = sum(_depth_count(p) for p in paths)
        for path in paths:
            sources.append(str(path))
            n_bag = 0
            with BagReader(path) as reader:
                for stamp, msgs in reader.frame_sets(wanted):
                    fx = float(msgs[topics.DEPTH_INFO].k[0])
                    if fx <= 0:
                        raise GestureBagError(f"{path}: camera_info has no focal length (K[0] = {fx})")
                    if focal is None:
                        focal, first_path = fx, path
                    elif abs(fx - focal) > 1e-6 * focal:
                        raise GestureBagError(f"{path}: focal length {fx:g} differs from {focal:g} "
                                              f"({first_path})")
                    img = image_to_numpy(msgs[topics.DEPTH_IMAGE])
                    if frame_fn is not None:
                        img = frame_fn(img)
                    if depth is None:
                        depth = np.empty((capacity,) + img.shape, img.dtype)
                    elif img.shape != depth.shape[1:]:
                        raise GestureBagError(f"{path}: image size {img.shape[::-1]} differs from "
                                              f"{depth.shape[:0:-1]} ({first_path})")
                    if n == depth.shape[0]:  # more frame sets than depth messages cannot happen
                        raise GestureBagError(f"{path}: more frames than depth images")
                    depth[n] = img
                    n += 1
                    n_bag += 1
                    stamps.append(stamp)
                    gestures = list(msgs[topics.GT_GESTURES].gestures)
                    if gestures:
                        g = gestures[0]
                        names[int(g.class_id)] = str(g.name)
                        labels.append((int(g.class_id), float(g.u), float(g.v)))
                        visible.append(bool(g.position_valid))
                    else:
                        labels.append(None)
                        visible.append(True)
            if n_bag == 0:
                raise GestureBagError(f"{path}: no frame with depth image, camera_info and gesture ground truth")
    except BagReadError as err:
        raise GestureBagError(str(err)) from err
    except FileNotFoundError as err:
        raise GestureBagError(f"{err.filename}: no such bag") from err
    # A prefix of a C-contiguous array is C-contiguous: no copy.
    return GestureBag(depth[:n], np.asarray(stamps, np.int64), labels, np.asarray(visible, bool),
                      float(focal), _class_names(names), sources)


def average_precision(scores, correct, n_positives: int) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """All-point interpolated AP of ranked detections: (ap, precision, recall, score thresholds)."""
    scores = np.asarray(scores, float)
    correct = np.asarray(correct, bool)
    order = np.argsort(-scores, kind="stable")
    tp = np.cumsum(correct[order])
    fp = np.cumsum(~correct[order])
    recall = tp / max(n_positives, 1)
    precision = tp / np.maximum(tp + fp, 1)
    if n_positives == 0 or scores.size == 0:
        return 0.0, precision, recall, scores[order]
    envelope = np.maximum.accumulate(precision[::-1])[::-1]
    steps = np.diff(np.concatenate([[0.0], recall]))
    return float(np.sum(envelope * steps)), precision, recall, scores[order]


def evaluate_gestures(data: GestureBag, forest: Forest, params: DetectorParams | None = None) -> dict:
    """Run the detector over ``data`` in order and score it (module docstring); a JSON-able dict."""
    if params is None:
        params = DetectorParams(min_score=SWEEP_MIN_SCORE, min_volume=0.0)
    detector = GestureDetector(forest, params, focal_px=data.focal_px)
    tolerance = TOLERANCE_PX_640 * data.width / REFERENCE_WIDTH
    n_gestures = forest.n_classes - 1
    scores = [[] for _ in range(n_gestures)]
    correct = [[] for _ in range(n_gestures)]
    positives = np.zeros(n_gestures, int)
    seconds = 0.0
    for i in range(len(data.labels)):
        t0 = time.perf_counter()
        detections = detector.update(data.depth[i], int(data.stamps_ns[i]))
        seconds += time.perf_counter() - t0
        if not data.visible[i]:
            continue
        label = data.labels[i]
        if label is not None and 1 <= label[0] <= n_gestures:
            positives[label[0] - 1] += 1
        for det in detections:
            hit = (label is not None and det.class_id == label[0]
                   and np.hypot(det.u - label[1], det.v - label[2]) <= tolerance)
            scores[det.class_id - 1].append(det.score)
            correct[det.class_id - 1].append(bool(hit))
    per_class = {}
    for k in range(n_gestures):
        ap, precision, recall, thresholds = average_precision(scores[k], correct[k], int(positives[k]))
        per_class[forest.class_names[k + 1]] = {
            "ap": ap, "positives": int(positives[k]), "detections": len(scores[k]),
            "true_positives": int(np.sum(correct[k])),
            "pr": {"precision": precision.round(4).tolist(), "recall": recall.round(4).tolist(),
                   "score": np.round(thresholds, 4).tolist()},
        }
    aps = [c["ap"] for c in per_class.values() if c["positives"] > 0]
    n = len(data.labels)
    return {
        "bags": data.sources,
        "frames": n,
        "scored_frames": int(data.visible.sum()),
        "image_size": [data.width, data.height],
        "focal_px": data.focal_px,
        "model_focal_px": forest.training_focal_px,
        "offset_scale": detector.offset_scale,
        "criterion": f"correct class and location within {tolerance:g} px "
                     f"(10 px at 640x480, scaled by width {data.width}/640)",
        "tolerance_px": tolerance,
        "per_class": per_class,
        "mean_ap": float(np.mean(aps)) if aps else 0.0,
        "fps": n / seconds if seconds > 0 else 0.0,
        "detector_params": dataclasses.asdict(detector.active_params),
    }


def plot_pr(result: dict, path, title: str = "") -> None:
    """Precision-recall curves per gesture into a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 5))
    for name, c in result["per_class"].items():
        if c["positives"]:
            ax.plot([0.0] + c["pr"]["recall"], [1.0] + c["pr"]["precision"], label=f"{name} (AP {c['ap']:.2f})")
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_xlim(0, 1.01)
    ax.set_ylim(0, 1.01)
    ax.grid(alpha=0.3)
    ax.set_title(title or f"mean AP {result['mean_ap']:.3f}, {result['criterion']}", fontsize=8)
    ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="annotated depth bag (hmocap sim gestures layout)")
    parser.add_argument("--model", default=str(DEFAULT_MODEL),
                        help="gesture forest (.npz; default: the shipped hmocap_ros/data/gesture_forest.npz)")
    parser.add_argument("--json", required=True, help="write the results (JSON) here")
    parser.add_argument("--plot", help="write the precision-recall curves (PNG) here")


def main_from_args(ns) -> int:
    try:
        forest = load_forest(ns.model)
    except (ForestFileError, OSError) as err:
        print(f"error: cannot load the gesture forest {ns.model}: {err}", file=sys.stderr)
        return 2
    try:
        data = read_gesture_bag(ns.bag)
    except GestureBagError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    result = evaluate_gestures(data, forest)
    result["model"] = str(ns.model)
    Path(ns.json).write_text(json.dumps(result, indent=1) + "\n")
    if ns.plot:
        plot_pr(result, ns.plot)
    for name, c in result["per_class"].items():
        print(f"  {name:10s} AP {c['ap']:.3f}  ({c['true_positives']}/{c['positives']} found, "
              f"{c['detections']} detections)")
    print(f"mean AP {result['mean_ap']:.3f} over {result['scored_frames']} scored frames "
          f"({result['criterion']}); {result['fps']:.1f} frames/s")
    return 0
