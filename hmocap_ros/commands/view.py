"""``hmocap view``: the live topics of the room served to Foxglove over its WebSocket protocol
(the node: :mod:`hmocap_ros.nodes.foxglove_view`, imported when the command runs). Exit status
2 with one line on bad options or when the server cannot start."""

from __future__ import annotations

import argparse
import sys

from hmocap_ros.viz.foxglove_bridge import DEFAULT_HOST, DEFAULT_PORT

__all__ = ["add_arguments", "main_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("topics", nargs="*", help="topics to offer (default: every topic of the graph)")
    parser.add_argument("--host", default=DEFAULT_HOST,
                        help=f"address to listen on (default {DEFAULT_HOST}: this machine only; 0.0.0.0 "
                             f"opens it to the network)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"port (default {DEFAULT_PORT}; 0: any free)")
    parser.add_argument("--period", type=float, default=1.0, help="seconds between looks for new topics (default 1)")


def main_from_args(ns: argparse.Namespace, ros_args: list[str]) -> int:
    if not ns.period > 0:
        print(f"hmocap view: --period must be positive, got {ns.period}", file=sys.stderr)
        return 2
    if not 0 <= ns.port <= 65535:
        print(f"hmocap view: --port must be 0 to 65535, got {ns.port}", file=sys.stderr)
        return 2
    from hmocap_ros.nodes.foxglove_view import view

    return view(ns.host, ns.port, ns.topics, ns.period, ros_args)
