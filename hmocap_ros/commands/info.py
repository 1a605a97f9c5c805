"""``hmocap info BAG``: a bag's topics, types and counts, then the whole bag read
(:meth:`~hmocap_ros.io.bag_reader.BagReader.verify`): exit status 2 and one line naming the
part that cannot be read when it is damaged."""

from __future__ import annotations

import argparse
import sys

from hmocap_ros.io.bag_reader import BagReader, BagReadError

__all__ = ["add_arguments", "main_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help=".mcap file or rosbag2 directory")


def main_from_args(ns: argparse.Namespace) -> int:
    try:
        with BagReader(ns.bag) as reader:
            topics = reader.topics()
            duration = (reader.end_ns - reader.start_ns) * 1e-9 if topics else 0.0
            print(f"{ns.bag}: {sum(t.count for t in topics.values())} messages, {duration:.2f} s")
            for t in sorted(topics.values(), key=lambda t: t.topic):
                print(f"  {t.topic:40s} {t.msgtype:40s} {t.count:6d}{'  latched' if t.latched else ''}")
            reader.verify()
    except BagReadError as err:
        print(f"hmocap info: {err}", file=sys.stderr)
        return 2
    return 0
