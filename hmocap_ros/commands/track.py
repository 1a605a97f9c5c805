"""``hmocap track BAG --out OUT.mcap``: the body tracker on a multi-view bag, into a bag.

The work is :func:`hmocap_ros.eval.bag_tracking.track_to_bag` (its docstring says what is
written and where the foreground comes from). Progress goes to stderr; bad input (a bag that
cannot be read, no rig, no foreground source, a bad setting, an output that exists) is one
line on stderr and exit status 2. The bag is written whole or not at all.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from hmocap_ros.detection.detectors import detector_names
from hmocap_ros.eval.bag_tracking import SILHOUETTES, TrackError, track_to_bag

__all__ = ["add_arguments", "main_from_args"]

PROG = "hmocap track"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from hmocap_ros.tracking.methods import method_names

    parser.add_argument("bag", help="multi-view bag (.mcap or rosbag2 folder) in the documented layout")
    parser.add_argument("--out", required=True, type=Path,
                        help="bag to write (.mcap: one file; another name: a rosbag2 folder); must not exist")
    parser.add_argument("--method", choices=method_names(), default=None,
                        help="tracker method (default: body_tracker's)")
    parser.add_argument("--detector", choices=detector_names(), default=None,
                        help="extremity detector of a method that uses detections (default: "
                             "extremity_detection's)")
    parser.add_argument("--silhouettes", choices=SILHOUETTES, default="auto",
                        help="masks: the bag's /<camera>/foreground; fg: segment the images; gt: the "
                             "bag's exact silhouettes; auto: the first the bag has (default)")
    parser.add_argument("--learn-from", choices=("empty_room", "person_masks"), default=None,
                        help="how the background model of fg learns: from the first frames (the "
                             "room empty) or where the person masks leave the room free "
                             "(default: empty_room when the ground truth shows an empty room "
                             "first or --learn-frames is given, else person_masks)")
    parser.add_argument("--learn-frames", type=int, default=None,
                        help="frames the background model learns from with fg: the first ones "
                             "(empty_room), or per pixel the steady ones free of the person "
                             "(person_masks) (default: the frames before the ground truth's first "
                             "skeleton, else the node's learn_frames)")
    parser.add_argument("--max-people", type=int, default=1, help="people followed at once (default 1)")
    parser.add_argument("--body-id", default="b0",
                        help="REP-155 id of the first body (default b0, body_tracker's; the others are "
                             "numbered on: b1, b2...)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the tracker (default 0)")
    parser.add_argument("--param", action="append", metavar="KEY=VALUE",
                        help="a tracker setting by its dotted name, e.g. filter.particles=500 "
                             "(repeatable; body_tracker --help lists them)")
    parser.add_argument("--detection-param", action="append", metavar="KEY=VALUE",
                        help="an extremity detection setting by its dotted name, e.g. "
                             "keypoints.views_per_set=0 (repeatable; extremity_detection --help "
                             "lists them)")
    parser.add_argument("--rig", default=None, help="rig YAML (default: the bag's /camera_rig)")
    parser.add_argument("--no-tf", action="store_true", help="leave out the bodies' frames on /tf")
    parser.add_argument("--frames", type=int, default=None, help="stop after this many frame sets")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")


def main_from_args(ns: argparse.Namespace) -> int:
    from hmocap_ros.eval.mocap_eval import detection_overrides, tracker_overrides
    from hmocap_ros.io.bag_reader import BagReadError
    from hmocap_ros.io.bag_writer import BagWriteError

    out = Path(ns.out)
    if out.exists():
        print(f"{PROG}: {out} exists already; refusing to overwrite it", file=sys.stderr)
        return 2

    def progress(text: str) -> None:
        print(f"{PROG}: {text}", file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    try:
        counts = track_to_bag(ns.bag, out, method=ns.method, detector=ns.detector, silhouettes=ns.silhouettes,
                              learn_frames=ns.learn_frames, learn_from=ns.learn_from,
                              max_people=ns.max_people, seed=ns.seed,
                              overrides=tracker_overrides(ns.param), body_id=ns.body_id,
                              publish_tf=not ns.no_tf, rig_file=ns.rig, max_frames=ns.frames,
                              progress=None if ns.quiet else progress,
                              detection_overrides=detection_overrides(ns.detection_param))
    except (BagReadError, BagWriteError, TrackError) as err:
        print(f"{PROG}: {err}", file=sys.stderr)
        return 2
    except (ValueError, TypeError) as err:  # a setting or a rig that cannot be used
        print(f"{PROG}: {err}", file=sys.stderr)
        return 2
    except OSError as err:
        print(f"{PROG}: cannot write {out}: {err.strerror or err}", file=sys.stderr)
        return 2
    for note in counts["notes"]:
        print(f"{PROG}: note: {note}", file=sys.stderr)
    for text, n in counts["warnings"].items():
        print(f"{PROG}: warning ({n} times): {text}", file=sys.stderr)
    seconds = time.perf_counter() - t0
    print(f"{out}: {counts['with_pose']} of {counts['frame_sets']} frame sets with a body "
          f"(silhouettes {counts['silhouettes']}, {seconds / max(counts['frame_sets'], 1):.2f} s per frame set)")
    for topic, n in sorted(counts["topics"].items()):
        print(f"  {topic}: {n} messages")
    left_out = counts.get("people_left_out") or {}
    if left_out:
        print("  keypoints left out: " + ", ".join(f"{what} {n}" for what, n in sorted(left_out.items())))
    return 0
