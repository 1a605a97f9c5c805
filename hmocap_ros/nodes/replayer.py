"""Bag replay node (``hmocap replay``): publishes a bag's topics with the original timing.

Publications: every topic of the bag (or those of ``--topics``), with the bag's message
types, published as the stored serialized bytes (nothing is decoded): topics recorded as
latched are published transient-local (reliable, keep last 1), the others reliable with
keep-last ``VOLATILE_DEPTH``, which best-effort subscribers (sensor-data QoS) accept too.
Subscriptions: none. Parameters: none (command-line options ``--rate``, ``--loop``,
``--topics``, ``--wait-subscribers``, ``--settle``).

Starting a replay into freshly started nodes: ``--wait-subscribers N`` holds the first message
until every replayed topic has N matched subscriptions. That is the publisher's side of DDS
discovery only; a best-effort subscriber drops messages from a publisher that it has not
matched in turn, so the replay then waits ``--settle`` seconds more for the other side.
When the replay falls behind (a loaded machine), it publishes the overdue messages at once:
subscribers need a queue that holds such a burst (see ``nodes.common.sensor_qos``).

A bag that cannot be read, a ``--topics`` entry the bag lacks or a rate that is not positive
ends ``hmocap replay`` with one line on stderr and exit status 2, before ROS starts.
"""

from __future__ import annotations

import argparse
import sys
import time

import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from hmocap_ros.io.bag_reader import BagReader, BagReadError
from hmocap_ros.nodes.common import ShutdownFlag, message_class

#: History of the reliable volatile publishers: a reliable subscriber that falls behind gets
#: the messages again from it, so it must hold a burst: two seconds of a 25 fps topic.
VOLATILE_DEPTH = 50


class Replayer(Node):
    """Holds one publisher per replayed topic."""

    def __init__(self, topics: dict):
        super().__init__("hmocap_replay")
        self.publishers_by_topic = {}
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
           ros_args: list[str] | None = None, quiet: bool = False, settle: float = 1.0) -> dict[str, int]:
    """Publish the bag's messages at ``rate`` times the recorded pace; return counts per topic.

    With ``wait_subscribers`` > 0, wait (at most ``wait_timeout`` s) for that many subscribers on
    every topic, then ``settle`` s more (see the module doc). The bag is opened and ``topics``
    checked before ROS starts: ``ValueError`` for a rate that is not positive,
    :class:`~hmocap_ros.io.bag_reader.BagReadError` for a bag that cannot be read or lacks one
    of ``topics``."""
    if not rate > 0:
        raise ValueError(f"--rate must be positive, got {rate:g}")
    with BagReader(bag) as reader:
        available = reader.topics()
        if topics:
            reader.check_topics(topics)
        wanted = {t: available[t] for t in topics} if topics else available
        flag = ShutdownFlag()
        rclpy.init(args=["hmocap_replay", *(ros_args or [])], signal_handler_options=SignalHandlerOptions.NO)
        flag.install()
        try:
            node = Replayer(wanted)
            if wait_subscribers > 0:
                short = node.wait_for_subscribers(wait_subscribers, wait_timeout, flag)
                if short and not quiet:
                    print(f"warning: no subscriber after {wait_timeout:.0f} s on: {', '.join(short)}")
                _pause(settle, flag)
            if not quiet:
                print(f"replaying {bag}: {len(node.publishers_by_topic)} topics at rate {rate:g}"
                      + (" (looping)" if loop else ""), flush=True)
            counts = _publish(node, reader, rate, loop, flag)
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


def _publish(node: Replayer, reader: BagReader, rate: float, loop: bool, flag: ShutdownFlag) -> dict[str, int]:
    """Publish the messages of the node's topics with their recorded spacing divided by ``rate``
    (again from the start while ``loop``); return counts per topic."""
    counts = {t: 0 for t in node.publishers_by_topic}
    while not flag.requested:
        t0 = time.monotonic()
        start_ns = None
        for item in reader.messages(list(node.publishers_by_topic), raw=True):
            if flag.requested:
                break
            if start_ns is None:
                start_ns = item.log_time_ns
            delay = t0 + (item.log_time_ns - start_ns) * 1e-9 / rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            node.publishers_by_topic[item.topic].publish(item.msg)
            counts[item.topic] += 1
        if not loop:
            break
    return counts


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="bag to replay (.mcap file or rosbag2 directory)")
    parser.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default 1)")
    parser.add_argument("--loop", action="store_true", help="start again at the end")
    parser.add_argument("--topics", nargs="+", default=None, help="replay only these topics")
    parser.add_argument("--wait-subscribers", type=int, default=0, metavar="N",
                        help="wait until every replayed topic has N subscribers before starting")
    parser.add_argument("--wait-timeout", type=float, default=10.0, help="seconds to wait for subscribers")
    parser.add_argument("--settle", type=float, default=1.0,
                        help="with --wait-subscribers: seconds to wait after they matched, for the "
                             "subscribers to match the replay in turn (default 1)")
    parser.add_argument("--linger", type=float, default=0.5,
                        help="seconds to keep publishers alive after the last message")


def main_from_args(ns: argparse.Namespace, ros_args: list[str]) -> int:
    topics = [t if t.startswith("/") else "/" + t for t in ns.topics] if ns.topics else None
    try:
        replay(ns.bag, ns.rate, ns.loop, topics, ns.wait_subscribers, ns.wait_timeout, ns.linger, ros_args,
               settle=ns.settle)
    except (BagReadError, ValueError) as err:
        print(f"hmocap replay: {err}", file=sys.stderr)
        return 2
    return 0
