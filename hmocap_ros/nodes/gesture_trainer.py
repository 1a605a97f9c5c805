"""gesture_trainer: teach the room a gesture in front of the depth camera (thesis sec. 3.4.1).

A thin ROS layer over :class:`~hmocap_ros.gestures.trainer.Trainer`: a session runs ``rounds``
rounds of *do gesture -> update positive -> release -> do negatives*, then *testing*; the
online forest (sec. 3.3.1) learns from the frames of the learning states, with negatives
mined on the fly (sec. 3.3.2), and the automatic threshold of sec. 3.4.1 is kept per gesture in
the forest file. When the session is done the forest file is written atomically (temporary
file renamed into place) and ``gesture_detection`` started with ``model_file`` at that path
picks it up without a restart (it watches the file).

Subscriptions:
  ``depth/image_raw`` (sensor_msgs/Image 16UC1/mono16 millimetres or 32FC1 metres by REP 118,
  or any unit through ``detector.depth_unit_m``; with ``image_transport:=compressedDepth``
  ``depth/image_raw/compressedDepth``, sensor_msgs/CompressedImage; ``image_reliability`` with a queue of
  ``queue_depth``: :func:`~hmocap_ros.nodes.common.image_qos`), as gesture_detection reads it.
  ``depth/camera_info`` (sensor_msgs/CameraInfo, the same QoS): the focal length a new forest
  is grown at.
Services:
  ``gesture_trainer/teach`` (hmocap_interfaces/TeachGesture): start a session (gesture name,
  forest file, new forest or not, extend a known gesture or not); refused with the reason.
  ``gesture_trainer/cancel`` (std_srvs/Trigger): stop the session; the forest is put back as it
  was when the current round began.
  ``gesture_trainer/save`` (std_srvs/Trigger): write the forest file now.
Publications:
  ``gesture_trainer/state`` (hmocap_interfaces/TrainerState): state, gesture, round, seconds
  left, progress, threshold, instruction, box, detection; after every frame and on changes.
  ``gesture_trainer/feedback`` (sensor_msgs/Image rgb8, only with ``publish_feedback``): the
  depth frame false-coloured with the box, the taught gesture's density, the detections and
  the instruction (fig. 3.11), for a screen in the room (Foxglove, rqt_image_view).
  ``/diagnostics`` (diagnostic_msgs/DiagnosticArray, every ``diagnostics_period`` s): frames
  received and processed, frames skipped (gaps in the stamps longer than 1.5 frame periods),
  mean and maximum milliseconds per frame, and the lag (how long the last frame waited in the
  queue between its arrival and its processing); WARN when frames were skipped in the period
  or the lag exceeds ``max_lag_s``.

The session, its choices and results: docs/gestures_interactive.md. Parameters: ``--help``
prints them after this text.

Bad input is logged (throttled) and the node keeps running: a wrong encoding, data shorter
than its step, a teach request for a forest file that does not exist (or exists, for a new
forest), that cannot be read or was grown at another focal length, a gesture name the forest
knows (without ``extend``). A request while a session runs is refused (cancel first). A request
before the first camera_info waits for it (``camera_info_timeout_s``), then is refused. Stamps
that go back in time (a camera or replay starting over) continue the session. A session that
gets no frame for ``camera_timeout_s`` (the camera stopped) is cancelled; one in which nothing
moved in view (nobody in the room) ends undone: in both cases the forest file is not written,
and the state's instruction says why. An offline forest file (e.g. the shipped forest) is
continued online: the taught gesture joins its classes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from hmocap_interfaces.msg import Gesture, TrainerState
from hmocap_interfaces.srv import TeachGesture
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import CameraInfo
from std_srvs.srv import Trigger

from hmocap_ros.geometry import PinholeCamera
from hmocap_ros.gestures.depth_features import depth_to_metres
from hmocap_ros.gestures.forest_file import ForestFileError, load_forest
from hmocap_ros.gestures.trainer import INSTRUCTIONS, Trainer, TrainerParams, TrainerStatus
from hmocap_ros.gestures.trainer_feedback import feedback_image
from hmocap_ros.io.conversions import numpy_to_image
from hmocap_ros.io.msg_factory import RclpyFactory, ns_to_stamp, stamp_to_ns
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
from hmocap_ros.nodes.gesture_detection import DEPTH_ENCODINGS

NODE_NAME = "gesture_trainer"


@dataclass(frozen=True)
class TrainerNodeConfig:
    forest_file: str = param("gestures.forest.npz", "Forest file a teach request without one teaches into "
                                                     "(relative paths from the node's working folder).")
    save_when_taught: bool = param(True, "Write the forest file when a session is done.")
    publish_feedback: bool = param(True, "Publish the feedback image on gesture_trainer/feedback.")
    queue_depth: int = param(30, "Depth images queued while the node is busy (>= 1): frames that overflow "
                                 "it are lost and counted as skipped.")
    image_reliability: str = image_reliability_param()
    image_transport: str = image_transport_param(depth=True)
    diagnostics_period: float = param(1.0, "Seconds between diagnostics messages (0 = none).")
    max_lag_s: float = param(0.5, "Diagnostics warn when processing is more than this many seconds behind "
                                  "the stream.")
    seed: int = param(0, "Seed of the trainer's random draws (candidate tests, bagging, samples).")
    camera_info_timeout_s: float = param(
        10.0, "A teach request that comes before the first depth/camera_info waits this many seconds "
              "(> 0) for it, then is refused.")
    camera_timeout_s: float = param(
        10.0, "A session that gets no depth frame for this many seconds (> 0: the camera stopped) is "
             "cancelled: the forest goes back to what it was when the round began, nothing is written.")


@dataclass
class FrameStats:
    """Counters of the depth stream for the diagnostics (node docstring)."""

    received: int = 0
    processed: int = 0
    skipped: int = 0
    skipped_reported: int = 0
    seconds: float = 0.0
    max_seconds: float = 0.0
    period_ns: int = 0
    last_stamp: int | None = None
    lag_s: float = 0.0

    def frame(self, stamp_ns: int, waited_s: float) -> None:
        """Count a frame that waited ``waited_s`` in the queue: stamp gaps longer than 1.5 of the
        shortest period seen count as skipped frames."""
        self.received += 1
        if self.last_stamp is not None and stamp_ns > self.last_stamp:
            gap = stamp_ns - self.last_stamp
            self.period_ns = gap if self.period_ns == 0 else min(self.period_ns, gap)
            if gap > 1.5 * self.period_ns:
                self.skipped += int(round(gap / self.period_ns)) - 1
        self.last_stamp = stamp_ns
        self.lag_s = max(0.0, float(waited_s))

    def done(self, seconds: float) -> None:
        self.processed += 1
        self.seconds += seconds
        self.max_seconds = max(self.max_seconds, seconds)


def state_message(status: TrainerStatus, frame_id: str, forest_file: str) -> TrainerState:
    """The TrainerState message of a trainer status."""
    msg = TrainerState()
    msg.header.stamp = ns_to_stamp(status.stamp_ns)
    msg.header.frame_id = frame_id
    msg.state, msg.gesture = status.state, status.gesture
    msg.round, msg.rounds = int(status.round), int(status.rounds)
    msg.seconds_left, msg.progress = float(status.seconds_left), float(status.progress)
    msg.threshold_valid = status.threshold is not None
    msg.threshold = float(status.threshold) if status.threshold is not None else float("nan")
    msg.instruction = status.instruction
    msg.box_u, msg.box_v, msg.box_half_size = (float(x) for x in status.box)
    msg.known_gestures = list(status.known_gestures)
    det = status.detection
    msg.detected = det is not None
    if det is not None:
        msg.detection = Gesture(name=det.name, class_id=int(det.class_id), score=float(det.score),
                                volume=float(det.volume), u=float(det.u), v=float(det.v))
    msg.samples = int(status.samples)
    msg.forest_file = forest_file
    msg.shown_gesture = status.rehearsed
    return msg


class GestureTrainer(Node):
    def __init__(self):
        super().__init__(NODE_NAME)
        self.config = declare_parameters(self, TrainerNodeConfig)
        self.params = declare_parameters(self, TrainerParams)
        image = image_qos(self.config.image_reliability, self.config.queue_depth)
        self.factory = RclpyFactory()
        self.trainer: Trainer | None = None
        self.forest_path: Path | None = None
        self.camera: PinholeCamera | None = None
        self.frame_id = ""
        self.stats = FrameStats()
        self.last_status: TrainerStatus | None = None
        self.state_pub = self.create_publisher(TrainerState, "gesture_trainer/state", RESULT_QOS)
        self.feedback_pub = (create_image_publisher(self, "gesture_trainer/feedback", self.config.queue_depth)
                             if self.config.publish_feedback else None)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", RESULT_QOS)
        self.create_subscription(CameraInfo, "depth/camera_info", self._on_info, image)
        create_image_subscription(self, "depth/image_raw", self.config.image_transport, self._on_depth, image)
        self._info_waiters: list = []
        self._teach_waiting = False
        self._last_frame_wall: float | None = None
        self._restarts = 0
        if self.config.camera_info_timeout_s <= 0 or self.config.camera_timeout_s <= 0:
            raise ValueError("camera_info_timeout_s and camera_timeout_s must be > 0")
        self.create_timer(min(0.5, self.config.camera_timeout_s / 2), self._check_camera)
        # its own callback group: a request waiting for camera_info must not hold the group of the
        # subscriptions and timers that end the wait
        self.create_service(TeachGesture, "gesture_trainer/teach", self._on_teach,
                            callback_group=MutuallyExclusiveCallbackGroup())
        self.create_service(Trigger, "gesture_trainer/cancel", self._on_cancel)
        self.create_service(Trigger, "gesture_trainer/save", self._on_save)
        if self.config.diagnostics_period > 0:
            self.create_timer(self.config.diagnostics_period, self._publish_diagnostics)
        self.get_logger().info(f"gesture trainer ready: call gesture_trainer/teach (forest file "
                               f"{self.config.forest_file})")

    # -- services -----------------------------------------------------------------------

    def _trainer_for(self, path: Path, new_forest: bool) -> Trainer:
        """The trainer of forest file ``path`` (the current one when it is that file)."""
        if self.trainer is not None and self.forest_path == path and not new_forest:
            return self.trainer
        focal = self.camera.fx if self.camera is not None else None
        rng = np.random.default_rng(self.config.seed)
        if new_forest:
            if path.exists():
                raise ValueError(f"{path} exists: teach into it with new_forest false, or name another file")
            if not path.parent.is_dir():
                raise ValueError(f"folder {path.parent} does not exist")
            if focal is None:
                raise ValueError("no depth/camera_info yet: a new forest needs the camera's focal length")
            return Trainer(None, self.params, rng, focal_px=focal)
        if not path.exists():
            raise ValueError(f"no forest file {path} (new_forest true starts one)")
        try:
            forest = load_forest(path)
        except (ForestFileError, OSError) as err:
            raise ValueError(f"cannot use the forest file {path}: {err}") from err
        trainer = Trainer(forest, self.params, rng, focal_px=focal)
        state = forest.meta.get("online", {}).get("rng_state")
        if state:
            trainer.rng.bit_generator.state = state
        return trainer

    async def _camera_info(self) -> bool:
        """Wait (without blocking the node) for the first depth/camera_info, at most
        ``camera_info_timeout_s``; whether one came."""
        if self.camera is not None:
            return True
        future = Future()
        self._info_waiters.append(future)

        def give_up():
            if not future.done():
                future.set_result(False)

        timer = self.create_timer(self.config.camera_info_timeout_s, give_up)
        try:
            return bool(await future)
        finally:
            timer.cancel()
            self.destroy_timer(timer)

    async def _on_teach(self, request, response):
        log = self.get_logger()
        busy = self._teach_waiting or (self.trainer is not None and self.trainer.state not in ("idle", "done"))
        if busy:
            response.success = False
            response.message = ("another teach request is waiting for depth/camera_info" if self._teach_waiting else
                                f"already teaching '{self.trainer.gesture}' (state {self.trainer.state}): cancel first")
            log.error(response.message)
            return response
        self._teach_waiting = True
        try:
            has_camera = await self._camera_info()
        finally:
            self._teach_waiting = False
        if not has_camera:
            response.success = False
            response.message = (f"no depth/camera_info within {self.config.camera_info_timeout_s:g} s: is the "
                                f"depth camera running? (the forest learns at the camera's focal length)")
            log.error(f"teach '{request.gesture}': {response.message}")
            return response
        path = Path(request.forest_file or self.config.forest_file).expanduser().resolve()
        try:
            trainer = self._trainer_for(path, bool(request.new_forest))
            stamp = self.stats.last_stamp  # None before any frame: the session starts at the first one
            trainer.start(request.gesture, stamp, extend=bool(request.extend))
        except ValueError as err:
            response.success = False
            response.message = str(err)
            log.error(f"teach '{request.gesture}': {err}")
            return response
        self.trainer, self.forest_path = trainer, path
        self._last_frame_wall = time.monotonic()  # the camera's silence counts from the session's start
        p = self.params
        response.success = True
        response.message = (f"teaching '{trainer.gesture}' into {path}: {p.rounds} rounds of "
                            f"{p.round_s(len(trainer.rehearsed)):g} s and {p.testing_s:g} s of testing"
                            + (f", rehearsing {', '.join(trainer.rehearsed)}" if trainer.rehearsed else ""))
        log.info(response.message)
        self._publish_state(trainer.status(stamp or 0, *self._image_size()))
        return response

    def _on_cancel(self, _request, response):
        if self.trainer is None or self.trainer.state in ("idle", "done"):
            response.success = False
            response.message = "no session to cancel"
            return response
        gesture, rnd = self.trainer.gesture, self.trainer.round
        self.trainer.cancel()
        response.success = True
        response.message = (f"cancelled teaching '{gesture}' after {rnd - 1} complete round(s): the forest "
                            f"is as it was before the round")
        self.get_logger().info(response.message)
        self._publish_state(self.trainer.status(self.stats.last_stamp or 0, *self._image_size()))
        return response

    def _on_save(self, _request, response):
        response.success, response.message = self._save()
        return response

    def _save(self) -> tuple[bool, str]:
        if self.trainer is None or self.trainer.online is None:
            return False, "no forest yet: teach a gesture first"
        try:
            path = self.trainer.save(self.forest_path)
        except (OSError, ValueError) as err:
            self.get_logger().error(f"cannot write {self.forest_path}: {err}")
            return False, f"cannot write {self.forest_path}: {err}"
        message = f"forest with {', '.join(self.trainer.online.class_names[1:])} written to {path}"
        self.get_logger().info(message)
        return True, message

    # -- input --------------------------------------------------------------------------

    def _image_size(self) -> tuple[int, int]:
        if self.camera is not None:
            return self.camera.width, self.camera.height
        return 640, 480

    def _on_info(self, msg: CameraInfo) -> None:
        self.camera = depth_camera_from_info(msg, self.camera, self.get_logger())
        if self.camera is not None:
            for future in self._info_waiters:
                if not future.done():
                    future.set_result(True)
            self._info_waiters.clear()

    def _check_camera(self) -> None:
        """Cancel a session whose camera stopped (no frame for ``camera_timeout_s``)."""
        trainer = self.trainer
        if trainer is None or trainer.state in ("idle", "done") or self._last_frame_wall is None:
            return
        silent = time.monotonic() - self._last_frame_wall
        if silent < self.config.camera_timeout_s:
            return
        gesture, rnd = trainer.gesture, trainer.round
        trainer.cancel()
        reason = (f"no depth frame for {silent:.1f} s (the camera stopped): teaching '{gesture}' cancelled in "
                  f"round {rnd}; the forest is as it was when the round began, nothing written")
        self.get_logger().error(reason)
        status = trainer.status(self.stats.last_stamp or 0, *self._image_size())
        self._publish_state(replace(status, instruction=reason))

    def _on_depth(self, msg, info) -> None:
        log = self.get_logger()
        stamp = stamp_to_ns(msg.header.stamp)
        received = info.get("received_timestamp", 0) if info else 0
        self.stats.frame(stamp, (time.time_ns() - received) * 1e-9 if received else 0.0)
        depth = depth_from_msg(msg, DEPTH_ENCODINGS, log)
        if depth is None:
            return
        self._last_frame_wall = time.monotonic()
        self.frame_id = msg.header.frame_id
        t0 = time.perf_counter()
        trainer = self.trainer
        if trainer is None:
            status = TrainerStatus("idle", "", 0, self.params.rounds, 0.0, None, INSTRUCTIONS["idle"].format(g=""),
                                   (0.0, 0.0, 0.0), None, (), stamp, ())
        else:
            try:
                status = trainer.on_frame(depth, stamp)
            except ValueError as err:
                log.error(f"depth/image_raw: {err}", throttle_duration_sec=5.0)
                return
            if trainer.restarts != self._restarts and trainer.state not in ("idle", "done"):
                log.warning(f"depth/image_raw: stamps went back in time (the camera started over); teaching "
                            f"'{trainer.gesture}' goes on")
            self._restarts = trainer.restarts
        self.stats.done(time.perf_counter() - t0)
        self._last_frame_wall = time.monotonic()  # a long first frame (kernels compiling) is no silence
        previous = self.last_status
        self._publish_state(status)
        if self.feedback_pub is not None:
            self._publish_feedback(depth, status, msg.header.frame_id)
        if previous is not None and previous.state != status.state:
            log.info(f"'{status.gesture}': {status.state}" + (f" (round {status.round}/{status.rounds})"
                                                              if status.round else ""))
            if status.state == "done":
                assert trainer is not None  # with no trainer the status is idle
                if not trainer.taught:
                    log.error(status.instruction + " Nothing written.")
                else:
                    th = trainer.thresholds.get(status.gesture)
                    log.info(f"'{status.gesture}' is taught" + (f", threshold {th:.3f}" if th is not None else ""))
                    if self.config.save_when_taught:
                        self._save()

    def _publish_state(self, status: TrainerStatus) -> None:
        self.last_status = status
        self.state_pub.publish(state_message(status, self.frame_id, str(self.forest_path or "")))

    def _publish_feedback(self, depth: np.ndarray, status: TrainerStatus, frame_id: str) -> None:
        trainer = self.trainer
        fmt = self.params.detector.depth_format
        metres = depth_to_metres(depth, fmt, fmt.max_depth_m + 1.0)
        metres[metres > fmt.max_depth_m] = 0.0
        prob = None
        detector = trainer.detector if trainer is not None else None
        if trainer is not None and detector is not None and trainer.gesture in detector.forest.class_names:
            prob = detector.probability_image(detector.forest.class_names.index(trainer.gesture))
        image = feedback_image(metres, status, prob)
        self.feedback_pub.publish(numpy_to_image(image, "rgb8", status.stamp_ns, frame_id, self.factory))

    def _publish_diagnostics(self) -> None:
        s = self.stats
        skipped = s.skipped - s.skipped_reported
        s.skipped_reported = s.skipped
        behind = s.lag_s > self.config.max_lag_s
        level = DiagnosticStatus.WARN if skipped or behind else DiagnosticStatus.OK
        ms = 1e3 * s.seconds / s.processed if s.processed else 0.0
        state = self.trainer.state if self.trainer is not None else "idle"
        message = state
        if skipped:
            message += f"; {skipped} frames skipped"
        if behind:
            message += f"; {s.lag_s:.2f} s behind the stream"
        out = DiagnosticArray()
        out.header.stamp = self.get_clock().now().to_msg()
        out.status.append(DiagnosticStatus(
            level=level, name=f"{NODE_NAME}: depth", hardware_id=self.frame_id or "depth", message=message,
            values=[KeyValue(key="frames_received", value=str(s.received)),
                    KeyValue(key="frames_processed", value=str(s.processed)),
                    KeyValue(key="frames_skipped", value=str(s.skipped)),
                    KeyValue(key="ms_per_frame", value=f"{ms:.2f}"),
                    KeyValue(key="max_ms_per_frame", value=f"{1e3 * s.max_seconds:.2f}"),
                    KeyValue(key="lag_s", value=f"{s.lag_s:.3f}")]))
        self.diag_pub.publish(out)


def main(args=None) -> int:
    return run_node(GestureTrainer, NODE_NAME, __doc__, (TrainerNodeConfig, TrainerParams), args)


if __name__ == "__main__":
    raise SystemExit(main())
