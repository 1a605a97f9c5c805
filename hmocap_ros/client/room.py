"""``Room``: the room's outputs on an app's rclpy node, as bodies and gestures in one fixed frame.

Subscriptions (relative names, remappable; all reliable, as the nodes publish them):
  ``skeleton`` (hmocap_interfaces/Skeleton, body_tracker: every body's joints), ``humans/bodies/tracked``
  (hri_msgs/IdsList, REP-155: the bodies tracked now), ``gestures`` (hmocap_interfaces/GestureArray,
  gesture_detection), ``camera_rig`` (hmocap_interfaces/CameraRig, latched) and ``/tf_static``
  (tf2_msgs/TFMessage, transient local: ``world`` -> ``room`` -> cameras, and the depth camera's
  pose where it is published).
Publications: none. Parameters: none (the app passes ``fixed_frame`` and ``lost_after_s``).

Every message goes through :class:`~hmocap_ros.client.room_state.RoomState` (the guarantees are
there and in docs/client.md); its events call the app's ``on_body(body)``, ``on_gesture(gesture)``
and ``on_body_lost(body_id)`` in the node's executor, in the order the messages came.
"""

from __future__ import annotations

from collections.abc import Callable

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from hmocap_ros.client.bodies import Body, Gesture
from hmocap_ros.client.places import PlacesFile
from hmocap_ros.client.room_state import RoomState
from hmocap_ros.config_files import find_config_file

__all__ = ["Room", "EXAMPLE_PLACES"]

#: The places and zones of the example room (config/), for an app given no file.
EXAMPLE_PLACES = "places_example.yaml"
#: Outputs: reliable, volatile, keep last 10 (as RESULT_QOS of the nodes).
OUTPUT_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
#: /tf_static as tf2's listener takes it: every static broadcaster's latched message.
TF_STATIC_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
LATCHED_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: (s) period of the check for a silent tracker and for changed place files
TIMER_PERIOD_S = 0.5


class Room:
    """The room's bodies and gestures for an app running on ``node`` (module docstring).

    fixed_frame: the +Z-up frame everything is expressed in (REP 103; ``world`` is
    camera_rig_publisher's); lost_after_s: a tracker silent this long (node clock) loses every
    body (0: never); on_body, on_gesture, on_body_lost: the app's callbacks (or set the
    attributes later).
    """

    def __init__(self, node: Node, fixed_frame: str = "world", lost_after_s: float = 10.0,
                 on_body: Callable[[Body], None] | None = None,
                 on_gesture: Callable[[Gesture], None] | None = None,
                 on_body_lost: Callable[[str], None] | None = None):
        from hmocap_interfaces.msg import CameraRig, GestureArray, Skeleton
        from hri_msgs.msg import IdsList
        from tf2_msgs.msg import TFMessage

        self.node = node
        self.on_body, self.on_gesture, self.on_body_lost = on_body, on_gesture, on_body_lost
        self.state = RoomState(fixed_frame, int(lost_after_s * 1e9), node.get_logger().warning)
        self.places_files: list[PlacesFile] = []
        feeds = ((Skeleton, "skeleton", self.state.on_skeleton, OUTPUT_QOS),
                 (IdsList, "humans/bodies/tracked", self.state.on_tracked, OUTPUT_QOS),
                 (GestureArray, "gestures", self.state.on_gestures, OUTPUT_QOS),
                 (CameraRig, "camera_rig", self.state.on_rig, LATCHED_QOS),
                 (TFMessage, "/tf_static", self.state.on_tf_static, TF_STATIC_QOS))
        self.subscriptions = [node.create_subscription(cls, topic, self._feed(handler), qos)
                              for cls, topic, handler, qos in feeds]
        self.timer = node.create_timer(TIMER_PERIOD_S, self._tick)

    @property
    def fixed_frame(self) -> str:
        return self.state.fixed_frame

    @property
    def bodies(self) -> dict[str, Body]:
        """The bodies tracked now, by id, each at its newest pose."""
        return self.state.bodies

    @property
    def gestures(self) -> tuple[Gesture, ...]:
        """The gestures of the newest depth frame (empty when it had none)."""
        return self.state.gestures

    @property
    def stamp_ns(self) -> int:
        """The newest stamp of the body messages (``skeleton``, ``humans/bodies/tracked``), 0 before the first."""
        return self.state.stamp_ns

    def body_of(self, gesture: Gesture, max_distance: float = 0.5) -> Body | None:
        """The body that made ``gesture``: the one whose hand joint is nearest to its 3D point,
        within ``max_distance`` m, or None (:meth:`RoomState.body_of`)."""
        return self.state.body_of(gesture, max_distance)

    def load_places(self, path: str, section: str) -> PlacesFile:
        """The places of ``section`` (``places`` or ``zones``) of the YAML file ``path`` (empty:
        the package's config/places_example.yaml), in the fixed frame; read again when the
        file changes. Each problem of the file is one warning; the app goes on without the
        places it could not read."""
        if not path:
            found = find_config_file(EXAMPLE_PLACES)
            path = str(found) if found is not None else EXAMPLE_PLACES
        places = PlacesFile(path, section, self.fixed_frame)
        self._report(places)
        self.places_files.append(places)
        return places

    def _report(self, places: PlacesFile) -> None:
        log = self.node.get_logger()
        for error in places.errors:
            log.warning(error)
        log.info(f"{len(places)} {places.section} from {places.path}: {', '.join(places.places) or 'none'}")

    def _now_ns(self) -> int:
        return self.node.get_clock().now().nanoseconds

    def _feed(self, handler):
        def callback(msg) -> None:
            self._dispatch(handler(msg, self._now_ns()))
        return callback

    def _tick(self) -> None:
        self._dispatch(self.state.on_timer(self._now_ns()))
        for places in self.places_files:
            if places.reload_if_changed():
                self._report(places)

    def _dispatch(self, events) -> None:
        for kind, payload in events:
            callback = {"body": self.on_body, "lost": self.on_body_lost, "gesture": self.on_gesture}[kind]
            if callback is not None:
                callback(payload)
