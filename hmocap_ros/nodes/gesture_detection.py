"""gesture_detection: static hand/arm gestures localized in a depth image (thesis sec. 3.2.4).

A random forest with depth-clipped pixel-pair tests (eq. 3.6) votes per pixel; the votes are
turned into a Parzen density, smoothed over time (eq. 3.4) and the maximum of each class that
passes the volume test (eq. 3.5) is a detection (:class:`~hmocap_ros.gestures.GestureDetector`).

Subscriptions:
  ``depth/image_raw`` (sensor_msgs/Image 16UC1/mono16 millimetres or 32FC1 metres by REP 118,
  or any unit through ``depth_unit_m``; sensor-data QoS with a queue of ``queue_depth``).
  ``depth/camera_info`` (sensor_msgs/CameraInfo): the focal length, to which the forest's test
  offsets (trained at the focal length recorded in the forest file) and the detector's pixel
  sizes are rescaled, and the intrinsics for the 3D point of each gesture.
Publications:
  ``gestures`` (hmocap_interfaces/GestureArray, the depth image's stamp and frame_id), one per
  processed frame, empty when no gesture is seen.
  ``gestures/probability`` (sensor_msgs/Image mono8, 0-255 = density 0-1; only with
  ``publish_probability``): the smoothed density of the best class, for Foxglove/RViz.
Parameters: ``model_file`` (may be changed at run time: the new forest is loaded, or the
change is refused with the reason), ``publish_probability``, ``queue_depth`` and every field of
:class:`~hmocap_ros.gestures.DetectorParams` (``gesture_detection --help``).

Depth in the wrong unit is warned of once: when the median valid depth of a frame, read with
``depth_unit_m``, lies outside 0.2 to 8 m (raw 1/8 mm SR300/SR305 values published as 16UC1
read 8 times too far, metres read as millimetres 1000 times too near), one warning names the
median and a unit that fits (:func:`~hmocap_ros.gestures.depth_units.implausible_depth`).

Bad input is logged (throttled) and the node keeps running: a wrong encoding, data shorter
than its step, a frame without valid depth (NaN depth is "no depth" by REP 118), an image
whose size differs from camera_info (no 3D positions), no camera_info yet (the camera is
assumed to be the forest's training camera at this image width; no 3D positions), a missing,
corrupt or incompatible model file (nothing is published until ``model_file`` names a usable
forest).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from hmocap_interfaces.msg import Gesture, GestureArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image

from hmocap_ros.camera_model import PinholeCamera
from hmocap_ros.gestures.depth_units import implausible_depth
from hmocap_ros.gestures import DetectorParams, ForestFileError, GestureDetector, load_forest
from hmocap_ros.io.conversions import ConversionError, camera_info_to_dict, image_to_numpy, numpy_to_image
from hmocap_ros.io.msg_factory import RclpyFactory, stamp_to_ns
from hmocap_ros.nodes.common import RESULT_QOS, SENSOR_QOS, declare_parameters, param, run_node, sensor_qos

NODE_NAME = "gesture_detection"
DEFAULT_MODEL = Path(__file__).resolve().parents[1] / "data" / "gesture_forest.npz"
DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")


@dataclass(frozen=True)
class GestureNodeConfig:
    model_file: str = param("", "Gesture forest file (hmocap-forest .npz); empty = the shipped "
                                "hmocap_ros/data/gesture_forest.npz. Settable at run time.")
    publish_probability: bool = param(True, "Publish the debug density image on gestures/probability.")
    queue_depth: int = param(30, "Depth images queued while the node is busy (sensor-data QoS): a stall or "
                                 "the burst of a replay catching up must fit.")


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
        self.detector: GestureDetector | None = None
        self.model_error = ""
        error = self._load_model(self.config.model_file)
        if error:
            self.get_logger().error(f"{error}; no gestures are published until the parameter model_file "
                                    f"names a valid forest")
        self.camera: PinholeCamera | None = None
        self.frames = 0
        self.seconds = 0.0
        self.unit_warned = False
        self.pub = self.create_publisher(GestureArray, "gestures", RESULT_QOS)
        self.prob_pub = (self.create_publisher(Image, "gestures/probability", SENSOR_QOS)
                         if self.config.publish_probability else None)
        self.create_subscription(CameraInfo, "depth/camera_info", self._on_info, RESULT_QOS)
        self.create_subscription(Image, "depth/image_raw", self._on_depth, sensor_qos(max(1, self.config.queue_depth)))
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.get_logger().info("detecting gestures" + (f" with {self.model_path.name}" if self.detector else
                                                       " once a forest is loaded"))

    # -- model --------------------------------------------------------------------------

    def _load_model(self, model_file: str) -> str:
        """Load a forest and build the detector; returns an error text ("" on success)."""
        path = Path(model_file or DEFAULT_MODEL)
        try:
            forest = load_forest(path)
            detector = GestureDetector(forest, self.params)
            detector.update(np.full((8, 8), 2000, np.uint16), 0)  # compile the numba kernels now
            detector.reset()
        except (ForestFileError, OSError, ValueError) as err:
            self.model_error = f"cannot use the gesture forest {path}: {err}"
            return self.model_error
        if self.detector is not None and self.detector.focal_px is not None:
            detector.set_focal(self.detector.focal_px)
        self.detector, self.model_path, self.model_error = detector, path, ""
        trained = forest.training_focal_px
        self.get_logger().info(
            f"gesture forest {path.name}: {len(forest.trees)} trees, classes {', '.join(forest.class_names[1:])}, "
            f"{forest.features.feature_type} tests" + (f" (kappa {forest.features.kappa_m:g} m)" if forest.features.clipped
                                                       else "")
            + (f", trained at fx {trained:g} px" if trained else ", training focal length unknown (offsets used as is)"))
        return ""

    def _on_set_parameters(self, params) -> SetParametersResult:
        for p in params:
            if p.name == "model_file":
                error = self._load_model(str(p.value))
                if error:
                    self.get_logger().error(error)
                    return SetParametersResult(successful=False, reason=error)
            elif p.name in {f for f in DetectorParams.__dataclass_fields__} | {"publish_probability", "queue_depth"}:
                return SetParametersResult(successful=False, reason=f"{p.name} is read at start: restart the node")
        return SetParametersResult(successful=True)

    # -- input --------------------------------------------------------------------------

    def _on_info(self, msg: CameraInfo) -> None:
        try:
            camera = PinholeCamera.from_camera_info(camera_info_to_dict(msg))
        except (ConversionError, ValueError) as err:
            self.get_logger().error(f"depth/camera_info: {err}", throttle_duration_sec=5.0)
            return
        if self.camera is None or camera.fx != self.camera.fx:
            self.get_logger().info(f"depth camera {camera.width}x{camera.height}, fx {camera.fx:g} px")
        self.camera = camera
        if self.detector is not None:
            self.detector.set_focal(camera.fx)

    def _on_depth(self, msg: Image) -> None:
        log = self.get_logger()
        if self.detector is None:
            log.error(f"{self.model_error}: depth frames are dropped", throttle_duration_sec=10.0)
            return
        if msg.encoding not in DEPTH_ENCODINGS:
            log.error(f"depth/image_raw has encoding '{msg.encoding}'; expected one of {DEPTH_ENCODINGS}",
                      throttle_duration_sec=5.0)
            return
        try:
            depth = image_to_numpy(msg)
        except ConversionError as err:
            log.error(f"depth/image_raw: {err}", throttle_duration_sec=5.0)
            return
        if not self.unit_warned:
            reason = implausible_depth(depth, self.params.depth_format)
            if reason:
                log.warning(f"depth/image_raw: {reason}")
                self.unit_warned = True
        camera = self.camera
        if camera is None:
            log.warning("no depth/camera_info yet: assuming the forest's training camera at this image width; "
                        "gestures have no 3D position", throttle_duration_sec=10.0)
            self.detector.set_focal(None)
        elif (msg.width, msg.height) != (camera.width, camera.height):
            log.error(f"depth/image_raw is {msg.width}x{msg.height} but camera_info says "
                      f"{camera.width}x{camera.height}: assuming the training camera at this width, "
                      f"no 3D positions", throttle_duration_sec=5.0)
            camera = None
            self.detector.set_focal(None)
        else:
            self.detector.set_focal(camera.fx)
        stamp = stamp_to_ns(msg.header.stamp)
        t0 = time.perf_counter()
        try:
            detections = self.detector.update(depth, stamp)
        except ValueError as err:
            log.error(f"depth/image_raw: {err}", throttle_duration_sec=5.0)
            return
        self.seconds += time.perf_counter() - t0
        self.frames += 1
        if self.detector.class_map is not None and not np.any(self.detector.class_map >= 0):
            log.warning("depth/image_raw has no valid depth (all zero, NaN or out of range)",
                        throttle_duration_sec=10.0)
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
