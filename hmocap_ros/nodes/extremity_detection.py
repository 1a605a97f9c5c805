"""extremity_detection: head, hands, feet and limb joints in 3D from the rig's images and foregrounds
(thesis sec. 2.5.1).

Pairs each camera's image with its foreground mask by stamp, synchronises the cameras into frame
sets and runs :class:`~hmocap_ros.detection.extremity_pipeline.ExtremityPipeline` on each:
``detector`` ``keypoints`` (a 2D landmark network per view on the crop MediaPipe's pipeline
gives it: from the view's previous landmarks, the previous skeleton or a pose detector;
triangulated robustly over the views) or ``skin`` (the thesis' skin-colour detector on the
oriented surface of the carved hull, eq. 2.16-2.18). body_tracker's ``kf-hpf`` and ``dd-hpf``
consume the detections. The detectors, their choices and results: docs/tracking.md, sections
2.4, 3.7 and 4.3.

Subscriptions:
  ``camera_rig`` (hmocap_interfaces/CameraRig, latched): the calibration, unless ``rig_file``.
  ``<camera>/image_raw`` (sensor_msgs/Image, rgb8/bgr8/..., ``image_reliability``) and
  ``<camera>/foreground`` (sensor_msgs/Image mono8, the foreground_segmentation node's); with
  ``image_transport:=compressed`` ``<camera>/image_raw/compressed`` and ``<camera>/foreground/compressed``
  (sensor_msgs/CompressedImage) instead; per
  rig camera, at the rig's resolution.
  ``skeleton`` (hmocap_interfaces/Skeleton), when ``use_skeleton``: the last tracked skeleton,
  which places the keypoint crops and the skin carving box and labels the skin candidates.
Publications (with the stamp of the frame set):
  ``extremities`` (hmocap_interfaces/Extremities): labelled 3D detections with scores.
  ``extremities/points`` (sensor_msgs/PointCloud2, fields x, y, z, probability): skin, the
  oriented surface points with their extremity probability (eq. 2.16-2.18); keypoints, the
  detections with their scores. For RViz/Foxglove.
  ``/diagnostics`` (diagnostic_msgs/DiagnosticArray): frame sets, detections, views, wall ms
  per set and CPU ms per set (the process's CPU time while it detects: every worker thread).
Synchronisation and keeping up (``slop_ms``, ``max_wait_ms``, ``min_views_to_sync``,
``latest_only``) as in body_tracker, over (image, foreground) pairs: docs/tracking.md,
section 7. Parameters: ``--help`` prints them after this text.

Bad input (a wrong encoding or size, a view missing, no rig yet) is logged and the frame or view
left out; a keypoint model file that is missing or corrupt is logged with its path and how to
get it, and the node detects with ``skin`` instead.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Vector3
from hmocap_interfaces.msg import Extremities, Skeleton
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2

from hmocap_ros.detection.detections import fill_msg
from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams, ExtremityPipeline, skeleton_labels
from hmocap_ros.detection.tflite_model import ModelFileError
from hmocap_ros.frame_intake import FrameSetIntake
from hmocap_ros.frame_sets import PickedSet
from hmocap_ros.geometry.rig import Rig
from hmocap_ros.io.conversions import ConversionError
from hmocap_ros.io.image_codec import decoded_mono
from hmocap_ros.io.msg_factory import RclpyFactory, stamp_to_ns
from hmocap_ros.io.point_clouds import array_to_pointcloud2
from hmocap_ros.nodes.common import (
    RESULT_QOS,
    create_image_subscription,
    declare_parameters,
    image_qos,
    image_reliability_param,
    image_transport_param,
    param,
    rgb_from_msg,
    run_node,
    take_rig,
)

NODE_NAME = "extremity_detection"
POINT_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("probability", "<f4")])
#: images kept per camera for their masks, which come a segmentation later: one second at 25 fps
IMAGES_KEPT = 25


@dataclass(frozen=True)
class ExtremityNodeConfig:
    rig_file: str = param("", "Rig calibration YAML; empty = take the rig from the latched camera_rig topic.")
    model_file: str = param("", "Keypoint network file (TFLite); empty = the model shipped with the package.")
    use_skeleton: bool = param(True, "Use the last tracked skeleton (topic skeleton) to place the keypoint "
                                     "crops and the skin carving box and to label skin candidates.")
    slop_ms: float = param(5.0, "Largest stamp difference (ms) between the frames of one frame set.")
    min_views_to_sync: int = param(2, "Frame sets with at least this many cameras are processed when a "
                                      "camera drops out (after max_wait_ms).")
    max_wait_ms: float = param(200.0, "How long (ms, > 0) a frame set waits for a missing camera.")
    queue_depth: int = param(5, "Frames queued per camera and topic while the node is busy.")
    latest_only: bool = param(True, "Live: when frame sets come faster than the detector, detect on the "
                                    "newest and skip (and count) the others. false: every set, in stamp "
                                    "order (slow bag replays; raise queue_depth too).")
    image_reliability: str = image_reliability_param()
    image_transport: str = image_transport_param()
    skeleton_max_age_ms: float = param(500.0, "A skeleton older than this (ms) before the frame set is "
                                              "not used.")


class ExtremityDetectionNode(Node):
    def __init__(self) -> None:
        super().__init__(NODE_NAME)
        self.config = declare_parameters(self, ExtremityNodeConfig)
        self.image_qos = image_qos(self.config.image_reliability, self.config.queue_depth)
        self.params = declare_parameters(self, ExtremityDetectionParams)
        if self.config.max_wait_ms <= 0:
            raise ValueError(f"max_wait_ms must be > 0, got {self.config.max_wait_ms}")
        self.factory = RclpyFactory()
        self.rig: Rig | None = None
        self.pipeline: ExtremityPipeline | None = None
        self.intake: FrameSetIntake | None = None
        self.images: dict = {}   # camera -> stamp -> rgb image waiting for its mask
        self.skeleton: tuple[int, dict] | None = None
        #: with several people (``keypoints.max_people`` > 1): body id -> (stamp, skeleton)
        self.skeletons: dict[str, tuple[int, dict]] = {}
        self.frame_id = "room"
        self.frames = 0
        self.seconds = 0.0
        self.cpu_seconds = 0.0
        self.skipped = 0
        self.last_counts = (0, 0)
        self.pub = self.create_publisher(Extremities, "extremities", RESULT_QOS)
        self.pub_points = self.create_publisher(PointCloud2, "extremities/points", RESULT_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", RESULT_QOS)
        self.create_timer(1.0, self._publish_diagnostics)
        if self.config.use_skeleton:
            self.create_subscription(Skeleton, "skeleton", self._on_skeleton, RESULT_QOS)
        take_rig(self, self.config.rig_file, self._set_rig)

    # ------------------------------------------------------------------ set-up

    def _make_pipeline(self, rig: Rig) -> ExtremityPipeline:
        model = self.config.model_file or None
        try:
            return ExtremityPipeline(rig.cameras, self.params, model)
        except ModelFileError as err:
            self.get_logger().error(f"{err}; detecting with the skin detector instead")
            self.params = replace(self.params, detector="skin")
            return ExtremityPipeline(rig.cameras, self.params)

    def _set_rig(self, rig: Rig) -> None:
        first = self.rig is None
        if self.intake is not None:
            self.intake.close()  # its worker uses the pipeline
        self.rig = rig
        self.frame_id = rig.frame_id
        self.images = {name: {} for name in rig.names}
        if first:
            # Subscribe before loading the network: frames that arrive meanwhile wait in the
            # subscriptions' queues instead of being published to nobody.
            qos = self.image_qos
            for name in rig.names:
                transport = self.config.image_transport
                create_image_subscription(self, f"{name}/image_raw", transport, self._on_image(name), qos)
                create_image_subscription(self, f"{name}/foreground", transport, self._on_mask(name), qos)
        if self.pipeline is not None:
            self.pipeline.close()
        self.pipeline = self._make_pipeline(rig)
        self.intake = FrameSetIntake(
            rig.names, self._process, slop_ns=int(self.config.slop_ms * 1e6),
            min_keys=min(self.config.min_views_to_sync, len(rig)),
            max_wait_ns=int(self.config.max_wait_ms * 1e6), queue_size=max(10, self.config.queue_depth),
            latest_only=self.config.latest_only, on_start_over=self._start_over,
            on_error=self._work_failed, name=NODE_NAME)
        self.get_logger().info(f"detecting with {self.params.detector} on {len(rig)} cameras "
                               f"({', '.join(rig.names)})")

    # ------------------------------------------------------------------ inputs

    def _on_skeleton(self, msg: Skeleton) -> None:
        joints = np.array([[p.x, p.y, p.z] for p in msg.positions], float).reshape(-1, 3)
        if len(joints) != len(msg.joint_names):
            self.get_logger().error("skeleton: joint names and positions differ in length",
                                    throttle_duration_sec=5.0)
            return
        self.skeleton = (stamp_to_ns(msg.header.stamp),
                         skeleton_labels([str(n) for n in msg.joint_names], joints))
        self.skeletons[str(msg.body_id)] = self.skeleton

    def _on_image(self, name: str):
        def on_image(msg) -> None:
            if self.rig is None or name not in self.images:
                return
            rgb = rgb_from_msg(msg, f"{name}/image_raw", self.get_logger())
            if rgb is None:
                return
            recent = self.images[name]
            recent[stamp_to_ns(msg.header.stamp)] = rgb
            while len(recent) > max(IMAGES_KEPT, 2 * self.config.queue_depth):
                recent.pop(next(iter(recent)))

        return on_image

    def _on_mask(self, name: str):
        def on_mask(msg) -> None:
            if self.intake is None or name not in self.images:
                return
            try:
                mask = decoded_mono(msg)
            except ConversionError as err:
                self.get_logger().error(f"{name}/foreground: {err}", throttle_duration_sec=5.0)
                return
            stamp = stamp_to_ns(msg.header.stamp)
            image = self._image_for(name, stamp)
            if image is None:
                self.get_logger().debug(f"{name}: no image of stamp {stamp} for its mask")
                return
            self.intake.add(name, stamp, (image, mask))

        return on_mask

    def _start_over(self, jump_ns: int) -> None:
        """The stamps went back: the crops and the last skeleton belong to the old stream."""
        self.get_logger().warning(f"the stamps went back by {jump_ns / 1e9:.2f} s: frame sets start over")
        self.skeleton = None
        self.skeletons.clear()
        assert self.pipeline is not None  # made with the intake
        self.pipeline.reset()

    def _work_failed(self, err: Exception) -> None:
        self.get_logger().error(f"frame set not detected: {err!r}", throttle_duration_sec=5.0)

    def _image_for(self, name: str, stamp_ns: int) -> np.ndarray | None:
        recent = self.images[name]
        slop = int(self.config.slop_ms * 1e6)
        for stamp in list(recent):
            if abs(stamp - stamp_ns) <= slop:
                return recent.pop(stamp)
        return None

    # ------------------------------------------------------------------ detection

    def _previous(self, stamp_ns: int) -> tuple[dict | None, int | None]:
        """The last skeleton and its stamp, (None, None) when none is recent enough; with
        several people every body's recent skeleton by body id, and the newest stamp."""
        max_age = self.config.skeleton_max_age_ms * 1e6
        if self.params.keypoints.max_people > 1:
            recent = {body: item for body, item in self.skeletons.items()
                      if abs(stamp_ns - item[0]) <= max_age}
            if not recent:
                return None, None
            return ({body: joints for body, (_, joints) in recent.items()},
                    max(stamp for stamp, _ in recent.values()))
        if self.skeleton is None:
            return None, None
        stamp, joints = self.skeleton
        if abs(stamp_ns - stamp) > max_age:
            return None, None
        return joints, stamp

    def _process(self, picked: PickedSet) -> None:
        """Detect on one frame set (the intake's worker thread)."""
        self.skipped += picked.skipped
        self._detect(picked.stamp_ns, picked.items)

    def destroy_node(self) -> None:
        if self.intake is not None:
            self.intake.close()
        super().destroy_node()

    def _detect(self, stamp_ns: int, items: dict) -> None:
        # frame sets are taken once the rig came, with the pipeline
        assert self.rig is not None and self.pipeline is not None
        images, masks = [], []
        for name in self.rig.names:
            image, mask = items.get(name, (None, None))
            images.append(image)
            masks.append(mask)
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            previous, previous_stamp = self._previous(stamp_ns)
            det = self.pipeline.detect(images, masks, previous, stamp_ns, previous_stamp)
        except Exception as err:  # a detector bug must not take the room's node down
            self.get_logger().error(f"extremity detection failed on frame {stamp_ns}: {err!r}")
            return
        self.seconds += time.perf_counter() - t0
        self.cpu_seconds += time.process_time() - c0
        self.frames += 1
        self.last_counts = (len(det), sum(m is not None for m in masks))
        msg = Extremities()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
        msg.header.frame_id = self.frame_id
        self.pub.publish(fill_msg(msg, det, Point, Vector3))
        points = det.points if len(det.points) else det.positions
        values = det.probability if len(det.points) else det.scores
        cloud = np.zeros(len(points), POINT_DTYPE)
        for k, axis in enumerate("xyz"):
            cloud[axis] = points[:, k]
        cloud["probability"] = values
        self.pub_points.publish(array_to_pointcloud2(cloud, stamp_ns, self.frame_id,
                                                     self.factory))

    def _publish_diagnostics(self) -> None:
        out = DiagnosticArray()
        out.header.stamp = self.get_clock().now().to_msg()
        ms = 1e3 * self.seconds / self.frames if self.frames else 0.0
        cpu_ms = 1e3 * self.cpu_seconds / self.frames if self.frames else 0.0
        level = DiagnosticStatus.OK if self.rig is not None else DiagnosticStatus.WARN
        out.status.append(DiagnosticStatus(
            level=level, name=f"{NODE_NAME}", hardware_id="rig",
            message=(f"detecting ({self.params.detector})" if self.rig is not None
                     else "waiting for the rig"),
            values=[KeyValue(key="frame_sets", value=str(self.frames)),
                    KeyValue(key="ms_per_frame_set", value=f"{ms:.1f}"),
                    KeyValue(key="cpu_ms_per_frame_set", value=f"{cpu_ms:.1f}"),
                    KeyValue(key="skipped_frame_sets", value=str(self.skipped)),
                    KeyValue(key="detections", value=str(self.last_counts[0])),
                    KeyValue(key="views", value=str(self.last_counts[1])),
                    KeyValue(key="views_left_out", value=" ".join(
                        f"{name}:{n}" for name, n in sorted(self._left_out().items()))),
                    KeyValue(key="people_left_out", value=" ".join(
                        f"{what.replace(' ', '_')}:{n}" for what, n in sorted(self._people_left_out().items())))]))
        self.pub_diag.publish(out)

    def _left_out(self) -> dict:
        """Per camera, the frame sets whose keypoints left the view out (disagreeing)."""
        if self.pipeline is None:
            return {}
        return dict(getattr(self.pipeline.detector, "views_left_out", {}))

    def _people_left_out(self) -> dict:
        """With several people: what the keypoint stage left out and how often."""
        if self.pipeline is None:
            return {}
        return dict(getattr(self.pipeline.detector, "people_left_out", {}))

    def log_totals(self) -> None:
        self.get_logger().info(f"frame sets detected: {self.frames}")


def main(args=None) -> int:
    return run_node(ExtremityDetectionNode, NODE_NAME, __doc__,
                    (ExtremityNodeConfig, ExtremityDetectionParams), args,
                    on_shutdown=lambda node: node.log_totals())


if __name__ == "__main__":
    raise SystemExit(main())
