"""The messages of ``gesture_detection`` for one depth frame, built without rclpy.

``gesture_detection`` publishes them and ``hmocap detect gestures`` writes them into a bag, so
a live run and an offline run of the detector give the same topics, types, stamps and
contents. Messages are built through a message factory (:mod:`hmocap_ros.io.msg_factory`).

Topics (relative names, as the node publishes them; each message carries the depth frame's
stamp and frame_id):

- ``gestures`` (hmocap_interfaces/GestureArray): the detections of the frame (thesis sec.
  3.2.4: class, score = smoothed density at the maximum, volume, pixel), each with its 3D point
  in the depth optical frame when the camera and the depth there are known; empty when no
  gesture is seen;
- ``gestures/probability`` (sensor_msgs/Image mono8): the smoothed density of the best class,
  0-255 for 0-1.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hmocap_ros.io.conversions import numpy_to_image
from hmocap_ros.io.msg_factory import make_header

__all__ = ["GESTURES_TOPIC", "PROBABILITY_TOPIC", "gesture_array", "gesture_point", "probability_image"]

GESTURES_TOPIC = "gestures"
PROBABILITY_TOPIC = "gestures/probability"


def gesture_point(camera, u: float, v: float, depth_m: float | None):
    """3D point (x, y, z) in the depth optical frame of pixel (u, v) at depth ``depth_m``, or
    None (no camera, no valid depth); ``camera`` a :class:`~hmocap_ros.geometry.PinholeCamera`."""
    if camera is None or depth_m is None or not np.isfinite(depth_m) or depth_m <= 0:
        return None
    ray = camera.undistort_points(np.array([[u, v]], float))[0]
    return float(ray[0] * depth_m), float(ray[1] * depth_m), float(depth_m)


def gesture_array(detections: Sequence, stamp_ns: int, frame_id: str, camera, factory):
    """``hmocap_interfaces/GestureArray`` of a frame's detections (``Detection``: name,
    class_id, score, volume, u, v, depth_m); ``camera`` None: no 3D points."""
    gestures = []
    for det in detections:
        point = gesture_point(camera, det.u, det.v, det.depth_m)
        x, y, z = point if point is not None else (0.0, 0.0, 0.0)
        gestures.append(factory.make(
            "hmocap_interfaces/msg/Gesture", name=str(det.name), class_id=int(det.class_id),
            score=float(det.score), volume=float(det.volume), u=float(det.u), v=float(det.v),
            position=factory.make("geometry_msgs/msg/Point", x=x, y=y, z=z),
            position_valid=point is not None))
    return factory.make("hmocap_interfaces/msg/GestureArray",
                        header=make_header(factory, stamp_ns, frame_id), gestures=gestures)


def probability_image(probability: np.ndarray, stamp_ns: int, frame_id: str, factory):
    """The mono8 ``gestures/probability`` image of a density in [0, 1]."""
    prob = np.clip(np.asarray(probability) * 255.0, 0, 255).astype(np.uint8)
    return numpy_to_image(prob, "mono8", stamp_ns, frame_id, factory)
