"""The simulated user of ``hmocap sim teacher``: it follows gesture_trainer's instructions over DDS.

The user of :class:`~hmocap_sim.gesture_teacher.GestureTeacher` (a person in a furnished room of
the gesture simulator) in a closed loop with a running ``gesture_trainer`` node: it subscribes
``gesture_trainer/state`` (hmocap_interfaces/TrainerState) and publishes, frame by frame, the
depth image of what the last state asks (the gesture held in the box, releasing, everyday
motions, near misses of the taught gesture and unknown gestures as negatives) on
``depth/image_raw`` (16UC1 mm) with ``depth/camera_info``, stamped ``1 / fps`` apart. A real
user in front of a real depth camera replaces it one for one.

Closed loop: after each frame the teacher waits (up to ``--wait`` wall seconds) for the
trainer's state of that frame before rendering the next, so a slow machine slows the session
down instead of dropping frames, and a run repeats; ``--wait 0`` publishes at the frame rate
without waiting. With ``--teach GESTURE`` it asks the trainer to teach that gesture
(``gesture_trainer/teach``) once the trainer answers its frames, follows the session to its
end and, with ``--hold-after S``, then holds the gesture in the box for S more seconds (for a
detector to find it). Exit status 2 with one line when the trainer refuses the request or
does not answer, or when the session ends without teaching (nothing moved in view).
"""

from __future__ import annotations

import argparse
import time
from types import SimpleNamespace

__all__ = ["TeacherError", "run_teacher"]


class TeacherError(RuntimeError):
    """The session cannot go on: nothing subscribes, the trainer refuses or does not answer,
    or the session ends without teaching. The message is the one line to print."""


def _status(msg) -> SimpleNamespace:
    """What the simulated user reads of a TrainerState."""
    return SimpleNamespace(state=msg.state, gesture=msg.gesture, box=(msg.box_u, msg.box_v, msg.box_half_size),
                           known_gestures=tuple(msg.known_gestures), rehearsed=msg.shown_gesture)


def run_teacher(ns: SimpleNamespace | argparse.Namespace) -> int:
    """The closed loop with a running gesture_trainer (the module docstring); ``ns`` holds the
    options of ``hmocap sim teacher`` (:mod:`hmocap_sim.commands.teacher`). Returns 0 at the
    end of the session or of ``--duration``; raises :class:`TeacherError`."""
    import rclpy
    from hmocap_interfaces.msg import TrainerState
    from hmocap_interfaces.srv import TeachGesture
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo, Image

    from hmocap_ros.io.conversions import dict_to_camera_info, numpy_to_image
    from hmocap_ros.io.msg_factory import RclpyFactory, stamp_to_ns
    from hmocap_ros.nodes.common import RESULT_QOS
    from hmocap_sim.gesture_teacher import GestureTeacher

    teacher = GestureTeacher(seed=ns.seed, width=ns.width, height=ns.height, fps=ns.fps, subject_id=ns.subject,
                             sensor=ns.sensor,
                             layout_id=ns.layout)
    cam = teacher.camera
    rclpy.init()
    node = rclpy.create_node("simulated_teacher")
    log = node.get_logger()
    factory = RclpyFactory()
    frames_qos = QoSProfile(depth=30, reliability=ReliabilityPolicy.RELIABLE)
    pub_depth = node.create_publisher(Image, "depth/image_raw", frames_qos)
    pub_info = node.create_publisher(CameraInfo, "depth/camera_info", frames_qos)
    latest = {}

    def on_state(msg):
        latest["msg"] = msg
        latest["stamp"] = stamp_to_ns(msg.header.stamp)

    node.create_subscription(TrainerState, f"{ns.trainer}/state", on_state, RESULT_QOS)
    status = SimpleNamespace(state="idle", gesture="", box=(0.5 * cam.width, 0.45 * cam.height, 1.0),
                             known_gestures=())
    rc, published, requested, done_at, shown = 0, 0, not ns.teach, None, ""
    limit = None if ns.duration is None else int(round(ns.duration * ns.fps))
    hold = int(round(ns.hold_after * ns.fps))
    try:
        end = time.monotonic() + 30.0
        while pub_depth.get_subscription_count() < 1 and time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
        if pub_depth.get_subscription_count() < 1:
            raise TeacherError("nothing subscribes depth/image_raw (is gesture_trainer running?)")
        client = node.create_client(TeachGesture, f"{ns.trainer}/teach")
        while limit is None or published < limit:
            t_frame = time.monotonic()
            depth, stamp = teacher.next_frame(status)
            pub_info.publish(dict_to_camera_info(cam.to_camera_info_dict(), stamp, factory))
            pub_depth.publish(numpy_to_image(depth, "16UC1", stamp, "depth_optical_frame", factory))
            published += 1
            end = time.monotonic() + ns.wait
            while ns.wait > 0 and latest.get("stamp") != stamp and time.monotonic() < end:
                rclpy.spin_once(node, timeout_sec=0.01)
            rclpy.spin_once(node, timeout_sec=0.0)
            if ns.wait == 0:
                time.sleep(max(0.0, 1.0 / ns.fps - (time.monotonic() - t_frame)))
            msg = latest.get("msg")
            if not requested and msg is not None:
                requested = True
                if not client.wait_for_service(timeout_sec=30.0):
                    raise TeacherError(f"no service {ns.trainer}/teach")
                future = client.call_async(TeachGesture.Request(gesture=ns.teach, forest_file=ns.forest,
                                                                new_forest=ns.new_forest, extend=ns.extend))
                rclpy.spin_until_future_complete(node, future, timeout_sec=60.0)
                answer = future.result()
                if answer is None or not answer.success:
                    why = answer.message if answer is not None else "no answer"
                    raise TeacherError(f"the trainer refused to teach '{ns.teach}': {why}")
                log.info(answer.message)
                continue
            if done_at is not None:
                if published - done_at >= hold:
                    break
                continue
            if msg is None:
                continue
            status = _status(msg)
            if msg.state != shown:
                shown = msg.state
                log.info(f"{msg.state} '{msg.gesture}' round {msg.round}/{msg.rounds}: {msg.instruction}")
            if ns.teach and msg.gesture == ns.teach and msg.state == "done" and "not taught" in msg.instruction:
                raise TeacherError(str(msg.instruction))
            if ns.teach and msg.gesture == ns.teach and msg.state == "done":
                done_at = published
                status = SimpleNamespace(state="testing", gesture=ns.teach, box=status.box,
                                         known_gestures=status.known_gestures)
                if hold:
                    log.info(f"holding '{ns.teach}' in the box for {ns.hold_after:g} s")
    except KeyboardInterrupt:
        pass
    finally:
        log.info(f"published {published} frames")
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return rc
