"""Gesture detection over a recorded bag (thesis sec. 3.2.4): the messages the gesture detector
node publishes, written to a new bag, each output stamped with its depth frame's stamp.

The offline runner behind ``hmocap detect gestures``
(:mod:`hmocap_ros.commands.detect_gestures`, whose docstring describes the bag written).
"""

from __future__ import annotations

import time
from typing import TypedDict

__all__ = ["DEPTH_ENCODINGS", "DetectCounts", "DetectError", "detect_to_bag", "output_topics"]

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
    """Bad input of :func:`detect_to_bag` (one line for the user)."""


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
    messages to the new bag ``out`` (``hmocap detect gestures``). Returns counts: ``frames``,
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
