"""``hmocap view``: the live topics of the room served to Foxglove over its WebSocket protocol.

A thin rclpy shell around :class:`~hmocap_ros.viz.foxglove_bridge.FoxgloveBridge`: every
``--period`` seconds it offers each topic of the ROS graph (or those named) as a Foxglove
channel, and subscribes, with ``raw=True`` (no decoding), to the topics that a Foxglove client
watches, dropping the subscription when no client watches any more. Open Foxglove, "Open
connection", ``ws://127.0.0.1:8765``, and load ``config/hmocap_foxglove.json``.

Subscriptions: the watched topics, best effort and volatile (matches reliable and best-effort
publishers, and a busy viewer never makes a publisher wait), or reliable and transient local
with a depth of one for a latched topic (``camera_rig``, ``/tf_static``, ``body_shape``),
whose every publisher is transient local. Publications: none. Parameters: none (command-line
options: ``--host`` 127.0.0.1, ``--port`` 8765, ``--period``, topics).
"""

from __future__ import annotations

import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription

from hmocap_ros.nodes.common import ShutdownFlag, message_class
from hmocap_ros.viz.foxglove_bridge import FoxgloveBridge

__all__ = ["FoxgloveView", "view"]

#: Topics of the ROS graph itself, not offered.
GRAPH_TOPICS = {"/rosout", "/parameter_events"}
#: Seconds between two looks at which topics the clients watch.
WATCH_PERIOD_S = 0.1


class FoxgloveView(Node):
    """Offers the graph's topics on ``bridge`` and carries the watched ones (module docstring)."""

    def __init__(self, bridge: FoxgloveBridge, topics: list[str], period_s: float = 1.0):
        super().__init__("hmocap_view")
        self.bridge = bridge
        self.requested = {t if t.startswith("/") else "/" + t for t in topics}
        self.types: dict[str, str] = {}
        self.subs: dict[str, Subscription] = {}
        self.refused: set[str] = set()
        self._discover()
        self.create_timer(period_s, self._discover)
        self.create_timer(WATCH_PERIOD_S, self._follow_clients)

    def _discover(self) -> None:
        present = set()
        for topic, types in self.get_topic_names_and_types():
            if topic in GRAPH_TOPICS or (self.requested and topic not in self.requested):
                continue
            if not self.count_publishers(topic):
                continue
            present.add(topic)
            if topic in self.types or topic in self.refused:
                continue
            if self.bridge.advertise(topic, types[0]):
                self.types[topic] = types[0]
                self.get_logger().info(f"offering {topic} [{types[0]}]")
            else:
                self.refused.add(topic)
                self.get_logger().warning(f"{topic}: no definition of {types[0]} here; not offered")
        for topic in [t for t in self.types if t not in present]:  # its publishers are gone
            self._unsubscribe(topic)
            self.bridge.remove(topic)
            del self.types[topic]
            self.get_logger().info(f"{topic} has no publisher any more; withdrawn")

    def _qos(self, topic: str) -> QoSProfile:
        infos = self.get_publishers_info_by_topic(topic)
        if infos and all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos):
            return QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.TRANSIENT_LOCAL)
        return QoSProfile(depth=10, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.VOLATILE)

    def _follow_clients(self) -> None:
        watched = self.bridge.watched()
        for topic in watched - set(self.subs):
            try:
                cls = message_class(self.types[topic])
            except ImportError as err:
                self.get_logger().error(f"cannot carry {topic}: {err}", throttle_duration_sec=10.0)
                continue
            self.subs[topic] = self.create_subscription(cls, topic, self._forward(topic), self._qos(topic), raw=True)
            self.get_logger().info(f"a viewer watches {topic}")
        for topic in set(self.subs) - watched:
            self._unsubscribe(topic)

    def _unsubscribe(self, topic: str) -> None:
        sub = self.subs.pop(topic, None)
        if sub is not None:
            self.destroy_subscription(sub)

    def _forward(self, topic: str):
        def callback(data: bytes) -> None:
            self.bridge.log(topic, data, time.time_ns())

        return callback


def view(host: str, port: int, topics: list[str], period_s: float, ros_args: list[str] | None = None) -> int:
    """Serve until Ctrl-C/SIGTERM; 2 with one line when the server cannot start."""
    try:
        bridge = FoxgloveBridge(host, port)
    except ImportError:
        print("hmocap view: needs the foxglove-sdk package (pip install foxglove-sdk; make setup installs it); "
              "in a ROS install foxglove_bridge serves the same", file=sys.stderr)
        return 2
    except OSError as err:
        print(f"hmocap view: {err}", file=sys.stderr)
        return 2
    flag = ShutdownFlag()
    rclpy.init(args=["hmocap_view", *(ros_args or [])], signal_handler_options=SignalHandlerOptions.NO)
    flag.install()
    node = FoxgloveView(bridge, topics, period_s)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    node.get_logger().info(f"serving the ROS topics to Foxglove at {bridge.url} (Open connection -> Foxglove "
                           f"WebSocket; layout: config/hmocap_foxglove.json). Ctrl-C to stop.")
    try:
        while not flag.requested and rclpy.ok():
            executor.spin_once(timeout_sec=0.05)
    finally:
        node.destroy_node()
        bridge.close()
        rclpy.try_shutdown()
    return 0
