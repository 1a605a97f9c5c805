"""``hmocap replay``: publish a bag's topics with their recorded timing (the node:
:mod:`hmocap_ros.nodes.replayer`, imported when the command runs). Exit status 2 with one line
when the bag or the options cannot be used, before ROS starts."""

from __future__ import annotations

import argparse
import sys

from hmocap_ros.io.bag_reader import BagReadError

__all__ = ["DEFAULT_CLOCK_HZ", "add_arguments", "main_from_args"]

#: Frequency (Hz) of /clock with a bare ``--clock``, as ``ros2 bag play --clock``.
DEFAULT_CLOCK_HZ = 40.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="bag to replay (.mcap file or rosbag2 directory)")
    parser.add_argument("--rate", type=float, default=1.0, help="playback speed factor (default 1)")
    parser.add_argument("--loop", action="store_true", help="start again at the end")
    parser.add_argument("--topics", nargs="+", default=None, help="replay only these topics")
    parser.add_argument("--wait-subscribers", type=int, default=0, metavar="N",
                        help="wait until every replayed topic has N subscribers before starting "
                             "(default 0: start at once)")
    parser.add_argument("--wait-timeout", type=float, default=10.0, help="seconds to wait for subscribers")
    parser.add_argument("--settle", type=float, default=1.0,
                        help="with --wait-subscribers: seconds to wait after they matched, for the "
                             "subscribers to match the replay in turn (default 1)")
    parser.add_argument("--linger", type=float, default=0.5,
                        help="seconds to keep publishers alive after the last message")
    parser.add_argument("--clock", type=float, nargs="?", const=DEFAULT_CLOCK_HZ, default=None, metavar="HZ",
                        help="publish the playback time (the bag's stamps) on /clock at HZ "
                             f"(default {DEFAULT_CLOCK_HZ:g}), as `ros2 bag play --clock`, for nodes run "
                             "with -p use_sim_time:=true")


def main_from_args(ns: argparse.Namespace, ros_args: list[str]) -> int:
    from hmocap_ros.nodes.replayer import replay

    topics = [t if t.startswith("/") else "/" + t for t in ns.topics] if ns.topics else None
    try:
        replay(ns.bag, ns.rate, ns.loop, topics, ns.wait_subscribers, ns.wait_timeout, ns.linger, ros_args,
               settle=ns.settle, clock_hz=ns.clock)
    except (BagReadError, ValueError) as err:
        print(f"hmocap replay: {err}", file=sys.stderr)
        return 2
    return 0
