"""``hmocap record``: record topics to an MCAP bag until Ctrl-C/SIGTERM (the node:
:mod:`hmocap_ros.nodes.recorder`, imported when the command runs)."""

from __future__ import annotations

import argparse
import sys

from hmocap_ros.io.cdr_stamps import LOG_TIMES

__all__ = ["add_arguments", "main_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", "-o", required=True,
                        help="bag to write: OUT.mcap for one MCAP file, any other name for a rosbag2 directory")
    parser.add_argument("topics", nargs="*", help="topics to record (relative names are taken from /)")
    parser.add_argument("-a", "--all", action="store_true", help="record every topic that appears")
    parser.add_argument("--duration", type=float, default=None,
                        help="stop after this many seconds (default: until Ctrl-C or SIGTERM)")
    parser.add_argument("--progress", type=float, default=0.0, metavar="SECONDS",
                        help="print the number of messages written on stderr when it changed, at most every "
                             "SECONDS (default 0: never)")
    parser.add_argument("--log-time", choices=LOG_TIMES, default="input",
                        help="input: a message with the header stamp of one recorded before (an output "
                             "and its input) is logged with it, so that viewers show each output over its "
                             "input; the first of a stamp, and one without, when it arrives. receive: "
                             "every message when it arrives (default input)")


def main_from_args(ns: argparse.Namespace, ros_args: list[str]) -> int:
    if not ns.topics and not ns.all:
        print("hmocap record: name the topics to record, or pass --all", file=sys.stderr)
        return 2
    from hmocap_ros.nodes.recorder import record

    record(ns.out, ns.topics, ns.all, ns.duration, ros_args, progress=ns.progress, log_time=ns.log_time)
    return 0
