"""Bag replay node (``hmocap replay``): publishes a bag's topics with the original timing.

Publications: every topic of the bag (or those of ``--topics``), with the bag's message
types, published as the stored serialized bytes (nothing is decoded): topics recorded as
latched are published transient-local (reliable, keep last 1), the others reliable with
keep-last ``VOLATILE_DEPTH``, which best-effort subscribers (sensor-data QoS) accept too.
With ``--clock [HZ]`` (as ``ros2 bag play --clock``): ``/clock`` (rosgraph_msgs/Clock,
reliable, keep last 1, which best-effort subscribers such as rclpy's time source accept),
the playback time on the bag's time line: the first message's log time when the replay
starts, then advancing with the replay at ``HZ`` (default 40) until the last message's log
time, never ahead of the next message to publish; our bags log every message at its
``header.stamp``, so nodes started with ``-p use_sim_time:=true`` see the time of the frames
they receive. With ``--loop`` the clock goes back to the start at each pass.
Subscriptions: none. Parameters: none (command-line options ``--rate``, ``--loop``,
``--topics``, ``--wait-subscribers``, ``--settle``, ``--clock``).

Starting a replay into freshly started nodes: ``--wait-subscribers N`` holds the first message
until every replayed topic has N matched subscriptions. That is the publisher's side of DDS
discovery only; a best-effort subscriber drops messages from a publisher that it has not
matched in turn, so the replay then waits ``--settle`` seconds more for the other side.
When the replay falls behind (a loaded machine), it publishes the overdue messages at once:
subscribers need a queue that holds such a burst (see ``nodes.common.sensor_qos``). What it
waits for and starts is logged (the ROS logger); at the end it prints on stdout what it published
per topic and how it kept time, one line per pass
(``replay timing: bag_s=20.000 wall_s=20.031 behind_max_s=0.012 behind_p95_s=0.004
cpu_s=3.1``): the bag's span from the first to the last message over ``--rate``, the seconds
the pass took from its first to its last publication, how late the messages went out
(publication time minus due time; the playback is real time when ``wall_s`` is ``bag_s`` and
the lateness a few milliseconds), and the CPU seconds the pass took (reading and publishing).

A bag that cannot be read, a ``--topics`` entry the bag lacks, a rate or clock frequency that
is not positive, or ``--clock`` for a replay that holds a ``/clock`` topic itself ends
``hmocap replay`` with one line on stderr and exit status 2, before ROS starts.
"""

from __future__ import annotations

import time

import numpy as np
import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock

from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.nodes.common import ShutdownFlag, message_class

#: History of the reliable volatile publishers: a reliable subscriber that falls behind gets
#: the messages again from it, so it must hold a burst: two seconds of a 25 fps topic.
VOLATILE_DEPTH = 50
CLOCK_TOPIC = "/clock"


class Replayer(Node):
    """Holds one publisher per replayed topic."""

    def __init__(self, topics: dict, clock: bool = False):
        super().__init__("hmocap_replay")
        self.publishers_by_topic = {}
        clock_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
        self.clock_pub = self.create_publisher(Clock, CLOCK_TOPIC, clock_qos) if clock else None
        self.clock_ns: int | None = None
        for topic, info in topics.items():
            try:
                cls = message_class(info.msgtype)
            except ImportError as err:
                self.get_logger().error(f"skipping {topic}: {err}")
                continue
            qos = QoSProfile(
                depth=1 if info.latched else VOLATILE_DEPTH,
                reliability=ReliabilityPolicy.RELIABLE,
                durability=DurabilityPolicy.TRANSIENT_LOCAL if info.latched else DurabilityPolicy.VOLATILE,
            )
            self.publishers_by_topic[topic] = self.create_publisher(cls, topic, qos)

    def publish_clock(self, stamp_ns: int) -> None:
        """Publish ``stamp_ns`` on /clock (with ``--clock``)."""
        if self.clock_pub is None:
            return
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(int(stamp_ns), 1_000_000_000)
        self.clock_pub.publish(msg)
        self.clock_ns = int(stamp_ns)

    def wait_for_subscribers(self, count: int, timeout: float, flag: ShutdownFlag) -> list[str]:
        """Wait until every volatile topic has ``count`` subscribers; return the topics still short."""
        end = time.monotonic() + timeout
        short = list(self.publishers_by_topic)
        while time.monotonic() < end and not flag.requested:
            short = [t for t, p in self.publishers_by_topic.items() if p.get_subscription_count() < count]
            if not short:
                break
            time.sleep(0.05)
        return short


