"""``hmocap eval extremities``: precision, recall and 3D error of the extremity detection on a
multi-view bag with ground truth (the scoring: :mod:`hmocap_ros.eval.extremity_eval`). Exit
status 2 with one line on bad input."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from hmocap_ros.detection.detectors import detector_names
from hmocap_ros.eval.extremity_eval import evaluate_extremities
from hmocap_ros.eval.mocap_frames import SILHOUETTES

__all__ = ["add_arguments", "main_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="multi-view bag with ground truth (hmocap sim mocap)")
    parser.add_argument("--detector", choices=detector_names(), default="keypoints",
                        help="extremity detector (default keypoints)")
    parser.add_argument("--silhouettes", choices=SILHOUETTES, default="fg",
                        help="masks: the bag's /<camera>/foreground; fg: segment the images "
                             "(default); gt: the bag's exact silhouettes; auto: the first the bag "
                             "has")
    parser.add_argument("--frames", type=int, default=None,
                        help="at most this many frame sets with ground truth")
    parser.add_argument("--radius", type=float, default=0.10,
                        help="a detection within this distance (m) of the truth is a hit")
    parser.add_argument("--json", metavar="OUT", help="write the report as JSON")


def main_from_args(ns: argparse.Namespace) -> int:
    try:
        report = evaluate_extremities(ns.bag, ns.detector, ns.silhouettes, ns.frames, ns.radius)
    except (ValueError, OSError, RuntimeError) as err:
        print(f"hmocap eval extremities: {err}", file=sys.stderr)
        return 2
    print(f"{Path(ns.bag).name}: {ns.detector}, {report['frame_sets']} frame sets, "
          f"{1e3 * report['seconds_per_frame_set']:.0f} ms per set")
    print(f"{'label':16s} {'precision':>9s} {'recall':>7s} {'mean mm':>8s} {'median mm':>9s}")
    for lab, s in sorted(report["labels"].items()):
        print(f"{lab:16s} {s['precision']:9.3f} {s['recall']:7.3f} {s['mean_error_mm']:8.1f} "
              f"{s['median_error_mm']:9.1f}")
    if ns.json:
        Path(ns.json).parent.mkdir(parents=True, exist_ok=True)
        Path(ns.json).write_text(json.dumps(report, indent=1))
    return 0
