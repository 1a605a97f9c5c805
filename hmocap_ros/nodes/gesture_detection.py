"""gesture_detection: static hand/arm gestures localized in a depth image (thesis sec. 3.2.4).

A random forest with depth-clipped pixel-pair tests (eq. 3.6) votes per pixel; the votes are
turned into a Parzen density, smoothed over time (eq. 3.4) and the maximum of each class that
passes the volume test (eq. 3.5) is a detection (:class:`~hmocap_ros.gestures.GestureDetector`).

Subscriptions:
  ``depth/image_raw`` (sensor_msgs/Image 16UC1/mono16 millimetres or 32FC1 metres by REP 118,
  or any unit through ``depth_unit_m``; with ``image_transport:=compressedDepth``
  ``depth/image_raw/compressedDepth``, sensor_msgs/CompressedImage; ``image_reliability`` with a
  queue of ``queue_depth``:
  :func:`~hmocap_ros.nodes.common.image_qos`).
  ``depth/camera_info`` (sensor_msgs/CameraInfo, the images' QoS): the focal length, to which
  the forest's test offsets (trained at the focal length recorded in the forest file) and the
  detector's pixel sizes are rescaled, and the intrinsics for the 3D point of each gesture.
Publications (built by :mod:`hmocap_ros.gestures.gesture_messages`, which ``hmocap detect
gestures`` writes to a bag):
  ``gestures`` (hmocap_interfaces/GestureArray, the depth image's stamp and frame_id), one per
  processed frame, empty when no gesture is seen.
  ``gestures/probability`` (sensor_msgs/Image mono8, 0-255 = density 0-1; only with
  ``publish_probability``): the smoothed density of the best class, for Foxglove/RViz.
``model_file`` may be changed at run time (the new forest is loaded, or the change is refused
with the reason); the file is watched every ``watch_period_s`` and loaded again when it is
written, e.g. by ``gesture_trainer``. The method, its choices and results: docs/gestures.md
("The node"). Parameters: ``--help`` prints them after this text.

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
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from hmocap_interfaces.msg import GestureArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo

from hmocap_ros.frame_intake import FrameSetIntake
from hmocap_ros.frame_sets import PickedSet
from hmocap_ros.geometry import PinholeCamera
from hmocap_ros.gestures import DetectorParams, ForestFileError, GestureDetector, load_forest
from hmocap_ros.gestures.depth_units import implausible_depth
from hmocap_ros.gestures.detection import gesture_thresholds, node_detections
from hmocap_ros.gestures.file_watch import FileWatch
from hmocap_ros.gestures.gesture_messages import gesture_array, probability_image
from hmocap_ros.io.msg_factory import RclpyFactory, stamp_to_ns
from hmocap_ros.nodes.common import (
    RESULT_QOS,
    create_image_publisher,
    create_image_subscription,
    declare_parameters,
    depth_camera_from_info,
    depth_from_msg,
    image_qos,
    image_reliability_param,
    image_transport_param,
    param,
    run_node,
)

NODE_NAME = "gesture_detection"
DEFAULT_MODEL = Path(__file__).resolve().parents[1] / "data" / "gesture_forest.npz"
DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")
#: the intake's key of the depth frames
DEPTH = "depth"


@dataclass(frozen=True)
class GestureNodeConfig:
    model_file: str = param("", "Gesture forest file (hmocap-forest .npz); empty = the shipped "
                                "hmocap_ros/data/gesture_forest.npz. Settable at run time.")
    publish_probability: bool = param(True, "Publish the debug density image on gestures/probability.")
    queue_depth: int = param(30, "Depth images queued while the node is busy: a stall or the burst of a replay "
                                 "catching up must fit; 30 holds one second at 30 fps.")
    latest_only: bool = param(True, "Live: when depth frames come faster than the detector, detect on the "
                                    "newest and skip (and count) the others, so the latency stays bounded. "
                                    "false: every frame in stamp order (slow bag replays).")
    image_reliability: str = image_reliability_param()
    image_transport: str = image_transport_param(depth=True)
    watch_period_s: float = param(1.0, "Seconds between checks of model_file on disk (0 = none): a forest file "
                                       "written again (gesture_trainer saving a taught gesture) is loaded "
                                       "without a restart.")
    use_taught_thresholds: bool = param(True, "A gesture taught by gesture_trainer is detected at the threshold "
                                              "the trainer computed for it (sec. 3.4.1, kept in the forest file) "
                                              "instead of min_score, and at that threshold times min_volume / "
                                              "min_score instead of min_volume.")


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
        self.prob_pub = (create_image_publisher(self, "gestures/probability", self.config.queue_depth)
                         if self.config.publish_probability else None)
        depth_qos = image_qos(self.config.image_reliability, self.config.queue_depth)
        # camera_info as the images: a driver publishes both with one QoS
        # the detector runs in the intake's worker, on the newest frame (``latest_only``)
        self.skipped = 0
        self.intake = FrameSetIntake(
            [DEPTH], self._process, slop_ns=0, min_keys=1, max_wait_ns=1_000_000_000,
            queue_size=max(1, self.config.queue_depth), latest_only=self.config.latest_only,
            on_start_over=self._start_over, on_error=self._work_failed, name=NODE_NAME)
        self.create_subscription(CameraInfo, "depth/camera_info", self._on_info, depth_qos)
        create_image_subscription(self, "depth/image_raw", self.config.image_transport, self._on_depth, depth_qos)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.model_watch = FileWatch(Path(self.config.model_file or DEFAULT_MODEL))
        if self.config.watch_period_s > 0:
            self.create_timer(self.config.watch_period_s, self._check_model_file)
        self.get_logger().info("detecting gestures" + (f" with {self.model_path.name}" if self.detector else
                                                       " once a forest is loaded"))

    # -- model --------------------------------------------------------------------------

    def _load_model(self, model_file: str) -> str:
        """Load a forest and build the detector; returns an error text ("" on success)."""
        path = Path(model_file or DEFAULT_MODEL)
        try:
            forest = load_forest(path)
            taught = {str(k): float(v) for k, v in forest.meta.get("gesture_thresholds", {}).items()
                      if self.config.use_taught_thresholds}
            own = gesture_thresholds(self.params, taught).values()
            detector = GestureDetector(forest, replace(
                self.params, min_score=min([self.params.min_score] + [t[0] for t in own]),
                min_volume=min([self.params.min_volume] + [t[1] for t in own])))
            detector.update(np.full((8, 8), 2000, np.uint16), 0)  # compile the numba kernels now
            detector.reset()
        except (ForestFileError, OSError, ValueError) as err:
            self.model_error = f"cannot use the gesture forest {path}: {err}"
            return self.model_error
        if self.detector is not None and self.detector.focal_px is not None:
            detector.set_focal(self.detector.focal_px)
        self.detector, self.model_path, self.model_error, self.thresholds = detector, path, "", taught
        self.model_watch = FileWatch(path)
        trained = forest.training_focal_px
        self.get_logger().info(
            f"gesture forest {path.name}: {len(forest.trees)} trees, classes {', '.join(forest.class_names[1:])}, "
            f"{forest.features.feature_type} tests"
            + (f" (kappa {forest.features.kappa_m:g} m)" if forest.features.clipped else "")
            + (f", trained at fx {trained:g} px" if trained
               else ", training focal length unknown (offsets used as is)"))
        return ""

    def _check_model_file(self) -> None:
        """Load model_file again when it was written since it was last seen (:mod:`~hmocap_ros.gestures.file_watch`)."""
        if self.model_watch.changed():
            error = self._load_model(str(self.model_watch.path))
            if error:
                self.get_logger().error(f"{error}; the forest in use is kept")

    def _on_set_parameters(self, params) -> SetParametersResult:
        for p in params:
            if p.name == "model_file":
                error = self._load_model(str(p.value))
                if error:
                    self.get_logger().error(error)
                    return SetParametersResult(successful=False, reason=error)
            elif p.name in {f for f in DetectorParams.__dataclass_fields__} | {"publish_probability", "queue_depth",
                                                                             "image_reliability", "image_transport",
                                                                             "watch_period_s", "use_taught_thresholds"}:
                return SetParametersResult(successful=False, reason=f"{p.name} is read at start: restart the node")
        return SetParametersResult(successful=True)

    # -- input --------------------------------------------------------------------------

    def _on_info(self, msg: CameraInfo) -> None:
        self.camera = depth_camera_from_info(msg, self.camera, self.get_logger())

    def _on_depth(self, msg) -> None:
        if self.detector is None:
            self.get_logger().error(f"{self.model_error}: depth frames are dropped", throttle_duration_sec=10.0)
            return
        depth = depth_from_msg(msg, DEPTH_ENCODINGS, self.get_logger())
        if depth is not None:
            self.intake.add(DEPTH, stamp_to_ns(msg.header.stamp), (msg, depth))

    def _start_over(self, jump_ns: int) -> None:
        """The stamps went back (a bag replayed again): the temporal smoothing starts anew."""
        self.get_logger().warning(f"the stamps went back by {jump_ns / 1e9:.2f} s: the smoothing starts over")
        if self.detector is not None:
            self.detector.reset()

    def _work_failed(self, err: Exception) -> None:
        self.get_logger().error(f"depth frame not detected: {err!r}", throttle_duration_sec=5.0)

    def _process(self, picked: PickedSet) -> None:
        """Detect on one depth frame (the intake's worker thread)."""
        self.skipped += picked.skipped
        msg, depth = picked.items[DEPTH]
        self._detect(msg, depth)

    def destroy_node(self) -> None:
        self.intake.close()
        super().destroy_node()

    def _detect(self, msg, depth: np.ndarray) -> None:
        log = self.get_logger()
        detector = self.detector  # a forest loaded meanwhile takes the next frame
        if detector is None:
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
            detector.set_focal(None)
        elif (depth.shape[1], depth.shape[0]) != (camera.width, camera.height):
            log.error(f"depth/image_raw is {depth.shape[1]}x{depth.shape[0]} but camera_info says "
                      f"{camera.width}x{camera.height}: assuming the training camera at this width, "
                      f"no 3D positions", throttle_duration_sec=5.0)
            camera = None
            detector.set_focal(None)
        else:
            detector.set_focal(camera.fx)
        stamp = stamp_to_ns(msg.header.stamp)
        t0 = time.perf_counter()
        try:
            detector.update(depth, stamp)
            detections = node_detections(detector.candidates,
                                         replace(detector.active_params, min_score=self.params.min_score,
                                                 min_volume=self.params.min_volume), self.thresholds)
        except ValueError as err:
            log.error(f"depth/image_raw: {err}", throttle_duration_sec=5.0)
            return
        self.seconds += time.perf_counter() - t0
        self.frames += 1
        if detector.class_map is not None and not np.any(detector.class_map >= 0):
            log.warning("depth/image_raw has no valid depth (all zero, NaN or out of range)",
                        throttle_duration_sec=10.0)
        self.pub.publish(gesture_array(detections, stamp, msg.header.frame_id, camera, self.factory))
        if self.prob_pub is not None:
            self.prob_pub.publish(probability_image(detector.probability_image(), stamp,
                                                    msg.header.frame_id, self.factory))
        if self.frames % 100 == 0:
            log.info(f"{self.frames} frames, {1e3 * self.seconds / self.frames:.1f} ms per frame, "
                     f"{self.skipped} skipped")


def main(args=None) -> int:
    return run_node(GestureDetection, NODE_NAME, __doc__, (GestureNodeConfig, DetectorParams), args)


if __name__ == "__main__":
    raise SystemExit(main())
