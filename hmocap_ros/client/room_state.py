"""The room as an app sees it, kept from the room's messages; no rclpy.

:class:`RoomState` takes the messages of ``skeleton``, ``humans/bodies/tracked``,
``gestures``, ``/tf_static`` and ``camera_rig`` (rclpy messages or rosbags dataclasses) and the
time of the node's clock, keeps the latest :class:`~hmocap_ros.client.bodies.Body` per id and
the latest frame's :class:`~hmocap_ros.client.bodies.Gesture`\\ s in the fixed frame, and
answers what happened as events: ``("body", Body)``, ``("lost", body_id)`` and
``("gesture", Gesture)``. :class:`~hmocap_ros.client.room.Room` feeds it from its subscriptions
and calls the app's callbacks; tests and offline tools feed it from a bag.

The guarantees (docs/client.md):

- a body's pose is the one of its newest stamp; an older one arriving later is dropped;
- a body is lost when ``humans/bodies/tracked`` no longer lists it, when the stamps go back by
  more than :data:`TIME_JUMP_NS` (a replay that starts over, a restarted camera driver), or
  when no ``skeleton`` nor ``tracked`` message came for ``lost_after_ns`` of the node's clock (a
  body_tracker stopped or cut off); a skeleton of a lost body that is not newer than the loss
  is dropped, a newer one brings the body back (an id comes back as a new body);
- a skeleton whose frame has no transform to the fixed frame yet is held (the newest per body)
  and delivered once the transform arrives;
- bad input (a skeleton with fewer positions than joint names, missing joints, a gesture
  without a 3D point, a frame with no transform) is one log line per kind and source, through
  the ``log`` callable; nothing raises.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from hmocap_ros.client.bodies import BadMessage, Body, Gesture, gesture_fields, skeleton_points
from hmocap_ros.client.frames import StaticFrames, rig_frame_transforms
from hmocap_ros.client.geometry import nearest_hand
from hmocap_ros.io.msg_factory import stamp_to_ns

__all__ = ["RoomState", "TIME_JUMP_NS"]

#: (ns) stamps that go back by more than this start the room over (every body lost); less is
#: the spread of one frame set's messages across topics
TIME_JUMP_NS = 1_000_000_000


class RoomState:
    """Bodies and gestures in ``fixed_frame`` (module docstring). ``lost_after_ns`` <= 0 never
    loses a body for silence; ``log`` takes each one-line report."""

    def __init__(self, fixed_frame: str = "world", lost_after_ns: int = 10_000_000_000,
                 log: Callable[[str], None] = print):
        self.fixed_frame = fixed_frame
        self.lost_after_ns = int(lost_after_ns)
        self.log = log
        self.frames = StaticFrames()
        self.bodies: dict[str, Body] = {}
        self.gestures: tuple[Gesture, ...] = ()
        self._pending: dict[str, tuple[Any, int]] = {}  # Skeleton messages waiting for their frame
        self._lost_at: dict[str, int] = {}
        self._newest_stamp: int | None = None
        self._last_heard: int | None = None
        self._reported: set = set()

    @property
    def stamp_ns(self) -> int:
        """The newest stamp of the body messages (0 before the first)."""
        return self._newest_stamp or 0

    def report_once(self, key, text: str) -> None:
        """Log ``text`` the first time ``key`` comes up."""
        if key not in self._reported:
            self._reported.add(key)
            self.log(text)

    # -- frames ---------------------------------------------------------------------------

    def on_tf_static(self, msg, now_ns: int) -> list:
        """A ``/tf_static`` message: its transforms join the tree; held skeletons that can now
        be placed are delivered."""
        for error in self.frames.add_message(msg):
            self.report_once(("tf", error), f"/tf_static: {error}: transform ignored")
        return self._release_pending()

    def on_rig(self, msg, now_ns: int) -> list:
        """A ``camera_rig`` message: the room -> camera transforms join the tree."""
        try:
            transforms = rig_frame_transforms(msg)
        except ValueError as err:
            self.report_once(("rig", str(err)), f"camera_rig: {err}: ignored")
            return []
        for transform in transforms:
            self.frames.add(transform)
        return self._release_pending()

    def _release_pending(self) -> list:
        events = []
        for body_id, (msg, now_ns) in list(self._pending.items()):
            frame = str(msg.header.frame_id)
            if self.frames.lookup(self.fixed_frame, frame) is not None:
                del self._pending[body_id]
                events += self.on_skeleton(msg, now_ns)
        return events

    # -- bodies ---------------------------------------------------------------------------

    def on_skeleton(self, msg, now_ns: int) -> list:
        """A ``skeleton`` message: the body's new pose (module docstring)."""
        try:
            body_id, names, positions, confidence = skeleton_points(msg)
        except BadMessage as err:
            self.report_once(("skeleton", str(msg.body_id), len(msg.positions), len(msg.joint_names)), str(err))
            return []
        stamp = stamp_to_ns(msg.header)
        events = self._heard(stamp, now_ns)
        current = self.bodies.get(body_id)
        if stamp <= self._lost_at.get(body_id, -1) or (current is not None and stamp < current.stamp_ns):
            return events
        frame = str(msg.header.frame_id)
        points = self.frames.transform_points(positions, self.fixed_frame, frame)
        if points is None:
            self._pending[body_id] = (msg, now_ns)
            self.report_once(("frame", frame), f"skeleton in frame '{frame}': no transform to '{self.fixed_frame}' "
                                               "yet (camera_rig_publisher puts it on /tf_static): held until it comes")
            return events
        body = Body(body_id, stamp, self.fixed_frame, names, points, confidence, float(msg.fit_error))
        missing = body.missing_joints
        if missing:
            self.report_once(("missing", body_id), f"skeleton of {body_id} without a position for "
                                                            f"{', '.join(missing)}: those joints answer None")
        self.bodies[body_id] = body
        self._lost_at.pop(body_id, None)
        events.append(("body", body))
        return events

    def on_tracked(self, msg, now_ns: int) -> list:
        """A ``humans/bodies/tracked`` message (hri_msgs/IdsList): the bodies it does not list are lost."""
        stamp = stamp_to_ns(msg.header)
        events = self._heard(stamp, now_ns)
        tracked = {str(i) for i in msg.ids}
        for body_id in [b for b in self.bodies if b not in tracked]:
            events.append(self._lose(body_id, stamp))
        for body_id in [b for b in self._pending if b not in tracked]:
            del self._pending[body_id]
        return events

    def on_timer(self, now_ns: int) -> list:
        """The node's clock at ``now_ns``: after ``lost_after_ns`` of silence every body is lost."""
        if (not self.bodies or self.lost_after_ns <= 0 or self._last_heard is None
                or now_ns - self._last_heard <= self.lost_after_ns):
            return []
        self.log(f"no skeleton nor tracked list for {(now_ns - self._last_heard) / 1e9:.1f} s: "
                 f"{', '.join(sorted(self.bodies))} lost")
        return [self._lose(body_id, self.stamp_ns) for body_id in list(self.bodies)]

    def _heard(self, stamp: int, now_ns: int) -> list:
        """Note a body message of ``stamp``; a jump back loses every body."""
        self._last_heard = now_ns
        events = []
        if self._newest_stamp is not None and stamp < self._newest_stamp - TIME_JUMP_NS:
            self.log(f"the stamps went back {(self._newest_stamp - stamp) / 1e9:.2f} s (a replay that started "
                     "over, a restarted driver): the room starts over"
                     + (f", {', '.join(sorted(self.bodies))} lost" if self.bodies else ""))
            events = [self._lose(body_id, stamp) for body_id in list(self.bodies)]
            self._lost_at.clear()
            self._pending.clear()
            self._newest_stamp = stamp
        elif self._newest_stamp is None or stamp > self._newest_stamp:
            self._newest_stamp = stamp
        return events

    def _lose(self, body_id: str, stamp: int) -> tuple[str, str]:
        del self.bodies[body_id]
        self._lost_at[body_id] = stamp
        return ("lost", body_id)

    # -- gestures -------------------------------------------------------------------------

    def on_gestures(self, msg, now_ns: int) -> list:
        """A ``gestures`` message (GestureArray): its gestures with their points in the fixed frame."""
        stamp = stamp_to_ns(msg.header)
        frame = str(msg.header.frame_id)
        out = []
        for g in msg.gestures:
            point, fields = gesture_fields(g)
            if point is None:
                self.report_once(("no point", frame), f"gesture {fields['name']} in '{frame}' without a 3D point "
                                                      "(gesture_detection has no depth/camera_info?): point None")
            else:
                point = self.frames.transform_points(point, self.fixed_frame, frame)
                if point is None:
                    self.report_once(("frame", frame), f"gestures in frame '{frame}': no transform to "
                                                       f"'{self.fixed_frame}' on /tf_static (place the depth camera "
                                                       "with a static transform): point None")
            out.append(Gesture(stamp_ns=stamp, source_frame=frame, point=point, **fields))
        self.gestures = tuple(out)
        return [("gesture", g) for g in out]

    def body_of(self, gesture: Gesture, max_distance: float = 0.5) -> Body | None:
        """The body that made ``gesture``: the one whose hand joint is nearest to its 3D point
        (:func:`~hmocap_ros.client.geometry.nearest_hand`), within ``max_distance`` m; None when
        the gesture has no point or no hand is that near. The bodies are at their newest poses,
        which may be older than the gesture."""
        if gesture.point is None:
            return None
        found = nearest_hand(self.bodies.values(), gesture.point, max_distance)
        return None if found is None else found[0]
