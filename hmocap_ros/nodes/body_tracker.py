"""body_tracker: the 3D body pose of the person in the room from N foreground masks (thesis ch. 2).

Synchronises the foreground masks of the rig cameras by stamp and runs
:class:`~hmocap_ros.tracking.body_tracker.BodyTracker` on each set: layered particle filtering
of a skinned body with the silhouette XOR weighting (``method``: one of
:data:`~hmocap_ros.tracking.methods.METHODS`, APF, HPF, HPF with approximate partitioning of
observations, or detector-driven HPF), anthropometry estimated when a person appears.

Subscriptions:
  ``camera_rig`` (hmocap_interfaces/CameraRig, latched): the calibration, unless ``rig_file``
  is set; the masks are expected at the rig's resolution.
  ``<camera>/foreground`` (sensor_msgs/Image mono8, sensor-data QoS), per rig camera.
  ``<camera>/skin`` (sensor_msgs/Image mono8, any resolution), per rig camera, with a
  method that uses a detector (``dd-hpf``) only: the extremity detector's maps
  (foreground_segmentation publishes them, each just before its mask). They are not waited for: a frame set is processed when its masks are
  complete, with the maps of its stamp that have arrived (a view without one is not searched
  for hands), so a foreground node that publishes none costs no latency.
Publications (all with the stamp of the frame set):
  ``joint_states`` (sensor_msgs/JointState): the pose parameters (root translation in metres,
  angles in radians) by DoF name, of the first body (``body_id``).
  ``skeleton`` (hmocap_interfaces/Skeleton): 3D joints in the room frame, one message per
  tracked body (``body_id`` says whose).
  ``skeleton_markers`` (visualization_msgs/MarkerArray): joints and bones for RViz/Foxglove,
  one namespace per body.
  ``body_shape`` (hmocap_interfaces/BodyShape, latched): the first body's anthropometry.
  ``humans/bodies/<id>/joint_states`` and ``humans/bodies/<id>/body_shape`` (REP-155 style),
  per body, when ``max_people`` > 1.
  ``diagnostics`` (diagnostic_msgs/DiagnosticArray): per body state, seconds per frame, ESS
  and milliseconds per layer, time per stage, views used and dropped, and with ``dd-hpf`` the
  extremities detected.
Synchronisation (:class:`~hmocap_ros.stamp_sync.StampSynchronizer`): a frame set goes to the
tracker when every camera's mask of its stamp (within ``slop_ms``) is there, or, with a camera
missing, ``max_wait_ms`` after its newest mask arrived (a steady-clock timer polls every
``max_wait_ms / 4``) or once a mask ``max_wait_ms`` newer has come, with at least
``min_views_to_sync`` views; a mask that arrives after its set went out is dropped. The wait
counts only time the node is idle: masks queued while the tracker works on a frame are not given
up on. So the last frames of a stream and a live stream with a dead camera are tracked with at
most ``max_wait_ms`` (plus a timer period) of added delay.

Parameters: ``rig_file``, ``slop_ms``, ``min_views_to_sync``, ``max_wait_ms``,
``queue_depth``, ``seed``, ``body_id``, ``max_people`` and every setting of
:class:`~hmocap_ros.tracking.params.TrackerParams` by its dotted name
(``startup.height_margin``; listed below; the YAML nests them in groups).

Several people (``max_people``): one tracker per person
(:class:`~hmocap_ros.tracking.people_tracker.PeopleTracker`); the first body is the one a
single tracker would follow (the person the cameras see best when the track starts), the
others are ``body_id`` numbered on (``body_0``, ``body_1``, ...). Each followed person costs
a filter run per frame.

A dropped camera is tracked on the remaining views; a frame without a person publishes
nothing but diagnostics; a fit that collapses re-initialises from the visual hull.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point
from hmocap_interfaces.msg import BodyShape as BodyShapeMsg
from hmocap_interfaces.msg import CameraRig, Skeleton
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import Image, JointState
from visualization_msgs.msg import Marker, MarkerArray

from hmocap_ros.body.model import load_body_model
from hmocap_ros.io.conversions import ConversionError, image_to_numpy
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.nodes.common import (LATCHED_QOS, RESULT_QOS, declare_parameters, param, run_node,
                                     sensor_qos)
from hmocap_ros.rig import Rig, RigError, load_rig, rig_from_msg
from hmocap_ros.stamp_sync import StampSynchronizer
from hmocap_ros.tracking.params import TrackerParams
from hmocap_ros.tracking.people_tracker import PeopleTracker, body_ids
from hmocap_ros.tracking.extremity_detection import END_EFFECTORS

NODE_NAME = "body_tracker"


@dataclass(frozen=True)
class BodyTrackerNodeConfig:
    rig_file: str = param("", "Rig calibration YAML; empty = take the rig from the latched camera_rig topic.")
    slop_ms: float = param(5.0, "Largest stamp difference (ms) between the masks of one frame set.")
    min_views_to_sync: int = param(2, "Frame sets with at least this many cameras are processed when a "
                                      "camera drops out (after max_wait_ms); 1 to the number of cameras.")
    max_wait_ms: float = param(200.0, "How long (ms, > 0) a frame set waits for a missing camera after its "
                                      "newest mask arrived (idle time of the node) or until a mask this "
                                      "much newer arrives; then it is processed with the views it has.")
    queue_depth: int = param(5, "Masks queued per camera while the tracker is busy (best effort: older "
                                "ones are dropped, so a live tracker works on recent frames; raise it "
                                "when replaying a bag slowly and every frame must be tracked).")
    seed: int = param(0, "Seed of the particle filter's random generator (repeatable runs).")
    body_id: str = param("body_0", "Body id of the first tracked body in the published messages "
                                   "(REP-155 style); further bodies are numbered on (body_1, ...).")
    max_people: int = param(1, "People followed at once, one tracker each: a bystander the cameras "
                               "see better does not take the user's track, and each person gets "
                               "a body id; every followed person costs a filter run per frame.")


class BodyTrackerNode(Node):
    def __init__(self):
        super().__init__(NODE_NAME)
        self.config = declare_parameters(self, BodyTrackerNodeConfig)
        self.params = declare_parameters(self, TrackerParams)
        self.model = load_body_model("tracking")
        self.rng = np.random.default_rng(self.config.seed)
        if self.config.max_people < 1:
            self.get_logger().fatal(f"max_people must be >= 1, got {self.config.max_people}")
            raise SystemExit(2)
        self.ids = body_ids(self.config.body_id, self.config.max_people)
        self.tracker: PeopleTracker | None = None
        self.sync: StampSynchronizer | None = None
        self.rig: Rig | None = None
        self.frame_id = "room"
        self.last_shape = [None] * len(self.ids)
        self.last_state = ["searching"] * len(self.ids)
        self.frames = 0
        self.busy_ns = 0  # time spent in _process: not waiting time for the synchroniser
        self.pub_skeleton = self.create_publisher(Skeleton, "skeleton", RESULT_QOS)
        self.pub_markers = self.create_publisher(MarkerArray, "skeleton_markers", RESULT_QOS)
        # per body: (joint_states, body_shape); the first body's on the plain topics too
        self.pub_body = [[(self.create_publisher(JointState, "joint_states", RESULT_QOS),
                           self.create_publisher(BodyShapeMsg, "body_shape", LATCHED_QOS))]]
        self.pub_body += [[] for _ in self.ids[1:]]
        if len(self.ids) > 1:
            for k, body in enumerate(self.ids):
                self.pub_body[k].append((
                    self.create_publisher(JointState, f"humans/bodies/{body}/joint_states",
                                          RESULT_QOS),
                    self.create_publisher(BodyShapeMsg, f"humans/bodies/{body}/body_shape",
                                          LATCHED_QOS)))
        self.pub_diag = self.create_publisher(DiagnosticArray, "diagnostics", RESULT_QOS)
        if self.config.max_wait_ms <= 0:
            self.get_logger().fatal(f"max_wait_ms must be > 0, got {self.config.max_wait_ms}")
            raise SystemExit(2)
        # A steady clock: sets with a missing view go out on time whatever /clock does.
        self.create_timer(self.config.max_wait_ms / 4000.0, self._poll_sync,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        if self.config.rig_file:
            try:
                self._set_rig(load_rig(self.config.rig_file))
            except (RigError, OSError) as err:
                self.get_logger().fatal(f"cannot load the rig: {err}")
                raise SystemExit(2) from err
        else:
            self.create_subscription(CameraRig, "camera_rig", self._on_rig, LATCHED_QOS)
            self.get_logger().info("waiting for the rig on camera_rig")

    def _on_rig(self, msg: CameraRig) -> None:
        try:
            rig = rig_from_msg(msg)
        except (RigError, ValueError) as err:
            self.get_logger().error(f"camera_rig: {err}")
            return
        if self.rig is not None and rig.isclose(self.rig):
            return
        self._set_rig(rig)

    def _set_rig(self, rig: Rig) -> None:
        first = self.rig is None
        self.rig = rig
        self.frame_id = rig.frame_id
        self.tracker = PeopleTracker(self.model, rig, self.params, self.rng,
                                     max_people=len(self.ids), ids=self.ids)
        self.use_maps = self.params.tracking_method.uses_detector
        self.maps = {name: {} for name in rig.names}  # camera -> stamp -> skin map (recent)
        self.sync = StampSynchronizer(
            list(rig.names), slop_ns=int(self.config.slop_ms * 1e6),
            queue_size=max(10, self.config.queue_depth), allow_partial=True,
            min_keys=min(self.config.min_views_to_sync, len(rig)),
            max_delay_ns=int(self.config.max_wait_ms * 1e6), max_wait_ns=int(self.config.max_wait_ms * 1e6))
        if first:
            # Subscribe before compiling: masks that arrive during the (cold-cache) warm-up
            # wait in the subscriptions' queues instead of being published to nobody.
            for name in rig.names:
                self.create_subscription(Image, f"{name}/foreground", self._on_mask(name),
                                         sensor_qos(max(1, self.config.queue_depth)))
                if self.use_maps:
                    self.create_subscription(Image, f"{name}/skin", self._on_skin(name),
                                             sensor_qos(max(1, self.config.queue_depth)))
            seconds = self.tracker.warm_up()
            self.get_logger().info(f"kernels ready ({seconds:.1f} s)")
        self.get_logger().info(f"tracking with {len(rig)} cameras ({', '.join(rig.names)}), method "
                               f"{self.params.method}")

    def _mono8(self, msg: Image, topic: str) -> np.ndarray | None:
        try:
            image = image_to_numpy(msg)
        except ConversionError as err:
            self.get_logger().error(f"{topic}: {err}", throttle_duration_sec=5.0)
            return None
        if image.ndim != 2:
            self.get_logger().error(f"{topic} must be mono8, got {msg.encoding}",
                                    throttle_duration_sec=5.0)
            return None
        return image

    def _on_skin(self, name: str):
        def on_skin(msg: Image) -> None:
            if self.rig is None or name not in self.maps:
                return
            image = self._mono8(msg, f"{name}/skin")
            if image is None:
                return
            recent = self.maps[name]
            recent[stamp_to_ns(msg.header.stamp)] = image
            while len(recent) > max(10, self.config.queue_depth):  # masks that never came
                recent.pop(next(iter(recent)))

        return on_skin

    def _map_for(self, name: str, stamp_ns: int) -> np.ndarray | None:
        """The skin map of ``name`` within the slop of ``stamp_ns`` (taken out), or None."""
        recent = self.maps.get(name, {})
        slop = int(self.config.slop_ms * 1e6)
        for stamp in list(recent):
            if abs(stamp - stamp_ns) <= slop:
                return recent.pop(stamp)
        return None

    def _on_mask(self, name: str):
        def on_mask(msg: Image) -> None:
            if self.sync is None or name not in self.rig:
                return
            mask = self._mono8(msg, f"{name}/foreground")
            if mask is None:
                return
            for synced in self.sync.add(name, stamp_to_ns(msg.header.stamp), mask,
                                        now_ns=self._idle_clock_ns()):
                self._process(synced.stamp_ns, synced.items)

        return on_mask

    def _idle_clock_ns(self) -> int:
        """Steady time the node has not spent processing (the synchroniser's arrival clock)."""
        return time.monotonic_ns() - self.busy_ns

    def _poll_sync(self) -> None:
        if self.sync is None:
            return
        for synced in self.sync.poll(self._idle_clock_ns()):
            self._process(synced.stamp_ns, synced.items)

    def _process(self, stamp_ns: int, items: dict) -> None:
        start = time.monotonic_ns()
        try:
            self._track(stamp_ns, items)
        finally:
            self.busy_ns += time.monotonic_ns() - start

    def _track(self, stamp_ns: int, items: dict) -> None:
        log = self.get_logger()
        masks = []
        for cam in self.rig.cameras:
            mask = items.get(cam.name)
            if mask is not None and mask.shape != (cam.height, cam.width):
                log.error(f"{cam.name}/foreground is {mask.shape[1]}x{mask.shape[0]}, the rig says "
                          f"{cam.width}x{cam.height}: view dropped", throttle_duration_sec=5.0)
                mask = None
            masks.append(mask)
        maps = [self._map_for(n, stamp_ns) for n in self.rig.names] if self.use_maps else None
        t0 = time.perf_counter()
        try:
            results = self.tracker.update(masks, stamp_ns, maps)
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
            if result.has_pose:
                self._publish_pose(k, stamp_ns, result)
        self._publish_diagnostics(stamp_ns, results, seconds)

    def _log_transition(self, k: int, result, seconds: float) -> None:
        log = self.get_logger()
        views = len(result.views)
        who = f"{self.ids[k]}: " if len(self.ids) > 1 else ""
        if result.state == "initialising":
            log.info(f"{who}a person appeared ({views} views): estimating the body shape "
                     f"({self.params.startup.frames} frames, start-up took {seconds:.1f} s)")
        elif result.state == "tracking":
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

    def _publish_pose(self, k: int, stamp_ns: int, result) -> None:
        skel = self.model.skeleton
        body = self.ids[k]
        js = self._header(JointState(), stamp_ns)
        js.name = list(skel.dof_names)
        js.position = [float(x) for x in result.params]
        for pub_joints, _ in self.pub_body[k]:
            pub_joints.publish(js)

        sk = self._header(Skeleton(), stamp_ns)
        sk.body_id = body
        sk.joint_names = list(result.joint_names)
        sk.positions = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in result.joints]
        sk.parents = [int(i) for i in self.model.parents]
        sk.fit_error = float(result.fit_cost)
        self.pub_skeleton.publish(sk)
        self.pub_markers.publish(self._markers(k, stamp_ns, result.joints))

        if result.shape is not None and result.shape is not self.last_shape[k]:
            self.last_shape[k] = result.shape
            shape = result.shape
            msg = self._header(BodyShapeMsg(), stamp_ns)
            msg.body_id = body
            msg.entity_names = list(shape.entity_names)
            msg.bone_scale = [float(x) for x in np.ravel(shape.bone_scale)]
            msg.radial_scale = [float(x) for x in np.ravel(shape.radial_scale)]
            msg.global_scale = float(shape.global_scale)
            msg.height = float(shape.height(self.tracker.trackers[k].model))
            for _, pub_shape in self.pub_body[k]:
                pub_shape.publish(msg)

    def _markers(self, k: int, stamp_ns: int, joints: np.ndarray) -> MarkerArray:
        body = self.ids[k]
        spheres = self._header(Marker(), stamp_ns)
        spheres.ns, spheres.id, spheres.type, spheres.action = body, 0, Marker.SPHERE_LIST, Marker.ADD
        spheres.scale.x = spheres.scale.y = spheres.scale.z = 0.06
        # the first body orange as before, the others in other hues
        spheres.color.r, spheres.color.g, spheres.color.b = ((1.0, 0.3, 0.0), (0.2, 0.9, 0.2),
                                                             (1.0, 0.8, 0.1), (0.3, 0.5, 1.0))[k % 4]
        spheres.color.a = 1.0
        spheres.points = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in joints]
        bones = self._header(Marker(), stamp_ns)
        bones.ns, bones.id, bones.type, bones.action = body, 1, Marker.LINE_LIST, Marker.ADD
        bones.scale.x = 0.02
        bones.color.g, bones.color.b, bones.color.a = 0.8, 1.0, 1.0
        for child, parent in enumerate(self.model.parents):
            if parent >= 0:
                bones.points += [spheres.points[parent], spheres.points[child]]
        for m in (spheres, bones):
            m.lifetime.nanosec = 500_000_000  # disappear when tracking stops
        return MarkerArray(markers=[spheres, bones])

    def _publish_diagnostics(self, stamp_ns: int, results, seconds: float) -> None:
        diag = self._header(DiagnosticArray(), stamp_ns)
        diag.status = [self._status(body, result, seconds)
                       for body, result in zip(self.ids, results)]
        self.pub_diag.publish(diag)

    def _status(self, body: str, result, seconds: float) -> DiagnosticStatus:
        values = [KeyValue(key="state", value=result.state),
                  KeyValue(key="seconds_per_frame", value=f"{seconds:.3f}"),
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
        level = DiagnosticStatus.OK if result.state in ("tracking", "initialising", "searching") else \
            DiagnosticStatus.WARN
        return DiagnosticStatus(level=level, name=f"{NODE_NAME}: {body}", message=result.state,
                                values=values)


def main(args=None) -> int:
    return run_node(BodyTrackerNode, NODE_NAME, __doc__, (BodyTrackerNodeConfig, TrackerParams), args)


if __name__ == "__main__":
    raise SystemExit(main())
