"""body_tracker: the 3D body pose of the people in the room from N cameras (thesis ch. 2).

Synchronises the foreground masks of the rig cameras by stamp, pairs each set with the
extremity node's keypoints of its stamp whenever they come, and runs
:class:`~hmocap_ros.tracking.body_tracker.BodyTracker` on the newest set in a worker thread
(:class:`~hmocap_ros.frame_intake.FrameSetIntake`), one per person with ``max_people``
(:class:`~hmocap_ros.tracking.people_tracker.PeopleTracker`).
The default method, ``kf-hpf``, fits the skinned body to the keypoints, checks them against
the silhouettes and runs the layered filter (alg. 5, weights eq. 2.8 and 2.15) only on the
blocks they leave uncertain. Live (``latest_only`` with ``budget_ms``) a track starts only from
keypoints, and without keypoints (the keypoint stage late, absent or crashed) a track goes on
from its prediction with falling confidence until they come back; offline (``hmocap track``,
``hmocap eval mocap``) a frame set without keypoints runs the silhouette filter. ``method``
selects the thesis' ``apf``, ``hpf``, ``hpf-apo`` and ``dd-hpf``
(:data:`~hmocap_ros.tracking.methods.METHODS`).

Subscriptions:
  ``camera_rig`` (hmocap_interfaces/CameraRig, latched), unless ``rig_file`` is set
  ``<camera>/foreground`` (sensor_msgs/Image mono8), or with ``image_transport:=compressed``
  ``<camera>/foreground/compressed`` (sensor_msgs/CompressedImage PNG), per rig camera
  ``extremities`` (hmocap_interfaces/Extremities), with ``kf-hpf`` and ``dd-hpf``
Publications (REP-155, stamped with the frame set):
  ``humans/bodies/tracked`` (hri_msgs/IdsList)
  ``humans/bodies/<id>/joint_states`` (sensor_msgs/JointState: the URDF's joints, then the
  tracker's degrees of freedom)
  ``humans/bodies/<id>/urdf`` (std_msgs/String, latched: human_description's URDF at the body's
  shape), ``skeleton2d`` (hri_msgs/Skeleton2D), ``roi`` (hri_msgs/NormalizedRegionOfInterest2D),
  ``position`` (geometry_msgs/PointStamped), ``velocity`` (geometry_msgs/TwistStamped), per body
  (:mod:`hmocap_ros.rep155.body_outputs`)
  ``humans/bodies/<id>/body_shape``, ``body_shape`` (hmocap_interfaces/BodyShape, latched)
  ``skeleton`` (hmocap_interfaces/Skeleton), ``skeleton_markers`` (visualization_msgs/MarkerArray)
  ``/tf`` (tf2_msgs/TFMessage, with ``publish_tf``; ``frame_prefix``, ``joint_frames``),
  ``/diagnostics``

The topics in full, synchronisation and keeping up with live cameras: docs/tracking.md,
section 7; the method, its choices and results: sections 1-5. Parameters: ``--help`` prints
them after this text; defaults in config/body_tracker.yaml.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numba
import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from hmocap_interfaces.msg import BodyShape as BodyShapeMsg
from hmocap_interfaces.msg import Extremities, Skeleton
from hri_msgs.msg import IdsList
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from hmocap_ros.body.model import load_body_model
from hmocap_ros.detection.detections import detections_from_msg
from hmocap_ros.frame_intake import FrameSetIntake
from hmocap_ros.frame_sets import PickedSet
from hmocap_ros.geometry.rig import Rig
from hmocap_ros.io.conversions import ConversionError
from hmocap_ros.io.image_codec import decoded_mono
from hmocap_ros.io.msg_factory import RclpyFactory, stamp_to_ns
from hmocap_ros.io.tf import TF_TOPIC
from hmocap_ros.nodes.common import (
    LATCHED_QOS,
    RESULT_QOS,
    create_image_subscription,
    declare_parameters,
    image_qos,
    image_reliability_param,
    image_transport_param,
    message_class,
    param,
    run_node,
    take_rig,
)
from hmocap_ros.rep155.body_outputs import Rep155Outputs, rep155_topics
from hmocap_ros.tracking.detection_assignment import END_EFFECTORS
from hmocap_ros.tracking.params import TrackerParams
from hmocap_ros.tracking.people_tracker import DEFAULT_BODY_ID, PeopleTracker, body_ids
from hmocap_ros.tracking.tracker_messages import TRACKED_TOPIC, TrackerMessages, per_body_topic

NODE_NAME = "body_tracker"
#: the frame sets' key (and topic) of the extremity detections
DETECTIONS = "extremities"
#: a frame set waits for its detections (however late they come) while the extremity topic has
#: a publisher and detections came this recently, or none yet since the first mask this recently
#: (the extremity node starts later than the masks); longer without any, the frame sets are
#: tracked without them (live, a track goes on from its prediction with falling confidence:
#: :meth:`~hmocap_ros.tracking.body_tracker.BodyTracker.update`)
KEYPOINTS_ALIVE_NS = 2_000_000_000
#: /tf as tf2's TransformBroadcaster publishes it (reliable, volatile, keep last 100)
TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


@dataclass(frozen=True)
class BodyTrackerNodeConfig:
    rig_file: str = param("", "Rig calibration YAML; empty = take the rig from the latched camera_rig topic.")
    slop_ms: float = param(5.0, "Largest stamp difference (ms) between the cameras' frames of one frame set.")
    min_views_to_sync: int = param(2, "Frame sets with at least this many cameras are processed when a "
                                      "camera drops out (after max_wait_ms); 1 to the number of cameras.")
    max_wait_ms: float = param(200.0, "How long (ms, > 0) a frame set waits for a missing camera after its "
                                      "newest frame arrived or until a frame this much newer arrives; "
                                      "then it is processed with the views it has.")
    queue_depth: int = param(5, "Frames queued per camera while the tracker is busy (best effort: older "
                                "ones are dropped, so a live tracker works on recent frames; raise it "
                                "when replaying a bag slowly and every frame must be tracked).")
    image_reliability: str = image_reliability_param()
    image_transport: str = image_transport_param()
    latest_only: bool = param(True, "Live: when frame sets come faster than the tracker processes them, "
                                    "track the newest and skip (and count) the others, so the latency "
                                    "stays bounded. false: track every set in stamp order (slow bag "
                                    "replays that must answer every frame; raise queue_depth too).")
    budget_ms: float = param(30.0, "Live (latest_only): milliseconds a frame set may take; the "
                                   "keypoint-first filter (kf-hpf) spends on its particles only "
                                   "what fits, and the keypoint fit is the pose when nothing "
                                   "does. 0: no limit.")
    publish_tf: bool = param(True, "Publish each tracked body's frames on /tf: room -> body_<id> (the "
                                   "pelvis) and <joint>_<id> along the skeleton (REP-155 names).")
    joint_frames: bool = param(True, "With publish_tf, the joints' frames too; false: only room -> "
                                     "body_<id>, for a robot_state_publisher per body that adds the "
                                     "frames of humans/bodies/<id>/urdf from humans/bodies/<id>/joint_states.")
    frame_prefix: str = param("", "Prefix of the bodies' frames on /tf (e.g. room_1/ gives "
                                  "room_1/body_b0), so that two rooms on one DDS domain keep their "
                                  "bodies apart; give robot_state_publisher the same frame_prefix.")
    seed: int = param(0, "Seed of the particle filter's random generator (repeatable runs).")
    threads: int = param(1, "Threads of the tracker's numba kernels (>= 1): one, as the room's other "
                            "stages run beside it; more only on a machine with cores to spare.")
    body_id: str = param(DEFAULT_BODY_ID, "REP-155 body id of the first tracked body (topics humans/bodies/"
                                          "<id>/..., frames body_<id> and <joint>_<id>; it must start with "
                                          "a letter); further bodies are numbered on (b1, b2, ...).")
    max_people: int = param(1, "People followed at once, one tracker each: a bystander the cameras "
                               "see better does not take the user's track, and each person gets "
                               "a body id; every followed person costs a filter run per frame.")


class BodyTrackerNode(Node):
    """The tracker over the masks and keypoints of the other nodes; :class:`~hmocap_ros.nodes.
    room_pipeline.RoomPipelineNode` runs every stage itself on the images (``_set_rig``,
    ``_update``)."""

    #: the node's name, and its diagnostics' prefix
    node_name = NODE_NAME

    def __init__(self) -> None:
        super().__init__(self.node_name)
        self.config = declare_parameters(self, BodyTrackerNodeConfig)
        self.mask_qos = image_qos(self.config.image_reliability, self.config.queue_depth)
        self.params = declare_parameters(self, TrackerParams)
        self.model = load_body_model("tracking")
        self.rng = np.random.default_rng(self.config.seed)
        if self.config.threads < 1:
            self.get_logger().fatal(f"threads must be >= 1, got {self.config.threads}")
            raise SystemExit(2)
        numba.set_num_threads(min(self.config.threads, numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]  # set at import
        if self.config.max_people < 1:
            self.get_logger().fatal(f"max_people must be >= 1, got {self.config.max_people}")
            raise SystemExit(2)
        self.ids = body_ids(self.config.body_id, self.config.max_people)
        self.tracker: PeopleTracker | None = None
        self.intake: FrameSetIntake | None = None
        self.rig: Rig | None = None
        self.frame_id = "room"
        self.last_state = ["searching"] * len(self.ids)
        self.frames = 0
        self.last_detections_ns = -KEYPOINTS_ALIVE_NS  # steady time of the last detections received
        self.first_mask_ns: int | None = None  # ... of the first mask received
        self.skipped_total = 0
        self.skipped_unreported = 0  # skipped since the last diagnostics message
        self.factory = RclpyFactory()
        self.pub_skeleton = self.create_publisher(Skeleton, "skeleton", RESULT_QOS)
        self.pub_markers = self.create_publisher(MarkerArray, "skeleton_markers", RESULT_QOS)
        self.pub_tracked = self.create_publisher(IdsList, TRACKED_TOPIC, RESULT_QOS)
        # per body: its joint_states and body_shape publishers; the first body's shape also on
        # the plain body_shape topic
        self.pub_joints = [self.create_publisher(JointState, per_body_topic(body, "joint_states"),
                                                 RESULT_QOS) for body in self.ids]
        self.pub_shapes = [[self.create_publisher(BodyShapeMsg, per_body_topic(body, "body_shape"),
                                                  LATCHED_QOS)] for body in self.ids]
        self.pub_shapes[0].append(self.create_publisher(BodyShapeMsg, "body_shape", LATCHED_QOS))
        self.pub_tf = (self.create_publisher(TFMessage, TF_TOPIC, TF_QOS)
                       if self.config.publish_tf else None)
        self.pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", RESULT_QOS)
        # per body: REP-155's urdf (latched), skeleton2d, roi, position and velocity
        self.pub_rep155 = {topic: self.create_publisher(message_class(kind), topic,
                                                        LATCHED_QOS if topic.endswith("/urdf") else RESULT_QOS)
                           for body in self.ids for topic, kind in rep155_topics(body).items()}
        self.messages: TrackerMessages | None = None  # the outputs' builder, with the rig's frame
        self.rep155: Rep155Outputs | None = None  # ... of REP-155's further outputs
        self.pub_by_topic = self._publishers_by_topic()
        if self.config.max_wait_ms <= 0:
            self.get_logger().fatal(f"max_wait_ms must be > 0, got {self.config.max_wait_ms}")
            raise SystemExit(2)
        self._declare_stages()
        take_rig(self, self.config.rig_file, self._set_rig)

    def _declare_stages(self) -> None:
        """Declare the parameters of the stages this node runs beside the tracker (none)."""

    def _set_rig(self, rig: Rig) -> None:
        first = self.rig is None
        self.rig = rig
        self.frame_id = rig.frame_id
        self.tracker = PeopleTracker(self.model, rig, self.params, self.rng,
                                     max_people=len(self.ids), ids=self.ids)
        self._new_messages(rig)
        self.use_detections = self.params.tracking_method.uses_detector
        if self.intake is not None:
            self.intake.close()
        # Masks by stamp; a set waits for its detections however late they come (the
        # extremity node answers at its own rate), and the worker takes the newest answered set.
        self.intake = FrameSetIntake(
            rig.names, self._process, slop_ns=int(self.config.slop_ms * 1e6),
            min_keys=min(self.config.min_views_to_sync, len(rig)),
            max_wait_ns=int(self.config.max_wait_ms * 1e6), queue_size=max(10, self.config.queue_depth),
            latest_only=self.config.latest_only, companion=DETECTIONS if self.use_detections else None,
            on_start_over=self._start_over, on_error=self._work_failed, name=self.node_name)
        if first:
            # Subscribe before compiling: masks that arrive during the (cold-cache) warm-up
            # wait in the subscriptions' queues instead of being published to nobody.
            for name in rig.names:
                create_image_subscription(self, f"{name}/foreground", self.config.image_transport,
                                          self._on_mask(name), self.mask_qos)
            if self.use_detections:
                # as deep as the masks' queues: detections dropped while the tracker works
                # would leave their frame sets incomplete
                self.create_subscription(Extremities, DETECTIONS, self._on_extremities, QoSProfile(
                    depth=max(RESULT_QOS.depth, self.config.queue_depth),
                    reliability=ReliabilityPolicy.RELIABLE))
            seconds = self.tracker.warm_up()
            self.get_logger().info(f"kernels ready ({seconds:.1f} s)")
        self.get_logger().info(f"tracking with {len(rig)} cameras ({', '.join(rig.names)}), method "
                               f"{self.params.method}")

    def _new_messages(self, rig: Rig) -> None:
        """The outputs' builder, in the rig's frame."""
        self.messages = TrackerMessages(self.model, self.ids, rig.frame_id, self.factory,
                                        publish_tf=self.pub_tf is not None)
        self.rep155 = Rep155Outputs(self.ids, rig.frame_id, rig.cameras, self.factory,
                                    frame_prefix=self.config.frame_prefix, joint_frames=self.config.joint_frames)

    def _mono8(self, msg, topic: str) -> np.ndarray | None:
        try:
            return decoded_mono(msg)
        except ConversionError as err:
            self.get_logger().error(f"{topic}: {err}", throttle_duration_sec=5.0)
            return None

    def _on_extremities(self, msg: Extremities) -> None:
        if self.intake is None:
            return
        try:
            detections = detections_from_msg(msg)
        except ValueError as err:
            self.get_logger().error(f"extremities: {err}", throttle_duration_sec=5.0)
            return
        self.last_detections_ns = time.monotonic_ns()
        self.intake.add_companion(stamp_to_ns(msg.header.stamp), detections)

    def _on_mask(self, name: str):
        def on_mask(msg) -> None:
            if self.intake is None or self.rig is None or name not in self.rig:
                return
            mask = self._mono8(msg, f"{name}/foreground")
            if mask is None:
                return
            self.intake.companion_expected = self._detections_expected()
            self.intake.add(name, stamp_to_ns(msg.header.stamp), mask)

        return on_mask

    def _detections_expected(self) -> bool:
        """Whether frame sets wait for their detections (:data:`KEYPOINTS_ALIVE_NS`)."""
        if not self.use_detections or self.count_publishers(DETECTIONS) == 0:
            return False
        now = time.monotonic_ns()
        if self.first_mask_ns is None:
            self.first_mask_ns = now
        return now - max(self.last_detections_ns, self.first_mask_ns) < KEYPOINTS_ALIVE_NS

    def _start_over(self, jump_ns: int) -> None:
        """The stamps went back (a bag replayed again, a camera clock reset): the intake
        started the stream over; the tracks (not the body shapes) go too."""
        assert self.tracker is not None  # comes with the rig
        self.get_logger().warning(
            f"the stamps went back by {jump_ns / 1e9:.2f} s: frame sets and tracks start over")
        self.tracker.reset(forget_shape=False)
        self.first_mask_ns = None

    def _work_failed(self, err: Exception) -> None:
        self.get_logger().error(f"frame set not tracked: {err!r}", throttle_duration_sec=5.0)

    def _process(self, picked: PickedSet) -> None:
        """Track one frame set (the intake's worker thread)."""
        assert self.tracker is not None  # frame sets are taken once the rig came
        self.skipped_total += picked.skipped
        self.skipped_unreported += picked.skipped
        self.tracker.saw(picked.passed_over)  # their stamps still measure the frame period
        self._track(picked)

    def destroy_node(self) -> None:
        if self.intake is not None:
            self.intake.close()
        super().destroy_node()

    def _track(self, picked: PickedSet) -> None:
        # frame sets are taken once the rig came, with the tracker and the messages' builder
        assert self.rig is not None and self.tracker is not None and self.messages is not None
        stamp_ns, items = picked.stamp_ns, picked.items
        log = self.get_logger()
        t0 = time.perf_counter()
        try:
            budget = (self.config.budget_ms / 1000.0
                      if self.config.latest_only and self.config.budget_ms > 0 else None)
            results = self._update(stamp_ns, items, budget)
        except Exception as err:  # a tracker bug must not take the room's node down
            log.error(f"tracking failed on frame {stamp_ns}: {err!r}; restarting the track")
            self.tracker.reset(forget_shape=False)
            return
        seconds = time.perf_counter() - t0
        self.frames += 1
        for k, result in enumerate(results):
            if result.state != self.last_state[k]:
                self._log_transition(k, result, seconds)
                self.last_state[k] = result.state
        models = [t.model for t in self.tracker.trackers]
        built = self.messages.frame_set(stamp_ns, results, models)
        heights = [float(r.shape.height(m)) if r.shape is not None else float("nan")
                   for r, m in zip(results, models)]
        assert self.rep155 is not None  # made with self.messages
        for topic, msg in self.rep155.messages(stamp_ns, results, heights, built.messages):
            for pub in self.pub_by_topic[topic]:
                pub.publish(msg)
        for error in built.errors:  # a degenerate pose must not stop the node
            log.error(error, throttle_duration_sec=5.0)
        self._publish_diagnostics(stamp_ns, results, seconds, picked)

    def _update(self, stamp_ns: int, items: dict, budget: float | None) -> list:
        """The trackers' results of one frame set (its masks by camera, its detections)."""
        assert self.rig is not None and self.tracker is not None  # sets come once the rig came
        masks = []
        for cam in self.rig.cameras:
            mask = items.get(cam.name)
            if mask is not None and mask.shape != (cam.height, cam.width):
                self.get_logger().error(
                    f"{cam.name}/foreground is {mask.shape[1]}x{mask.shape[0]}, the rig says "
                    f"{cam.width}x{cam.height}: view dropped", throttle_duration_sec=5.0)
                mask = None
            masks.append(mask)
        return self.tracker.update(masks, stamp_ns, items.get(DETECTIONS), budget)

    def _log_transition(self, k: int, result, seconds: float) -> None:
        log = self.get_logger()
        views = len(result.views)
        who = f"{self.ids[k]}: " if len(self.ids) > 1 else ""
        if result.state == "initialising":
            log.info(f"{who}a person appeared ({views} views): estimating the body shape "
                     f"({self.params.startup.frames} frames, start-up took {seconds:.1f} s)")
        elif result.state == "tracking":
            assert self.tracker is not None  # results come from it
            mesh = self.tracker.trackers[k].model  # a shape's factors scale the tracker's mesh
            height = result.shape.height(mesh) if result.shape is not None else float("nan")
            log.info(f"{who}tracking ({self.params.method}); body height {height:.2f} m, "
                     f"fit cost {result.fit_cost:.2f} per view")
        elif result.state == "lost":
            log.warning(f"{who}the fit collapsed: restarting from the visual hull")
        elif result.state == "searching":
            log.info(f"{who}no person in view" if k == 0 or not who else
                     f"{who}nobody else in view")

    def _header(self, msg, stamp_ns: int):
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
        msg.header.frame_id = self.frame_id
        return msg

    def _publishers_by_topic(self) -> dict:
        """Topic of :class:`~hmocap_ros.tracking.tracker_messages.TrackerMessages` -> publishers."""
        out = {"skeleton": [self.pub_skeleton], "skeleton_markers": [self.pub_markers],
               TRACKED_TOPIC: [self.pub_tracked], "body_shape": self.pub_shapes[0][1:]}
        for k, body in enumerate(self.ids):
            out[per_body_topic(body, "joint_states")] = [self.pub_joints[k]]
            out[per_body_topic(body, "body_shape")] = self.pub_shapes[k][:1]
        if self.pub_tf is not None:
            out[TF_TOPIC] = [self.pub_tf]
        out.update({topic: [pub] for topic, pub in self.pub_rep155.items()})
        return out

    def _publish_diagnostics(self, stamp_ns: int, results, seconds: float,
                             picked: PickedSet) -> None:
        diag = self._header(DiagnosticArray(), stamp_ns)
        timing = [KeyValue(key="skipped_frame_sets", value=str(self.skipped_total)),
                  KeyValue(key="skipped_since_last", value=str(self.skipped_unreported)),
                  KeyValue(key="wait_ms", value=f"{picked.waited_ns / 1e6:.1f}")]
        diag.status = [self._status(body, result, seconds, timing)
                       for body, result in zip(self.ids, results)]
        self.pub_diag.publish(diag)
        self.skipped_unreported = 0

    def _status(self, body: str, result, seconds: float, timing: list) -> DiagnosticStatus:
        assert self.rig is not None  # results come once the rig came
        values = [KeyValue(key="state", value=result.state),
                  KeyValue(key="seconds_per_frame", value=f"{seconds:.3f}"),
                  *timing,
                  KeyValue(key="fit_cost", value=f"{result.fit_cost:.4f}"),
                  KeyValue(key="views", value=" ".join(self.rig.names[i] for i in result.views)),
                  KeyValue(key="dropped", value=" ".join(self.rig.names[i] for i in result.dropped)),
                  KeyValue(key="ess_per_layer", value=" ".join(f"{e:.0f}" for e in result.ess)),
                  KeyValue(key="ms_per_layer", value=" ".join(
                      f"{1000 * (d.weight_time_s + d.filter_time_s):.0f}" for d in result.layers))]
        values += [KeyValue(key=f"time_{k}", value=f"{v:.4f}") for k, v in sorted(result.timings.items())]
        if result.extremities is not None:  # dd-hpf: which hands/feet/head were detected
            values.append(KeyValue(key="extremities", value=" ".join(
                n for n, ok in zip(END_EFFECTORS, result.extremities.found) if ok)))
            joints = result.extremities.joint_scores
            values.append(KeyValue(key="joint_detections", value=str(
                0 if joints is None else int((joints > 0).sum()))))
        level = DiagnosticStatus.OK if result.state in ("tracking", "initialising", "searching") else \
            DiagnosticStatus.WARN
        return DiagnosticStatus(level=level, name=f"{self.node_name}: {body}", message=result.state,
                                values=values)


def main(args=None) -> int:
    return run_node(BodyTrackerNode, NODE_NAME, __doc__, (BodyTrackerNodeConfig, TrackerParams), args)


if __name__ == "__main__":
    raise SystemExit(main())
