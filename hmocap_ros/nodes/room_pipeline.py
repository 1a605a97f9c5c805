"""room_pipeline: segmentation, keypoints and tracking of the room's cameras in one process.

For a room whose cameras feed one PC. :class:`~hmocap_ros.room_pipeline.RoomPipeline` runs the
stages of ``foreground_segmentation``, ``extremity_detection`` and ``body_tracker`` on each frame
set in two threads: the intake's worker (:class:`~hmocap_ros.frame_intake.FrameSetIntake`, the
newest set with ``latest_only``) segments a set and hands it to a second worker
(:class:`~hmocap_ros.frame_intake.StageHandoff`) that detects and tracks it, so that the next
set is segmented while the last is tracked, each on a core of its own, and no set is segmented
that the tracker does not take. Each image is received and decoded once, the keypoints are those
of the set's own images, and no mask or keypoint message crosses DDS. The separate nodes stay
for rooms whose stages run on several hosts; the outputs are the same (``body_tracker``'s, plus
``extremities``), and so are the parameters: the tracker's and ``body_tracker``'s by their
names, the background models' by ``foreground_segmentation``'s names, the extremity
detection's under ``detection.`` (``detection.detector``, ``detection.keypoints.threads``, ...).

Subscriptions:
  ``camera_rig`` (hmocap_interfaces/CameraRig, latched), unless ``rig_file`` is set
  ``<camera>/image_raw`` (sensor_msgs/Image rgb8/bgr8/mono8, ``image_reliability``), or with
  ``image_transport:=compressed`` ``<camera>/image_raw/compressed`` (sensor_msgs/CompressedImage), per rig camera
Publications (stamped with the frame set):
  ``body_tracker``'s (``humans/bodies/...``, ``skeleton``, ``skeleton_markers``, ``body_shape``,
  ``/tf``, ``/diagnostics``) and ``extremities`` (hmocap_interfaces/Extremities), with the
  tracking method's detections.

Parameters: ``--help`` prints them after this text; defaults in config/room_pipeline.yaml.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from geometry_msgs.msg import Point, Vector3
from hmocap_interfaces.msg import Extremities

from hmocap_ros.detection.detections import fill_msg
from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams
from hmocap_ros.detection.tflite_model import ModelFileError
from hmocap_ros.frame_intake import FrameSetIntake, StageHandoff
from hmocap_ros.frame_sets import PickedSet
from hmocap_ros.geometry.rig import Rig
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.nodes.body_tracker import BodyTrackerNode, BodyTrackerNodeConfig
from hmocap_ros.nodes.common import (
    RESULT_QOS,
    create_image_subscription,
    declare_parameters,
    image_qos,
    param,
    rgb_from_msg,
    run_node,
)
from hmocap_ros.params import group
from hmocap_ros.room_pipeline import RoomPipeline
from hmocap_ros.segmentation import ForegroundParams
from hmocap_ros.tracking.params import TrackerParams

NODE_NAME = "room_pipeline"


@dataclass(frozen=True)
class RoomStagesConfig:
    """The stages the composed node runs before the tracker."""

    model_file: str = param("", "Keypoint network file (TFLite); empty = the model shipped with the package.")
    detection: ExtremityDetectionParams = group(ExtremityDetectionParams, "the extremity detection")


class RoomPipelineNode(BodyTrackerNode):
    node_name = NODE_NAME

    def _declare_stages(self) -> None:
        self.stages = declare_parameters(self, RoomStagesConfig)
        self.foreground = declare_parameters(self, ForegroundParams)
        self.room: RoomPipeline | None = None
        self.handoff: StageHandoff | None = None
        self._segment_s = 0.0  # moving average of a set's segmentation (s)
        self.pub_extremities = self.create_publisher(Extremities, "extremities", RESULT_QOS)

    def _set_rig(self, rig: Rig) -> None:
        first = self.rig is None
        if self.intake is not None:
            self.intake.close()  # its worker uses the room pipeline
        if self.handoff is not None:
            self.handoff.close()
        if self.room is not None:
            self.room.close()
        self.rig = rig
        self.frame_id = rig.frame_id
        if first:
            # Subscribe before loading the network and compiling: frames that arrive meanwhile
            # wait in the subscriptions' queues.
            qos = image_qos(self.config.image_reliability, self.config.queue_depth)
            for name in rig.names:
                create_image_subscription(self, f"{name}/image_raw", self.config.image_transport,
                                          self._on_image(name), qos)
        try:
            self.room = RoomPipeline(rig, self.params, self.model, self.rng, foreground=self.foreground,
                                     detection=self.stages.detection, model_path=self.stages.model_file or None,
                                     max_people=len(self.ids), ids=self.ids)
        except ModelFileError as err:
            self.get_logger().error(f"{err}; tracking on the silhouettes alone")
            self.room = RoomPipeline(rig, self.params, self.model, self.rng, foreground=self.foreground,
                                     detection=None, max_people=len(self.ids), ids=self.ids)
        self.tracker = self.room.people
        self._new_messages(rig)
        self.handoff = StageHandoff(self._track_segmented, on_error=self._work_failed,
                                    name=f"{self.node_name}_tracking")
        self.intake = FrameSetIntake(
            rig.names, self._segment, slop_ns=int(self.config.slop_ms * 1e6),
            min_keys=min(self.config.min_views_to_sync, len(rig)),
            max_wait_ns=int(self.config.max_wait_ms * 1e6), queue_size=max(10, self.config.queue_depth),
            latest_only=self.config.latest_only, on_start_over=self._start_over,
            on_error=self._work_failed, name=self.node_name)
        if first:
            seconds = self.tracker.warm_up()
            self.get_logger().info(f"kernels ready ({seconds:.1f} s)")
        self.get_logger().info(f"segmenting, detecting ({self.stages.detection.detector}) and tracking "
                               f"({self.params.method}) {len(rig)} cameras ({', '.join(rig.names)}) in one process")

    def _on_image(self, name: str):
        def on_image(msg) -> None:
            if self.intake is None or self.rig is None or name not in self.rig:
                return
            rgb = rgb_from_msg(msg, f"{name}/image_raw", self.get_logger())
            if rgb is not None:
                self.intake.add(name, stamp_to_ns(msg.header.stamp), rgb)

        return on_image

    def _segment(self, picked: PickedSet) -> None:
        """The first stage (the intake's worker): the set's masks, handed to the second."""
        assert self.rig is not None and self.room is not None and self.handoff is not None
        images = [picked.items.get(name) for name in self.rig.names]
        t0 = time.monotonic()
        masks = self.room.segment(picked.stamp_ns, images)
        took = time.monotonic() - t0
        self._segment_s = took if self._segment_s == 0.0 else 0.8 * self._segment_s + 0.2 * took
        self.handoff.put((picked, images, masks, list(self.room.dropped)))
        # the next set is taken (the newest) a segmentation before the tracker is free
        self.handoff.wait_until_due(self._segment_s)

    def _track_segmented(self, item: tuple) -> None:
        """The second stage: detection and tracking of a segmented set (``body_tracker``'s
        frame step, with :meth:`_update`)."""
        picked, *self._segmented = item
        self._process(picked)

    def _start_over(self, jump_ns: int) -> None:
        assert self.room is not None and self.handoff is not None  # come with the intake
        self.handoff.drain()  # the second stage's set belongs to the old stream
        self.get_logger().warning(
            f"the stamps went back by {jump_ns / 1e9:.2f} s: frame sets and tracks start over")
        self.room.reset()

    def _update(self, stamp_ns: int, items: dict, budget: float | None) -> list:
        assert self.rig is not None and self.room is not None  # sets come once the rig came
        images, masks, dropped = self._segmented
        step = self.room.step(stamp_ns, images, masks, budget_s=budget)
        for k, reason in dropped:
            self.get_logger().error(f"{self.rig.names[k]}/image_raw: {reason}: view dropped",
                                    throttle_duration_sec=5.0)
        if step.detections is not None:
            msg = self._header(Extremities(), stamp_ns)
            self.pub_extremities.publish(fill_msg(msg, step.detections, Point, Vector3))
        return step.results

    def destroy_node(self) -> None:
        super().destroy_node()
        if self.handoff is not None:
            self.handoff.close()
        if self.room is not None:
            self.room.close()


def main(args=None) -> int:
    return run_node(RoomPipelineNode, NODE_NAME, __doc__,
                    (BodyTrackerNodeConfig, RoomStagesConfig, ForegroundParams, TrackerParams), args)


if __name__ == "__main__":
    raise SystemExit(main())
