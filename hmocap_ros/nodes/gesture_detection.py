"""gesture_detection: static hand/arm gestures localized in a depth image (thesis sec. 3.2.4).

A random forest with depth-clipped pixel-pair tests (eq. 3.6) votes per pixel; the votes are
turned into a Parzen density, smoothed over time (eq. 3.4) and the maximum of each class that
passes the volume test (eq. 3.5) is a detection (:class:`~hmocap_ros.gestures.GestureDetector`).

Subscriptions:
  ``depth/image_raw`` (sensor_msgs/Image 16UC1 millimetres or 32FC1 metres, sensor-data QoS).
  ``depth/camera_info`` (sensor_msgs/CameraInfo): intrinsics for the 3D point of each gesture.
Publications:
  ``gestures`` (hmocap_interfaces/GestureArray, the depth image's stamp and frame_id), one per
  processed frame, empty when no gesture is seen.
  ``gestures/probability`` (sensor_msgs/Image mono8, 0-255 = density 0-1; only with
  ``publish_probability``): the smoothed density of the best class, for Foxglove/RViz.
Parameters: ``model_file``, ``publish_probability`` and every field of
:class:`~hmocap_ros.gestures.DetectorParams` (``gesture_detection --help``).

Wrong encodings, NaN depth (treated as invalid) and a corrupt model file are logged clearly;
without camera_info gestures are still published, with ``position_valid`` false.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from hmocap_interfaces.msg import Gesture, GestureArray
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image

from hmocap_ros.camera_model import PinholeCamera
from hmocap_ros.gestures import DetectorParams, ForestFileError, GestureDetector, load_forest
from hmocap_ros.io.conversions import ConversionError, camera_info_to_dict, image_to_numpy, numpy_to_image
from hmocap_ros.io.msg_factory import RclpyFactory, stamp_to_ns
from hmocap_ros.nodes.common import RESULT_QOS, SENSOR_QOS, declare_parameters, param, run_node

NODE_NAME = "gesture_detection"
DEFAULT_MODEL = Path(__file__).resolve().parents[1] / "data" / "gesture_forest.npz"
DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")


@dataclass(frozen=True)
class GestureNodeConfig:
    model_file: str = param("", "Gesture forest file (hmocap-forest .npz); empty = the shipped "
                                "hmocap_ros/data/gesture_forest.npz.")
    publish_probability: bool = param(True, "Publish the debug density image on gestures/probability.")


def gesture_point(camera: PinholeCamera | None, u: float, v: float, depth_m: float | None):
    """3D point (x, y, z) in the depth optical frame of pixel (u, v) at depth ``depth_m``, or None."""
    if camera is None or depth_m is None or not np.isfinite(depth_m) or depth_m <= 0:
        return None
    ray = camera.undistort_points(np.array([[u, v]], float))[0]
    return float(ray[0] * depth_m), float(ray[1] * depth_m), float(depth_m)


class GestureDetection(Node):
    def __init__(self):
        super().__init__(NODE_NAME)
        self.config = declare_parameters(self, GestureNodeConfig)
        self.params = declare_parameters(self, DetectorParams)
        self.factory = RclpyFactory()
        path = Path(self.config.model_file or DEFAULT_MODEL)
        try:
            forest = load_forest(path)
        except (ForestFileError, OSError) as err:
            self.get_logger().fatal(f"cannot load the gesture forest {path}: {err}")
            raise SystemExit(2) from err
        self.detector = GestureDetector(forest, self.params)
        self.detector.update(np.full((8, 8), 2000, np.uint16), 0)  # compile the numba kernels now
        self.detector.reset()
        self.camera: PinholeCamera | None = None
        self.frames = 0
        self.seconds = 0.0
        self.pub = self.create_publisher(GestureArray, "gestures", RESULT_QOS)
        self.prob_pub = (self.create_publisher(Image, "gestures/probability", SENSOR_QOS)
                         if self.config.publish_probability else None)
        self.create_subscription(CameraInfo, "depth/camera_info", self._on_info, RESULT_QOS)
        self.create_subscription(Image, "depth/image_raw", self._on_depth, SENSOR_QOS)
        self.get_logger().info(f"detecting {', '.join(forest.class_names[1:])} with {path.name} "
                               f"({len(forest.trees)} trees)")

    def _on_info(self, msg: CameraInfo) -> None:
        try:
            self.camera = PinholeCamera.from_camera_info(camera_info_to_dict(msg))
        except (ConversionError, ValueError) as err:
            self.get_logger().error(f"depth/camera_info: {err}", throttle_duration_sec=5.0)

    def _on_depth(self, msg: Image) -> None:
        log = self.get_logger()
        if msg.encoding not in DEPTH_ENCODINGS:
            log.error(f"depth/image_raw has encoding '{msg.encoding}'; expected one of {DEPTH_ENCODINGS}",
                      throttle_duration_sec=5.0)
            return
        try:
            depth = image_to_numpy(msg)
        except ConversionError as err:
            log.error(f"depth/image_raw: {err}", throttle_duration_sec=5.0)
            return
        if self.camera is None:
            log.warning("no depth/camera_info yet: gestures have no 3D position", throttle_duration_sec=10.0)
        elif (msg.width, msg.height) != (self.camera.width, self.camera.height):
            log.error(f"depth/image_raw is {msg.width}x{msg.height} but camera_info says "
                      f"{self.camera.width}x{self.camera.height}: no 3D positions", throttle_duration_sec=5.0)
        stamp = stamp_to_ns(msg.header.stamp)
        t0 = time.perf_counter()
        detections = self.detector.update(depth, stamp)
        self.seconds += time.perf_counter() - t0
        self.frames += 1
        camera = self.camera if self.camera is not None and (msg.width, msg.height) == self.camera.size else None
        out = GestureArray()
        out.header = msg.header
        for det in detections:
            g = Gesture(name=det.name, class_id=int(det.class_id), score=float(det.score),
                        volume=float(det.volume), u=float(det.u), v=float(det.v))
            point = gesture_point(camera, det.u, det.v, det.depth_m)
            if point is not None:
                g.position.x, g.position.y, g.position.z = point
                g.position_valid = True
            out.gestures.append(g)
        self.pub.publish(out)
        if self.prob_pub is not None:
            prob = np.clip(self.detector.probability_image() * 255.0, 0, 255).astype(np.uint8)
            self.prob_pub.publish(numpy_to_image(prob, "mono8", stamp, msg.header.frame_id, self.factory))
        if self.frames % 100 == 0:
            log.info(f"{self.frames} frames, {1e3 * self.seconds / self.frames:.1f} ms per frame")


def main(args=None) -> int:
    return run_node(GestureDetection, NODE_NAME, __doc__, (GestureNodeConfig, DetectorParams), args)


if __name__ == "__main__":
    raise SystemExit(main())
