"""``hmocap detect gestures BAG --out OUT.mcap``: the gesture detector on any depth bag, into a bag.

Runs :class:`~hmocap_ros.gestures.GestureDetector` (thesis sec. 3.2.4, the code of the
``gesture_detection`` node, with its settings: ``DetectorParams`` defaults and ``--param``
overrides) over the frames of ``--depth-topic`` in stamp order, and writes what the node
publishes (:mod:`hmocap_ros.gestures.gesture_messages`): ``gestures`` (GestureArray, one per
frame) and, unless ``--no-probability``, ``gestures/probability`` (mono8), each with the depth
frame's stamp and frame_id and logged at that stamp, beside the input's ``camera_info``. No
ground truth is needed (``hmocap eval gestures`` scores an annotated bag).

The output topics are those of a node in the depth topic's namespace: ``/depth/image_raw`` gives
``/gestures``, ``/kitchen/depth/image_raw`` gives ``/kitchen/gestures``.

As in the node: the focal length of the latest ``camera_info`` (the first one of the bag for the
frames before it) rescales the forest's offsets and gives each gesture its 3D point; without a
camera_info, or for an image of another size, the camera is taken for the forest's training
camera at the image width and the gestures have no 3D point. A frame that cannot be read
(wrong encoding, short data) is skipped and counted; depth in an implausible unit is warned of
once (:func:`~hmocap_ros.gestures.depth_units.implausible_depth`). The bag is written whole or
not at all. Progress goes to stderr; bad input (a bag that cannot be read, no depth topic, an
unusable forest or setting, an output that exists) is one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from hmocap_ros.eval.gesture_detection_bag import DetectError, detect_to_bag

__all__ = ["add_arguments", "main_from_args"]

PROG = "hmocap detect gestures"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from hmocap_ros.io import topics

    parser.add_argument("bag", help="depth bag (.mcap or rosbag2 folder); no ground truth needed")
    parser.add_argument("--out", required=True, type=Path,
                        help="bag to write (.mcap: one file; another name: a rosbag2 folder); must not exist")
    parser.add_argument("--model", default=None,
                        help="gesture forest (.npz; default: the shipped hmocap_ros/data/gesture_forest.npz)")
    parser.add_argument("--depth-topic", default=topics.DEPTH_IMAGE,
                        help=f"depth image topic (default {topics.DEPTH_IMAGE}); its camera_info is the "
                             "topic beside it")
    parser.add_argument("--param", action="append", metavar="KEY=VALUE",
                        help="a detector setting by name, e.g. depth_unit_m=0.000125 (repeatable; "
                             "gesture_detection --help lists them)")
    parser.add_argument("--no-probability", action="store_true",
                        help="leave out gestures/probability (the density images, the bulk of the bag)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")


def main_from_args(ns: argparse.Namespace) -> int:
    from hmocap_ros.eval.gesture_eval import DEFAULT_MODEL
    from hmocap_ros.gestures.forest_file import ForestFileError, load_forest
    from hmocap_ros.gestures.params import DetectorParams
    from hmocap_ros.io.bag_reader import BagReadError
    from hmocap_ros.io.bag_writer import BagWriteError
    from hmocap_ros.params import field_overrides, from_flat

    model = Path(ns.model) if ns.model else DEFAULT_MODEL
    out = Path(ns.out)
    if out.exists():
        print(f"{PROG}: {out} exists already; refusing to overwrite it", file=sys.stderr)
        return 2
    try:
        forest = load_forest(model)
    except (ForestFileError, OSError) as err:
        print(f"{PROG}: cannot load the gesture forest {model}: {err}", file=sys.stderr)
        return 2
    try:
        params = from_flat(DetectorParams, field_overrides(DetectorParams, ns.param, "detector parameter"))
    except (ValueError, TypeError) as err:
        print(f"{PROG}: --param: {err}", file=sys.stderr)
        return 2

    def progress(text: str) -> None:
        print(f"{PROG}: {text}", file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    try:
        counts = detect_to_bag(ns.bag, out, forest, params, ns.depth_topic, not ns.no_probability,
                               None if ns.quiet else progress)
    except (BagReadError, BagWriteError, DetectError) as err:
        print(f"{PROG}: {err}", file=sys.stderr)
        return 2
    except ValueError as err:  # settings the forest cannot use
        print(f"{PROG}: {err}", file=sys.stderr)
        return 2
    except OSError as err:
        print(f"{PROG}: cannot write {out}: {err.strerror or err}", file=sys.stderr)
        return 2
    if counts["warning"]:
        print(f"{PROG}: warning: {ns.depth_topic}: {counts['warning']}", file=sys.stderr)
    for reason, n in counts["skipped"].items():
        print(f"{PROG}: {n} frames skipped: {reason}", file=sys.stderr)
    seconds = time.perf_counter() - t0
    print(f"{out}: {counts['detections']} gestures in {counts['frames']} frames of {ns.depth_topic} "
          f"({counts['frames'] / seconds:.1f} frames/s)")
    for topic, n in sorted(counts["topics"].items()):
        print(f"  {topic}: {n} messages")
    return 0
