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

**False detections** (``false_detections``): what the node would report wrongly at its own
thresholds (``min_score``, ``min_volume``, and a taught gesture's threshold from the forest
file), from the same run (:func:`~hmocap_ros.gestures.detection.node_detections` on each
frame's candidates): a gesture detected in a frame of another gesture or of none, or away from
the annotated point. Reported as the fraction of scored frames with one, and as events per
minute (a gesture falsely detected in a frame where it was not in the frame before). On a bag
without gestures (near misses, everyday motion) every detection is false: the measure of
near-miss refusal and of the taught thresholds.

Without ground truth (a bag with no ``/ground_truth/gestures``, e.g. a recording of a real
camera, or ``--no-truth``), :func:`detect_gestures` runs the detector with the node's settings
(``DetectorParams`` defaults and ``--param`` overrides) over the depth frames of ``--depth-topic``
in stamp order, streaming (one frame held at a time), and the JSON holds what the
``gesture_detection`` node would have published: the detections of every frame (stamp,
gesture, score, volume, pixel and depth) and a summary (frames, frames with a detection,
detections and mean score per gesture). The CameraInfo beside the depth topic gives the focal
length; without one the camera is taken for the forest's training camera at the image width.

Also here: :func:`read_gesture_bag` / :func:`read_gesture_bags`, the one reader of annotated
depth bags that training (``hmocap train gestures``) shares, and
:func:`~hmocap_ros.gestures.depth_units.implausible_depth`, the depth-unit check of the node and
of the detections.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from hmocap_ros.gestures.depth_units import implausible_depth
from hmocap_ros.gestures.detection import GestureDetector, node_detections, suppress_other_classes
from hmocap_ros.gestures.params import DetectorParams
from hmocap_ros.gestures.trees import Forest
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader, BagReadError
from hmocap_ros.io.conversions import ConversionError, image_to_numpy
from hmocap_ros.io.msg_factory import stamp_to_ns

__all__ = ["DEFAULT_MODEL", "DetectorRun", "GestureBag", "GestureBagError", "SWEEP_MIN_SCORE",
           "average_precision", "detect_gestures", "evaluate_gestures", "false_detections", "run_detector", "score_run",
           "read_gesture_bag",
           "read_gesture_bags"]

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
    None (background); ``visible[i]`` false where a gesture's reference point is hidden;
    ``near_misses[i]`` ``(missed class_id, u, v)`` on a near-miss frame of a bag with
    ``/ground_truth/near_misses``, else None.
    """

    depth: np.ndarray
    stamps_ns: np.ndarray
    labels: list
    visible: np.ndarray
    focal_px: float
    class_names: tuple
    sources: list
    near_misses: list | None = None

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
    from hmocap_ros.gestures.classes import ALL_GESTURES, GESTURE_CLASSES

    n = max([len(GESTURE_CLASSES)] + list(names_by_id))
    return ("background",) + tuple(names_by_id.get(c, ALL_GESTURES[c - 1] if c <= len(ALL_GESTURES)
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
    depth: np.ndarray | None = None
    n = 0
    labels: list[tuple[int, float, float] | None]
    stamps, labels, visible, names, focal, sources = [], [], [], {}, None, []
    near: list[tuple[int, float, float] | None] = []
    first_path = None
    try:
        capacity = sum(_depth_count(p) for p in paths)
        for path in paths:
            sources.append(str(path))
            n_bag = 0
            with BagReader(path) as reader:
                with_near = wanted + [topics.GT_NEAR_MISSES] * (topics.GT_NEAR_MISSES in reader.topics())
                for stamp, msgs in reader.frame_sets(with_near):
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
                    misses = list(msgs[topics.GT_NEAR_MISSES].gestures) if topics.GT_NEAR_MISSES in msgs else []
                    near.append((int(misses[0].class_id), float(misses[0].u), float(misses[0].v))
                                if misses and not gestures and misses[0].position_valid else None)
            if n_bag == 0:
                raise GestureBagError(f"{path}: no frame with depth image, camera_info and gesture ground truth")
    except BagReadError as err:
        raise GestureBagError(str(err)) from err
    except FileNotFoundError as err:
        raise GestureBagError(f"{err.filename}: no such bag") from err
    assert depth is not None and focal is not None  # each bag gave a frame (n_bag > 0), paths is not empty
    # A prefix of a C-contiguous array is C-contiguous: no copy.
    return GestureBag(depth[:n], np.asarray(stamps, np.int64), labels, np.asarray(visible, bool),
                      float(focal), _class_names(names), sources, near)


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


def _minutes(stamps_ns: np.ndarray) -> float:
    """Minutes a sequence of stamps covers: the frame periods summed, a gap (a cut between rooms,
    more than twice the median period) counted as one period."""
    if stamps_ns.size < 2:
        return 0.0
    gaps = np.diff(stamps_ns.astype(np.float64))
    period = float(np.median(gaps))
    return float(np.minimum(gaps, period).sum() + period) / 60e9 if period > 0 else 0.0


def false_detections(records: list, n_frames: int, minutes: float, class_names: tuple) -> dict:
    """False detections at the node's thresholds from per-frame records ``(frame, class_id,
    false)`` of the scored frames: frames with at least one, their fraction, and events (a
    gesture falsely detected in a frame where it was not falsely detected in the frame before:
    what an application reacting to detections sees) per minute, overall and per gesture."""
    frames = {f for f, _, bad in records if bad}
    per_class, events = {}, 0
    for c, name in enumerate(class_names[1:], start=1):
        bad = sorted({f for f, cid, b in records if b and cid == c})
        onsets = sum(1 for k, f in enumerate(bad) if k == 0 or bad[k - 1] != f - 1)
        events += onsets
        per_class[name] = {"frames": len(bad), "events": onsets,
                           "events_per_minute": onsets / minutes if minutes > 0 else 0.0}
    return {"frames": len(frames), "scored_frames": int(n_frames),
            "per_frame": len(frames) / n_frames if n_frames else 0.0, "events": events, "minutes": minutes,
            "events_per_minute": events / minutes if minutes > 0 else 0.0, "per_class": per_class}


@dataclass
class DetectorRun:
    """The detector run over an annotated bag once (:func:`run_detector`): per frame the
    localized candidates (:attr:`GestureDetector.candidates`, before suppression) at the run's
    thresholds; what :func:`score_run` scores at any thresholds at or above them."""

    candidates: list
    active_params: DetectorParams
    offset_scale: float
    seconds: float


def run_detector(data: GestureBag, forest: Forest, params: DetectorParams | None = None) -> DetectorRun:
    """Run the detector (the node's code) over ``data`` in stamp order, at the sweep thresholds
    (:data:`SWEEP_MIN_SCORE`, no volume test) unless ``params`` are given."""
    if params is None:
        params = DetectorParams(min_score=SWEEP_MIN_SCORE, min_volume=0.0)
    detector = GestureDetector(forest, params, focal_px=data.focal_px)
    candidates, seconds = [], 0.0
    for i in range(len(data.labels)):
        t0 = time.perf_counter()
        detector.update(data.depth[i], int(data.stamps_ns[i]))
        seconds += time.perf_counter() - t0
        candidates.append(list(detector.candidates))
    return DetectorRun(candidates, detector.active_params, detector.offset_scale, seconds)


def score_run(data: GestureBag, forest: Forest, run: DetectorRun, node_params: DetectorParams | None = None,
              thresholds: dict | None = None) -> dict:
    """Precision-recall and AP per gesture of a :class:`DetectorRun` (module docstring), and its
    false detections at ``node_params``' thresholds (default the node's) with the per-gesture
    ``thresholds`` (default the forest's taught ones, as the node's ``use_taught_thresholds``)."""
    node_params = node_params if node_params is not None else DetectorParams()
    swept = run.active_params
    if node_params.min_score < swept.min_score or node_params.min_volume < swept.min_volume:
        raise ValueError("the node's thresholds must not be below the run's")
    taught = ({str(k): float(v) for k, v in forest.meta.get("gesture_thresholds", {}).items()}
              if thresholds is None else dict(thresholds))
    tolerance = TOLERANCE_PX_640 * data.width / REFERENCE_WIDTH
    n_gestures = forest.n_classes - 1
    scores: list[list[float]] = [[] for _ in range(n_gestures)]
    correct: list[list[bool]] = [[] for _ in range(n_gestures)]
    positives = np.zeros(n_gestures, int)
    found = np.zeros(n_gestures, int)
    at_node = []
    scaled = replace(swept, min_score=node_params.min_score, min_volume=node_params.min_volume)

    def hit(det, label) -> bool:
        return bool(label is not None and det.class_id == label[0]
                    and np.hypot(det.u - label[1], det.v - label[2]) <= tolerance)

    for i, candidates in enumerate(run.candidates):
        if not data.visible[i]:
            continue
        label = data.labels[i]
        if label is not None and 1 <= label[0] <= n_gestures:
            positives[label[0] - 1] += 1
        for det in suppress_other_classes(candidates, swept.suppression_radius_px_m):
            scores[det.class_id - 1].append(det.score)
            correct[det.class_id - 1].append(hit(det, label))
        reported = node_detections(candidates, scaled, taught)
        at_node += [(i, d.class_id, not hit(d, label)) for d in reported]
        if label is not None and 1 <= label[0] <= n_gestures and any(hit(d, label) for d in reported):
            found[label[0] - 1] += 1
    per_class: dict[str, dict[str, Any]] = {}
    for k in range(n_gestures):
        ap, precision, recall, score_steps = average_precision(scores[k], correct[k], int(positives[k]))
        per_class[forest.class_names[k + 1]] = {
            "ap": ap, "positives": int(positives[k]), "detections": len(scores[k]),
            "true_positives": int(np.sum(correct[k])), "found_at_node_thresholds": int(found[k]),
            "pr": {"precision": precision.round(4).tolist(), "recall": recall.round(4).tolist(),
                   "score": np.round(score_steps, 4).tolist()},
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
        "offset_scale": run.offset_scale,
        "criterion": f"correct class and location within {tolerance:g} px "
                     f"(10 px at 640x480, scaled by width {data.width}/640)",
        "tolerance_px": tolerance,
        "per_class": per_class,
        "mean_ap": float(np.mean(aps)) if aps else 0.0,
        "false_detections": false_detections(at_node, int(data.visible.sum()), _minutes(data.stamps_ns),
                                             forest.class_names),
        "node_thresholds": {"min_score": node_params.min_score, "min_volume": node_params.min_volume,
                            "taught": taught},
        "fps": n / run.seconds if run.seconds > 0 else 0.0,
        "detector_params": dataclasses.asdict(swept),
    }


def evaluate_gestures(data: GestureBag, forest: Forest, params: DetectorParams | None = None,
                      node_params: DetectorParams | None = None) -> dict:
    """Run the detector over ``data`` in order and score it (module docstring); a JSON-able dict.

    ``node_params`` (default :class:`DetectorParams`' defaults, the node's): the thresholds at
    which ``false_detections`` counts what the ``gesture_detection`` node would report wrongly
    (:func:`~hmocap_ros.gestures.detection.node_detections`, with the forest's taught thresholds
    as the node's ``use_taught_thresholds``): a detection of a gesture in a frame of another or
    of none, or away from the annotated point; ``found_at_node_thresholds`` per gesture counts
    the frames whose gesture the node would report where it is."""
    return score_run(data, forest, run_detector(data, forest, params), node_params)


def _info_topic(depth_topic: str) -> str:
    """``camera_info`` beside a depth image topic (``/camera/depth/image_rect_raw`` ->
    ``/camera/depth/camera_info``), as camera drivers publish it."""
    return depth_topic.rsplit("/", 1)[0] + "/camera_info"


def detect_gestures(path, forest: Forest, params: DetectorParams | None = None,
                    depth_topic: str = topics.DEPTH_IMAGE, info_topic: str | None = None) -> dict:
    """The detections of the ``gesture_detection`` node on every frame of ``depth_topic`` of a
    bag with no ground truth (module docstring); a JSON-able dict. ``GestureBagError`` for a
    bag that cannot be read or has no depth frames there."""
    params = params if params is not None else DetectorParams()
    info_topic = info_topic or _info_topic(depth_topic)
    path = Path(path)
    detector = GestureDetector(forest, params)
    frames: list[dict[str, Any]]
    per_class: dict[str, dict[str, Any]]
    frames, per_class, size, focal, warning, notes = [], {}, None, None, "", []
    seconds = 0.0
    try:
        with BagReader(path) as reader:
            available = reader.topics()
            if depth_topic not in available:
                depth_like = sorted(t for t, i in available.items() if i.msgtype == "sensor_msgs/msg/Image")
                raise GestureBagError(f"{path}: no {depth_topic} (image topics: {', '.join(depth_like) or 'none'}); "
                                      f"name the depth topic with --depth-topic")
            if info_topic in available:
                stream = reader.frame_sets([depth_topic, info_topic])
            else:
                notes.append(f"no {info_topic}: the camera is taken for the forest's training camera at "
                             f"the image width, depths and pixels only")
                stream = ((stamp_to_ns(m.msg.header.stamp), {depth_topic: m.msg})
                          for m in reader.messages([depth_topic]))
            for stamp, msgs in stream:
                info = msgs.get(info_topic)
                if info is not None and float(info.k[0]) > 0:
                    focal = float(info.k[0])
                    detector.set_focal(focal)
                try:
                    depth = image_to_numpy(msgs[depth_topic])
                except ConversionError as err:
                    raise GestureBagError(f"{path}: {depth_topic} at stamp {stamp}: {err}") from err
                if size is None:
                    size = [int(depth.shape[1]), int(depth.shape[0])]
                if not warning:
                    warning = implausible_depth(depth, params.depth_format)
                t0 = time.perf_counter()
                try:
                    detections = detector.update(depth, int(stamp))
                except ValueError as err:
                    raise GestureBagError(f"{path}: {depth_topic} at stamp {stamp}: {err}") from err
                seconds += time.perf_counter() - t0
                frames.append({"stamp_ns": int(stamp), "gestures": [
                    {"name": d.name, "class_id": int(d.class_id), "score": round(float(d.score), 4),
                     "volume": round(float(d.volume), 4), "u": round(float(d.u), 2), "v": round(float(d.v), 2),
                     "depth_m": round(float(d.depth_m), 4)} for d in detections]})
                for d in detections:
                    c = per_class.setdefault(d.name, {"detections": 0, "score_sum": 0.0, "first_stamp_ns": int(stamp)})
                    c["detections"] += 1
                    c["score_sum"] += float(d.score)
                    c["last_stamp_ns"] = int(stamp)
    except BagReadError as err:
        raise GestureBagError(str(err)) from err
    except FileNotFoundError as err:
        raise GestureBagError(f"{err.filename}: no such bag") from err
    if not frames:
        raise GestureBagError(f"{path}: no depth frame on {depth_topic}"
                              + (f" with a {info_topic} of the same stamp" if info_topic in available else ""))
    per_gesture = {}
    for name in forest.class_names[1:]:
        seen = per_class.get(name)
        per_gesture[name] = ({"detections": seen["detections"], "frames": seen["detections"],
                              "mean_score": round(seen["score_sum"] / seen["detections"], 4),
                              "first_stamp_ns": seen["first_stamp_ns"], "last_stamp_ns": seen["last_stamp_ns"]}
                             if seen else {"detections": 0, "frames": 0})
    return {
        "mode": "detections",
        "bag": str(path),
        "depth_topic": depth_topic,
        "info_topic": info_topic if info_topic in available else None,
        "image_size": size,
        "focal_px": focal,
        "model_focal_px": forest.training_focal_px,
        "summary": {
            "frames": len(frames),
            "frames_with_detections": sum(1 for f in frames if f["gestures"]),
            "detections": sum(len(f["gestures"]) for f in frames),
            "duration_s": (frames[-1]["stamp_ns"] - frames[0]["stamp_ns"]) * 1e-9,
            "per_gesture": per_gesture,
        },
        "depth_unit_warning": warning,
        "notes": notes,
        "fps": len(frames) / seconds if seconds > 0 else 0.0,
        "detector_params": dataclasses.asdict(detector.active_params),
        "per_frame": frames,
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