def replay(bag: str, rate: float = 1.0, loop: bool = False, topics: list[str] | None = None,
           wait_subscribers: int = 0, wait_timeout: float = 10.0, linger: float = 0.5,
           ros_args: list[str] | None = None, quiet: bool = False, settle: float = 1.0,
           clock_hz: float | None = None) -> dict[str, int]:
    """Publish the bag's messages at ``rate`` times the recorded pace; return counts per topic.

    With ``clock_hz``, publish the playback time on /clock at that frequency (module doc).

    With ``wait_subscribers`` > 0, wait (at most ``wait_timeout`` s) for that many subscribers on
    every topic, then ``settle`` s more (see the module doc). The bag is opened and ``topics``
    checked before ROS starts: ``ValueError`` for a rate that is not positive,
    :class:`~hmocap_ros.io.bag_reader.BagReadError` for a bag that cannot be read or lacks one
    of ``topics``."""
    if not rate > 0:
        raise ValueError(f"--rate must be positive, got {rate:g}")
    if clock_hz is not None and not 0 < clock_hz < float("inf"):
        raise ValueError(f"--clock must be a positive frequency in Hz, got {clock_hz:g}")
    with BagReader(bag) as reader:
        available = reader.topics()
        if topics:
            reader.check_topics(topics)
        wanted = {t: available[t] for t in topics} if topics else available
        if clock_hz is not None and CLOCK_TOPIC in wanted:
            raise ValueError(f"{bag} holds a {CLOCK_TOPIC} topic: replay it without --clock, or leave it out "
                             f"with --topics")
        flag = ShutdownFlag()
        rclpy.init(args=["hmocap_replay", *(ros_args or [])], signal_handler_options=SignalHandlerOptions.NO)
        flag.install()
        try:
            node = Replayer(wanted, clock=clock_hz is not None)
            if wait_subscribers > 0:
                short = node.wait_for_subscribers(wait_subscribers, wait_timeout, flag)
                if short and not quiet:
                    node.get_logger().warning(f"fewer than {wait_subscribers} subscribers after {wait_timeout:g} s "
                                              f"on: {', '.join(short)}")
                _pause(settle, flag)
            if not quiet:
                node.get_logger().info(f"replaying {bag}: {len(node.publishers_by_topic)} topics at rate {rate:g}"
                                       + (" (looping)" if loop else "")
                                       + (f", {CLOCK_TOPIC} at {clock_hz:g} Hz" if clock_hz is not None else ""))
            counts = _publish(node, reader, rate, loop, flag, None if clock_hz is None else 1.0 / clock_hz,
                              quiet)
            # Give DDS time to deliver the last messages before the publishers go away.
            _pause(linger, flag)
            node.destroy_node()
        finally:
            rclpy.try_shutdown()
    if not quiet:
        for topic, count in sorted(counts.items()):
            print(f"  {topic}: {count} messages published")
    return counts


def _pause(seconds: float, flag: ShutdownFlag) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end and not flag.requested:
        time.sleep(0.02)


def _publish(node: Replayer, reader: BagReader, rate: float, loop: bool, flag: ShutdownFlag,
             clock_period: float | None = None, quiet: bool = False) -> dict[str, int]:
    """Publish the messages of the node's topics with their recorded spacing divided by ``rate``
    (again from the start while ``loop``), and with ``clock_period`` the playback time on
    /clock every ``clock_period`` seconds; return counts per topic. Unless ``quiet``, print
    the timing line of each pass (module docstring)."""
    counts = {t: 0 for t in node.publishers_by_topic}
    while not flag.requested:
        t0, cpu0 = time.monotonic(), time.process_time()
        start_ns = last_ns = None
        behind: list[float] = []
        for item in reader.messages(list(node.publishers_by_topic), raw=True):
            if flag.requested:
                break
            if start_ns is None:
                start_ns = item.log_time_ns
                node.publish_clock(start_ns)
            due = t0 + (item.log_time_ns - start_ns) * 1e-9 / rate
            if clock_period is None:
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
            else:
                _tick_clock_until(node, due, t0, start_ns, item.log_time_ns, rate, clock_period)
            node.publishers_by_topic[item.topic].publish(item.msg)
            behind.append(time.monotonic() - due)
            counts[item.topic] += 1
            last_ns = item.log_time_ns
        if last_ns is not None and clock_period is not None:
            node.publish_clock(last_ns)
        if behind and not quiet:
            assert start_ns is not None and last_ns is not None  # behind holds a message's lateness
            late = np.asarray(behind)
            print(f"replay timing: bag_s={(last_ns - start_ns) * 1e-9 / rate:.3f} "
                  f"wall_s={behind[-1] - behind[0] + (last_ns - start_ns) * 1e-9 / rate:.3f} "
                  f"behind_max_s={late.max():.3f} behind_p95_s={np.percentile(late, 95):.3f} "
                  f"cpu_s={time.process_time() - cpu0:.3f}", flush=True)
        if not loop:
            break
    return counts


def _tick_clock_until(node: Replayer, due: float, t0: float, start_ns: int, next_ns: int, rate: float,
                      period: float) -> None:
    """Sleep until the monotonic time ``due``, publishing the playback time on /clock every
    ``period`` s meanwhile, never beyond ``next_ns`` (the log time of the next message)."""
    next_tick = time.monotonic()
    while True:
        now = time.monotonic()
        if now >= next_tick:
            playback_ns = start_ns + int((now - t0) * rate * 1e9)
            node.publish_clock(max(node.clock_ns or start_ns, min(playback_ns, next_ns)))
            next_tick = now + period
        if now >= due:
            return
        time.sleep(max(0.0, min(due, next_tick) - now))
