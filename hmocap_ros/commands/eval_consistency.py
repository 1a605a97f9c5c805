"""``hmocap eval consistency BAG [--tracked TRACKED_BAG] --json OUT``: how well a tracked body
agrees with the images of a recording that has no ground truth (the checks:
:mod:`hmocap_ros.eval.consistency`). Exit status 2 with one line on bad input."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from hmocap_ros.eval.consistency import ConsistencyError, evaluate_consistency

__all__ = ["add_arguments", "main_from_args"]

PROG = "hmocap eval consistency"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="multi-view bag in the documented layout (no ground truth needed)")
    parser.add_argument("--tracked", default=None,
                        help="bag of body_tracker's output for BAG (default: track BAG now with "
                             "hmocap track's defaults)")
    parser.add_argument("--json", required=True, metavar="OUT", help="write the report as JSON")
    parser.add_argument("--picture", default=None, metavar="OUT.png",
                        help="draw a few frame sets: foreground, rendered body, keypoints, joints")
    parser.add_argument("--learn-from", choices=("empty_room", "person_masks"),
                        default="person_masks",
                        help="how the foreground's background is learnt (default person_masks)")
    parser.add_argument("--min-views", type=int, default=3,
                        help="views that must agree on a triangulated keypoint (default 3)")
    parser.add_argument("--frames", type=int, default=None, help="check at most this many frame sets")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")


def main_from_args(ns: argparse.Namespace) -> int:
    import time

    last = [0.0]

    def progress(done: int, total: int) -> None:
        if not ns.quiet and time.monotonic() - last[0] >= 2.0:
            last[0] = time.monotonic()
            print(f"{PROG}: {done}/{total} frame sets", file=sys.stderr, flush=True)

    try:
        if ns.min_views < 2:
            raise ConsistencyError(f"--min-views must be >= 2, got {ns.min_views}")
        report = evaluate_consistency(ns.bag, ns.tracked, learn_from=ns.learn_from,
                                      min_views=ns.min_views, max_frames=ns.frames,
                                      picture=Path(ns.picture) if ns.picture else None,
                                      progress=progress)
    except (ConsistencyError, ValueError, OSError) as error:
        print(f"{PROG}: {error}", file=sys.stderr)
        return 2
    Path(ns.json).parent.mkdir(parents=True, exist_ok=True)
    Path(ns.json).write_text(json.dumps(report, indent=1))

    def show(value, unit):
        return "-" if value is None else f"{value:.1f}{unit}"

    print(f"{ns.bag}: a pose on {report['frames_with_pose']} of {report['frames']} frame sets; "
          f"reprojection median {show(report['reprojection_median_px'], ' px')} "
          f"(p90 {show(report['reprojection_p90_px'], ' px')}); silhouette IoU "
          f"{show(report['silhouette_iou_mean'], '')}; "
          f"triangulation gap {show(report['triangulation_gap_mm'], ' mm')} "
          f"({report['triangulated_points']} points seen by >= {report['min_views']} views)")
    for body in report["bodies"][1:]:
        print(f"  {body['body_id']}: a pose on {body['frames_with_pose']} frame sets; reprojection median "
              f"{show(body['reprojection_median_px'], ' px')} (p90 {show(body['reprojection_p90_px'], ' px')}); "
              f"silhouette IoU {show(body['silhouette_iou_mean'], '')}")
    return 0
