"""Bag recorder node (``hmocap record``): subscribes to topics and writes a rosbag2 MCAP bag.

Subscriptions: each requested topic (or every topic with ``--all``), with its type and
QoS discovered from the publishers: best effort when a publisher is best effort (camera
images), transient local when a publisher is latched (``camera_rig``), reliable otherwise.
Messages are written as the serialized CDR bytes DDS delivered, so nothing is decoded.
Publications: none. Parameters: none (command-line options).

Log time (``--log-time``, :class:`~hmocap_ros.io.cdr_stamps.LogTimes`): with ``input`` (default)
a message whose header stamp (``/tf`` and marker arrays: their first element's), read from the
CDR bytes, is that of a message recorded before is logged at that message's log time, so that a
viewer playing the bag (Foxglove, RViz with ``ros2 bag play``, ``hmocap replay``) shows every
output with the input it was computed from, however late the node published it; the first
message of a stamp, and one without a stamp, are logged when they arrive. With ``receive`` every
message is logged when it arrived. The receive time is each message's MCAP publish time either
way.

Once a subscription has matched a publisher on its own side of DDS discovery (from then on
nothing that publisher sends is dropped for being unknown), the recorder logs
``receiving <topic> from N publisher(s)``: a script that starts a source after the recorder
waits for that line.

The bag is written at its final path and flushed at least once a second (see
:mod:`hmocap_ros.io.bag_writer`): a recorder killed at any moment leaves a readable bag holding
every message received up to its last flush, which ``hmocap repair`` makes whole. A bag that
exists already is never overwritten. Ctrl-C or SIGTERM stops the recording: the node first
takes every message already delivered, then flushes and closes the bag, and prints what it
recorded. A write error (disk full) stops it too, with the bag kept as last flushed.
"""

from __future__ import annotations

import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription

from hmocap_ros.io.bag_writer import BagWriteError, BagWriter, QosProfile
from hmocap_ros.io.cdr_stamps import LOG_TIMES, LogTimes, stamp_ns, stamp_offset
from hmocap_ros.nodes.common import ShutdownFlag, message_class

# Topics of the ROS graph itself, never worth recording with --all.
_GRAPH_TOPICS = {"/rosout", "/parameter_events"}


class Recorder(Node):
    """Discovers the requested topics and writes every message it receives to a BagWriter."""

    def __init__(self, writer: BagWriter, topics: list[str], record_all: bool = False,
                 log_time: str = "input"):
        super().__init__("hmocap_recorder")
        self.writer = writer
        self.log_times = LogTimes(by_stamp=log_time == "input")
        self._stamp_offsets: dict[str, int | None] = {}
        self.requested = [self._absolute(t) for t in topics]
        self.record_all = record_all
        self._subs: dict[str, Subscription] = {}
        self._matched: set[str] = set()
        self._unknown_types: set[str] = set()
        self.write_error: BagWriteError | None = None
        self._discover()
        self.create_timer(0.1, self._discover)

    def _absolute(self, topic: str) -> str:
        return topic if topic.startswith("/") else "/" + topic

    def _qos_for(self, topic: str) -> tuple[QoSProfile, QosProfile]:
        infos = self.get_publishers_info_by_topic(topic)
        best_effort = any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos)
        latched = bool(infos) and all(
            i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos
        )
        qos = QoSProfile(
            depth=100,
            reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        )
        stored = QosProfile(reliability=2 if best_effort else 1, durability=1 if latched else 2,
                            depth=1 if latched else 10)
        return qos, stored

    def _discover(self) -> None:
        for topic, sub in self._subs.items():
            if topic not in self._matched and sub.get_publisher_count() > 0:
                self._matched.add(topic)
                self.get_logger().info(f"receiving {topic} from {sub.get_publisher_count()} publisher(s)")
        for topic, types in self.get_topic_names_and_types():
            if topic in self._subs:
                continue
            if self.record_all:
                if topic in _GRAPH_TOPICS:
                    continue
            elif topic not in self.requested:
                continue
            if not self.get_publishers_info_by_topic(topic):
                continue
            typename = types[0]
            try:
                cls = message_class(typename)
            except ImportError as err:
                if typename not in self._unknown_types:
                    self.get_logger().error(f"cannot record {topic}: {err}")
                    self._unknown_types.add(typename)
                continue
            qos, stored = self._qos_for(topic)
            self._stamp_offsets[topic] = stamp_offset(typename, _fields)
            self.writer.add_topic(topic, typename, stored)
            self._subs[topic] = self.create_subscription(
                cls, topic, self._make_callback(topic, typename), qos, raw=True
            )
            self.get_logger().info(f"recording {topic} [{typename}]{' (latched)' if stored.latched else ''}")

    def _make_callback(self, topic: str, typename: str):
        def callback(data: bytes) -> None:
            if self.write_error is not None:
                return
            receive_ns = self.get_clock().now().nanoseconds
            log_ns = self.log_times.log_time(stamp_ns(data, self._stamp_offsets[topic]), receive_ns)
            try:
                self.writer.write(topic, data, log_ns, msgtype=typename, publish_ns=receive_ns)
            except BagWriteError as err:
                self.write_error = err
                self.get_logger().error(str(err))

        return callback

    def missing_topics(self) -> list[str]:
        return [t for t in self.requested if t not in self._subs]


