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
from typing import TypedDict

__all__ = ["add_arguments", "detect_to_bag", "main_from_args", "output_topics"]

PROG = "hmocap detect gestures"
DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")
#: seconds between two progress lines
PROGRESS_PERIOD_S = 2.0


class DetectCounts(TypedDict):
    """What :func:`detect_to_bag` returns (see there)."""

    frames: int
    detections: int
    skipped: dict[str, int]
    topics: dict[str, int]
    warning: str


class DetectError(ValueError):
    """Bad input of ``hmocap detect gestures`` (one line for the user)."""


def output_topics(depth_topic: str) -> tuple[str, str]:
    """``(gestures, probability)`` topics of a node in the namespace of ``depth_topic``."""
    from hmocap_ros.gestures.gesture_messages import GESTURES_TOPIC, PROBABILITY_TOPIC

    suffix = "depth/image_raw"
    ns = depth_topic[:-len(suffix)] if depth_topic.endswith("/" + suffix) else "/"
    ns = ns if ns.endswith("/") else ns + "/"
    return ns + GESTURES_TOPIC, ns + PROBABILITY_TOPIC


def _info_topic(depth_topic: str) -> str:
    return depth_topic.rsplit("/", 1)[0] + "/camera_info" if "/" in depth_topic.strip("/") else "/camera_info"


def _camera(info):
    """PinholeCamera of a CameraInfo message, or None when it has no intrinsics."""
    from hmocap_ros.geometry import PinholeCamera
    from hmocap_ros.io.conversions import ConversionError, camera_info_to_dict

    try:
        return PinholeCamera.from_camera_info(camera_info_to_dict(info))
    except (ConversionError, ValueError):
        return None


def detect_to_bag(bag, out, forest, params=None, depth_topic: str | None = None,
                  probability: bool = True, progress=None) -> DetectCounts:
    """Detect gestures on every frame of ``depth_topic`` of ``bag`` and write the node's
    messages to the new bag ``out`` (module docstring). Returns counts: ``frames``,
    ``detections``, ``skipped`` (reason -> frames), ``topics`` (topic -> messages written),
    ``warning`` (the depth-unit warning or ""). :class:`DetectError` for bad input."""
    from hmocap_ros.gestures.depth_units import implausible_depth
    from hmocap_ros.gestures.detection import GestureDetector
    from hmocap_ros.gestures.gesture_messages import gesture_array, probability_image
    from hmocap_ros.gestures.params import DetectorParams
    from hmocap_ros.io import topics
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.bag_writer import whole_bag
    from hmocap_ros.io.conversions import ConversionError, image_to_numpy
    from hmocap_ros.io.msg_factory import RosbagsFactory, stamp_to_ns

    params = params if params is not None else DetectorParams()
    depth_topic = depth_topic or topics.DEPTH_IMAGE
    info_topic = _info_topic(depth_topic)
    gestures_topic, prob_topic = output_topics(depth_topic)
    detector = GestureDetector(forest, params)
    factory = RosbagsFactory()
    counts: DetectCounts = {"frames": 0, "detections": 0, "skipped": {}, "topics": {}, "warning": ""}

    def skip(reason: str) -> None:
        counts["skipped"][reason] = counts["skipped"].get(reason, 0) + 1

    with BagReader(bag) as reader:
        available = reader.topics()
        if depth_topic not in available:
            images = sorted(t for t, i in available.items() if i.msgtype == "sensor_msgs/msg/Image")
            raise DetectError(f"{bag}: no {depth_topic} (image topics: {', '.join(images) or 'none'}); "
                              f"name the depth topic with --depth-topic")
        total = available[depth_topic].count
        has_info = info_topic in available
        camera = _camera(reader.first(info_topic)) if has_info else None
        last_report = time.monotonic()
        with whole_bag(out) as writer:
            for item in reader.messages([depth_topic, info_topic] if has_info else [depth_topic]):
                msg = item.msg
                stamp = stamp_to_ns(msg.header.stamp)
                if item.topic == info_topic:
                    camera = _camera(msg) or camera
                    writer.write(info_topic, msg, stamp, "sensor_msgs/msg/CameraInfo")
                    continue
                if msg.encoding not in DEPTH_ENCODINGS:
                    skip(f"encoding {msg.encoding!r}, not one of {', '.join(DEPTH_ENCODINGS)}")
                    continue
                try:
                    depth = image_to_numpy(msg)
                except ConversionError as err:
                    skip(str(err))
                    continue
                if not counts["warning"]:
                    counts["warning"] = implausible_depth(depth, params.depth_format)
                frame_camera = camera
                if camera is not None and (int(msg.width), int(msg.height)) != (camera.width, camera.height):
                    frame_camera = None
                detector.set_focal(None if frame_camera is None else frame_camera.fx)
                try:
                    detections = detector.update(depth, stamp)
                except ValueError as err:
                    skip(str(err))
                    continue
                counts["frames"] += 1
                counts["detections"] += len(detections)
                frame_id = str(msg.header.frame_id)
                writer.write(gestures_topic, gesture_array(detections, stamp, frame_id, frame_camera, factory),
                             stamp)
                if probability:
                    writer.write(prob_topic, probability_image(detector.probability_image(), stamp,
                                                               frame_id, factory), stamp)
                if progress is not None and time.monotonic() - last_report >= PROGRESS_PERIOD_S:
                    last_report = time.monotonic()
                    progress(f"{counts['frames']}/{total} frames, {counts['detections']} detections")
            if counts["frames"] == 0:
                reasons = "; ".join(f"{n} frames: {r}" for r, n in counts["skipped"].items())
                raise DetectError(f"{bag}: no usable frame on {depth_topic}" + (f" ({reasons})" if reasons else ""))
            counts["topics"] = dict(writer.counts)
    return counts


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
