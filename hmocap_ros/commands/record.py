"""``hmocap record``: record topics to an MCAP bag until Ctrl-C/SIGTERM (the node:
:mod:`hmocap_ros.nodes.recorder`, imported when the command runs)."""

from __future__ import annotations

import argparse
import sys

__all__ = ["add_arguments", "main_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-o", "--output", required=True,
                        help="bag to write: OUT.mcap for one MCAP file, any other name for a rosbag2 directory")
    parser.add_argument("topics", nargs="*", help="topics to record (relative names are taken from /)")
    parser.add_argument("-a", "--all", action="store_true", help="record every topic that appears")
    parser.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    parser.add_argument("--progress", type=float, default=0.0, metavar="SECONDS",
                        help="print the number of messages written when it changed, at most every SECONDS")


def main_from_args(ns: argparse.Namespace, ros_args: list[str]) -> int:
    if not ns.topics and not ns.all:
        print("hmocap record: name the topics to record, or pass --all", file=sys.stderr)
        return 2
    from hmocap_ros.nodes.recorder import record

    record(ns.output, ns.topics, ns.all, ns.duration, ros_args, progress=ns.progress)
    return 0