def _fields(typename: str) -> dict[str, str]:
    """The fields of a message type in order (``pkg/msg/Name`` or ``pkg/Name``); none when unknown."""
    parts = typename.split("/")
    try:
        cls = message_class("/".join([parts[0], "msg", parts[-1]]))
    except ImportError:
        return {}
    return dict(cls.get_fields_and_field_types())


def _flush_if_due(node: Recorder) -> None:
    try:
        node.writer.flush_if_due()
    except BagWriteError as err:
        node.write_error = err
        node.get_logger().error(str(err))


def record(output: str, topics: list[str], record_all: bool = False, duration: float | None = None,
           ros_args: list[str] | None = None, quiet: bool = False, progress: float = 0.0,
           log_time: str = "input") -> dict[str, int]:
    """Record until Ctrl-C/SIGTERM (or ``duration`` seconds); return messages written per topic.

    ``log_time``: one of :data:`LOG_TIMES` (module doc). With ``progress`` > 0, print
    ``written: N messages: /topic n, ...`` (the counts so far) on stderr whenever they changed,
    at most every ``progress`` seconds: a script waits on it for the outputs to come to rest.
    What was recorded is printed on stdout at the end (unless ``quiet``)."""
    if log_time not in LOG_TIMES:
        raise ValueError(f"log time must be one of {', '.join(LOG_TIMES)}, got {log_time!r}")
    try:
        writer = BagWriter(output).open()
    except BagWriteError as err:
        raise SystemExit(f"hmocap record: {err} (a recording cut short is made whole by "
                         f"`hmocap repair {output}`); record to another name") from None
    flag = ShutdownFlag()
    rclpy.init(args=["hmocap_record", *(ros_args or [])], signal_handler_options=SignalHandlerOptions.NO)
    flag.install()
    node = Recorder(writer, topics, record_all, log_time)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    if not quiet:
        node.get_logger().info(f"recording to {output}: {'all topics' if record_all else ' '.join(topics)}, "
                               f"logged {'with the input of their stamp' if log_time == 'input' else 'when received'} "
                               f"(Ctrl-C to stop)")
    t_end = None if duration is None else time.monotonic() + duration
    shown = 0
    next_progress = time.monotonic()
    try:
        while (not flag.requested and node.write_error is None
               and (t_end is None or time.monotonic() < t_end)):
            executor.spin_once(timeout_sec=0.05)
            _flush_if_due(node)
            if progress > 0 and time.monotonic() >= next_progress:
                total = sum(writer.counts.values())
                if total != shown:
                    per_topic = ", ".join(f"{t} {n}" for t, n in sorted(writer.counts.items()))
                    print(f"written: {total} messages: {per_topic}", file=sys.stderr, flush=True)
                    shown = total
                next_progress = time.monotonic() + progress
        # Take what DDS has already delivered to us before closing the bag.
        drain_end = time.monotonic() + 0.3
        while time.monotonic() < drain_end and node.write_error is None:
            executor.spin_once(timeout_sec=0.02)
    finally:
        missing = node.missing_topics()
        node.destroy_node()
        writer.close()
        rclpy.try_shutdown()
    if node.write_error is not None:
        raise SystemExit(f"hmocap record: {node.write_error}; stopped recording (`hmocap info {output}` "
                         f"lists what was kept; with space free again, `hmocap repair {output}` makes it whole)")
    if not quiet:
        for topic, count in sorted(writer.counts.items()):
            print(f"  {topic}: {count} messages")
        for topic in missing:
            print(f"  {topic}: never published (not recorded)")
        print(f"closed {output}" + (f" on {flag.signal_name}" if flag.signal_name else ""), flush=True)
    return dict(writer.counts)
