"""``hmocap eval gestures``: precision-recall and average precision per gesture on a depth bag,
or the detections alone on a bag without ground truth (the evaluation:
:mod:`hmocap_ros.eval.gesture_eval`). ``--set-thresholds OUT`` first chooses each gesture's
threshold from the false-detection and recall curves on the bag and ``--threshold-bags``
(:mod:`hmocap_ros.eval.gesture_thresholds`: validation bags, never the test bags), writes the
forest with them to ``OUT`` and evaluates that forest. Exit status 2 with one line on bad
input; nothing is written then."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from hmocap_ros.eval.gesture_eval import (
    DEFAULT_MODEL,
    SWEEP_MIN_SCORE,
    GestureBagError,
    detect_gestures,
    evaluate_gestures,
    plot_pr,
    read_gesture_bag,
)
from hmocap_ros.eval.gesture_thresholds import gesture_threshold_curves, set_gesture_thresholds
from hmocap_ros.gestures.forest_file import ForestFileError, load_forest, save_forest
from hmocap_ros.gestures.params import DetectorParams
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader, BagReadError
from hmocap_ros.params import field_overrides, from_flat

__all__ = ["add_arguments", "main_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="depth bag: annotated (hmocap sim gestures layout) for precision-recall, "
                                    "or any depth recording for the detections alone")
    parser.add_argument("--model", default=str(DEFAULT_MODEL),
                        help="gesture forest (.npz; default: the shipped hmocap_ros/data/gesture_forest.npz)")
    parser.add_argument("--json", required=True,
                        help="write the results (JSON) here: precision-recall with ground truth, else the "
                             "detections of every frame and their summary")
    parser.add_argument("--plot", help="write the precision-recall curves (PNG) here (with ground truth)")
    parser.add_argument("--no-truth", action="store_true",
                        help="write the detections (as gesture_detection publishes them) even when the bag "
                             "has ground truth; a bag without /ground_truth/gestures gets them anyway")
    parser.add_argument("--depth-topic", default=topics.DEPTH_IMAGE,
                        help=f"depth image topic for the detections (default {topics.DEPTH_IMAGE}); its "
                             "camera_info is the topic beside it")
    parser.add_argument("--param", action="append", metavar="KEY=VALUE",
                        help="a detector setting by name, e.g. depth_unit_m=0.000125 (repeatable; "
                             "gesture_detection --help lists them); with ground truth it applies on top "
                             "of the lowered thresholds of the precision-recall sweep")
    parser.add_argument("--set-thresholds", metavar="OUT",
                        help="choose each gesture's threshold on the annotated bag (and --threshold-bags): the "
                             "lowest at which its false events stay within --max-false-per-minute split over "
                             "the gestures; write the forest with them to OUT (the node uses them) and evaluate it")
    parser.add_argument("--threshold-bags", nargs="+", default=[], metavar="BAG",
                        help="more annotated validation bags pooled with the bag for --set-thresholds (e.g. a "
                             "bag of near misses)")
    parser.add_argument("--max-false-per-minute", type=float, default=1.0,
                        help="the node's false-event budget per minute for --set-thresholds (default 1)")
    parser.add_argument("--min-recall", type=float, default=0.8,
                        help="for --set-thresholds: a gesture whose budget costs more than this share of its "
                             "frames gets the highest threshold that finds this share (default 0.8)")


def _print_detections(result: dict) -> None:
    """The notes, the depth-unit warning and the detections per gesture of a run without truth."""
    summary = result["summary"]
    for note in result["notes"]:
        print(f"note: {note}")
    if result["depth_unit_warning"]:
        print(f"warning: {result['depth_topic']}: {result['depth_unit_warning']}", file=sys.stderr)
    for name, c in summary["per_gesture"].items():
        mean = f", mean score {c['mean_score']:.2f}" if c["detections"] else ""
        print(f"  {name:10s} {c['detections']:5d} detections{mean}")
    print(f"{summary['detections']} detections in {summary['frames_with_detections']} of {summary['frames']} "
          f"frames ({summary['duration_s']:.1f} s of {result['depth_topic']}); {result['fps']:.1f} frames/s")


def main_from_args(ns) -> int:
    try:
        forest = load_forest(ns.model)
    except (ForestFileError, OSError) as err:
        print(f"error: cannot load the gesture forest {ns.model}: {err}", file=sys.stderr)
        return 2
    try:
        overrides = field_overrides(DetectorParams, ns.param, "detector parameter")
        node_params = from_flat(DetectorParams, overrides)
    except (ValueError, TypeError) as err:
        print(f"error: --param: {err}", file=sys.stderr)
        return 2
    try:
        with BagReader(ns.bag) as reader:
            has_truth = topics.GT_GESTURES in reader.topics()
    except BagReadError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except FileNotFoundError as err:
        print(f"error: {err.filename}: no such bag", file=sys.stderr)
        return 2
    if has_truth and not ns.no_truth and ns.depth_topic != topics.DEPTH_IMAGE:
        print(f"error: the ground truth of {ns.bag} belongs to {topics.DEPTH_IMAGE}: add --no-truth to "
              f"detect on {ns.depth_topic}", file=sys.stderr)
        return 2
    if ns.set_thresholds and (ns.no_truth or not has_truth):
        print(f"error: --set-thresholds needs an annotated bag ({topics.GT_GESTURES}); {ns.bag} "
              + ("is read with --no-truth" if ns.no_truth else "has none"), file=sys.stderr)
        return 2
    if ns.no_truth or not has_truth:
        if not ns.no_truth:
            print(f"no ground truth ({topics.GT_GESTURES}) in {ns.bag}: writing the detections")
        try:
            result = detect_gestures(ns.bag, forest, node_params, ns.depth_topic)
        except (GestureBagError, ValueError) as err:  # ValueError: settings the forest cannot use
            print(f"error: {err}", file=sys.stderr)
            return 2
        result["model"] = str(ns.model)
        Path(ns.json).write_text(json.dumps(result, indent=1) + "\n")
        _print_detections(result)
        return 0
    try:
        data = read_gesture_bag(ns.bag)
    except GestureBagError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if ns.set_thresholds:
        if ns.max_false_per_minute <= 0 or not 0.0 <= ns.min_recall <= 1.0:
            print("error: --max-false-per-minute must be > 0 and --min-recall in [0, 1]", file=sys.stderr)
            return 2
        try:
            bags = [data] + [read_gesture_bag(b) for b in ns.threshold_bags]
        except GestureBagError as err:
            print(f"error: --threshold-bags: {err}", file=sys.stderr)
            return 2
        chosen = set_gesture_thresholds(forest, gesture_threshold_curves(bags, forest, node_params=node_params),
                                        ns.max_false_per_minute, [ns.bag] + list(ns.threshold_bags),
                                        ns.min_recall)
        save_forest(forest, ns.set_thresholds)
        print(f"thresholds written to {ns.set_thresholds}: " + ", ".join(f"{g} {t:.3f}" for g, t in chosen.items()))
    elif ns.threshold_bags:
        print("error: --threshold-bags needs --set-thresholds", file=sys.stderr)
        return 2
    params = None
    if overrides:
        params = from_flat(DetectorParams, {"min_score": SWEEP_MIN_SCORE, "min_volume": 0.0, **overrides})
    result = evaluate_gestures(data, forest, params, node_params)
    result["model"] = str(ns.model)
    Path(ns.json).write_text(json.dumps(result, indent=1) + "\n")
    if ns.plot:
        plot_pr(result, ns.plot)
    for name, c in result["per_class"].items():
        print(f"  {name:10s} AP {c['ap']:.3f}  ({c['true_positives']}/{c['positives']} found, "
              f"{c['detections']} detections)")
    print(f"mean AP {result['mean_ap']:.3f} over {result['scored_frames']} scored frames "
          f"({result['criterion']}); {result['fps']:.1f} frames/s")
    fd = result["false_detections"]
    print(f"false detections at the node's thresholds: {fd['frames']} of {fd['scored_frames']} frames "
          f"({100 * fd['per_frame']:.1f} %), {fd['events']} events in {fd['minutes']:.1f} min "
          f"({fd['events_per_minute']:.2f} per minute)")
    return 0
