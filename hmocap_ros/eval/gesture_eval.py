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
right, summed over the recall steps). The detector runs with ``min_score`` and ``min_volume``
lowered (:data:`SWEEP_MIN_SCORE`) so the sweep reaches low thresholds; everything else is the
node's defaults with the pixel sizes scaled by ``fx / 525``.

A forest records the focal length it was trained at (``meta["training"]["focal_px"]``, written
by ``hmocap train gestures``); on a bag with another focal length its test offsets
(pixel*metres) are rescaled by the ratio, so one forest serves 320x240 and 640x480 cameras.

Also here: :func:`read_gesture_bag`, the one reader of annotated depth bags that training
(``hmocap train gestures``) shares.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hmocap_ros.gestures.detection import GestureDetector
from hmocap_ros.gestures.forest_file import ForestFileError, load_forest
from hmocap_ros.gestures.params import DetectorParams
from hmocap_ros.gestures.trees import Forest, Tree
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader, BagReadError
from hmocap_ros.io.conversions import image_to_numpy

__all__ = ["DEFAULT_MODEL", "GestureBag", "GestureBagError", "SWEEP_MIN_SCORE", "average_precision",
           "detector_params_for_focal", "evaluate_gestures", "forest_for_focal", "read_gesture_bag",
           "read_gesture_bags", "add_arguments", "main_from_args"]

DEFAULT_MODEL = Path(__file__).resolve().parents[1] / "data" / "gesture_forest.npz"
#: Focal length (px) the pixel*metre defaults of ``hmocap_ros.gestures.params`` are tuned for.
REFERENCE_FOCAL_PX = 525.0
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


def read_gesture_bag(path) -> GestureBag:
    """Depth frames, camera focal length and gesture ground truth of one bag (``hmocap sim gestures``
    layout), matched by ``header.stamp``."""
    path = Path(path)
    wanted = [topics.DEPTH_IMAGE, topics.DEPTH_INFO, topics.GT_GESTURES]
    depth, stamps, labels, visible, names, focal = [], [], [], [], {}, None
    try:
        with BagReader(path) as reader:
            for stamp, msgs in reader.frame_sets(wanted):
                info = msgs[topics.DEPTH_INFO]
                fx = float(info.k[0])
                if fx <= 0:
                    raise GestureBagError(f"{path}: camera_info has no focal length (K[0] = {fx})")
                if focal is None:
                    focal = fx
                elif abs(fx - focal) > 1e-6 * focal:
                    raise GestureBagError(f"{path}: focal length changes within the bag")
                img = image_to_numpy(msgs[topics.DEPTH_IMAGE])
                if depth and img.shape != depth[0].shape:
                    raise GestureBagError(f"{path}: image size changes within the bag")
                gestures = list(msgs[topics.GT_GESTURES].gestures)
                depth.append(img)
                stamps.append(stamp)
                if gestures:
                    g = gestures[0]
                    names[int(g.class_id)] = str(g.name)
                    labels.append((int(g.class_id), float(g.u), float(g.v)))
                    visible.append(bool(g.position_valid))
                else:
                    labels.append(None)
                    visible.append(True)
    except BagReadError as err:
        raise GestureBagError(str(err)) from err
    except FileNotFoundError as err:
        raise GestureBagError(f"{path}: no such bag") from err
    if not depth:
        raise GestureBagError(f"{path}: no frame with depth image, camera_info and gesture ground truth")
    return GestureBag(np.stack(depth), np.asarray(stamps, np.int64), labels, np.asarray(visible, bool),
                      float(focal), _class_names(names), [str(path)])


def read_gesture_bags(paths) -> GestureBag:
    """Several bags of one camera (same size and focal length) concatenated in the given order."""
    bags = [read_gesture_bag(p) for p in paths]
    first = bags[0]
    for b in bags[1:]:
        if b.depth.shape[1:] != first.depth.shape[1:] or abs(b.focal_px - first.focal_px) > 1e-6 * first.focal_px:
            raise GestureBagError(f"{b.sources[0]}: {b.width}x{b.height} fx {b.focal_px} differs from "
                                  f"{first.sources[0]}: {first.width}x{first.height} fx {first.focal_px}")
    names = dict(enumerate(first.class_names))
    for b in bags[1:]:
        for c, n in enumerate(b.class_names):
            names.setdefault(c, n)
    return GestureBag(np.concatenate([b.depth for b in bags]), np.concatenate([b.stamps_ns for b in bags]),
                      sum((b.labels for b in bags), []), np.concatenate([b.visible for b in bags]),
                      first.focal_px, tuple(names[c] for c in sorted(names)), sum((b.sources for b in bags), []))


def forest_for_focal(forest: Forest, focal_px: float) -> tuple[Forest, float]:
    """``forest`` with its test offsets rescaled from its training focal length to ``focal_px``
    (offsets are pixel*metres: they scale with f); returns (forest, factor). A forest without a
    recorded focal length is used as is."""
    trained = forest.meta.get("training", {}).get("focal_px")
    if not trained:
        return forest, 1.0
    s = float(focal_px) / float(trained)
    if abs(s - 1.0) < 1e-6:
        return forest, 1.0
    trees = [Tree((t.feature * np.float32(s)).astype(np.float32), t.threshold, t.left, t.right, t.counts, t.depth)
             for t in forest.trees]
    features = dataclasses.replace(forest.features,
                                   patch_half_size_px_m=forest.features.patch_half_size_px_m * s)
    return Forest(trees, forest.class_names, features, forest.kind, forest.meta), s


def detector_params_for_focal(focal_px: float, **overrides) -> DetectorParams:
    """The node's detector defaults with pixel sizes scaled from f = 525 px to ``focal_px``."""
    s = float(focal_px) / REFERENCE_FOCAL_PX
    d = DetectorParams()
    base = dict(stride=max(1, round(d.stride * s)), parzen_sigma_px=d.parzen_sigma_px * s,
                volume_radius_px_m=d.volume_radius_px_m * s,
                suppression_radius_px_m=d.suppression_radius_px_m * s)
    base.update(overrides)
    return DetectorParams(**base)


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
    forest, offset_scale = forest_for_focal(forest, data.focal_px)
    if params is None:
        params = detector_params_for_focal(data.focal_px, min_score=SWEEP_MIN_SCORE, min_volume=0.0)
    detector = GestureDetector(forest, params)
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
        "model_focal_px": forest.meta.get("training", {}).get("focal_px"),
        "offset_scale": offset_scale,
        "criterion": f"correct class and location within {tolerance:g} px "
                     f"(10 px at 640x480, scaled by width {data.width}/640)",
        "tolerance_px": tolerance,
        "per_class": per_class,
        "mean_ap": float(np.mean(aps)) if aps else 0.0,
        "fps": n / seconds if seconds > 0 else 0.0,
        "detector_params": dataclasses.asdict(params),
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
