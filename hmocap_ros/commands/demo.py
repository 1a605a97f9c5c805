"""``hmocap demo``: the pipeline on the shipped data over DDS (the run: :mod:`hmocap_ros.demo`,
imported when the command runs)."""

from __future__ import annotations

import argparse
import sys

__all__ = ["add_arguments", "main_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="out/demo",
                        help="folder for the recorded bags, videos and logs, replaced once the run is complete "
                             "(default out/demo)")
    parser.add_argument("--domain-id", type=int, default=None,
                        help="ROS_DOMAIN_ID for the demo (default: environment's)")


def main_from_args(ns: argparse.Namespace) -> int:
    from hmocap_ros import demo

    try:
        return demo.run_demo(ns.out, domain_id=ns.domain_id)
    except RuntimeError as err:  # a node that did not start, a replay that failed: its log follows
        print(f"hmocap demo: FAILED: {err}", file=sys.stderr)
        return 1
