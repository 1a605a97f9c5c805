"""The ``hmocap`` command: demo, bag record/replay and info (later: sim, eval, bench).

ROS arguments go after ``--ros-args`` as usual, e.g. ``hmocap replay run.mcap --ros-args -r __ns:=/room``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence


def _split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    if "--ros-args" in argv:
        i = argv.index("--ros-args")
        return argv[:i], argv[i:]
    return argv, []


def _cmd_record(ns, ros_args):
    from hmocap_ros.nodes import recorder

    return recorder.main_from_args(ns, ros_args)


def _cmd_replay(ns, ros_args):
    from hmocap_ros.nodes import replayer

    return replayer.main_from_args(ns, ros_args)


def _cmd_info(ns, _ros_args):
    from hmocap_ros.io.bag_reader import BagReader

    with BagReader(ns.bag) as reader:
        topics = reader.topics()
        duration = (reader.end_ns - reader.start_ns) * 1e-9 if topics else 0.0
        print(f"{ns.bag}: {sum(t.count for t in topics.values())} messages, {duration:.2f} s")
        for t in sorted(topics.values(), key=lambda t: t.topic):
            print(f"  {t.topic:40s} {t.msgtype:40s} {t.count:6d}{'  latched' if t.latched else ''}")
    return 0


def _cmd_demo(ns, _ros_args):
    from hmocap_ros import demo

    return demo.run_demo(ns.out, domain_id=ns.domain_id)


def _cmd_sim(ns, _ros_args):
    import importlib

    module = importlib.import_module(ns.sim_module)
    return module.main_from_args(ns)


# `hmocap sim <kind>`: each kind is a module with add_arguments(parser) and main_from_args(ns).
SIM_COMMANDS = {
    "mocap": ("hmocap_ros.sim.mocap_dataset", "multi-view RGB bag of a retargeted BVH clip, with ground truth"),
    "gestures": ("hmocap_ros.sim.gesture_dataset", "depth bag of gestures among clutter, with ground truth"),
}


def build_parser() -> argparse.ArgumentParser:
    from hmocap_ros.nodes import recorder, replayer

    parser = argparse.ArgumentParser(
        prog="hmocap",
        description="hmocap_ros: multi-view body tracking and depth gestures for smart rooms.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("demo", help="run the pipeline on the shipped data over DDS and report",
                       description="Replay the shipped bag through the nodes (separate processes over "
                                   "DDS on loopback), record their outputs and print what went in and out.")
    p.add_argument("--out", default="out/demo", help="folder for the recorded bag and logs (default out/demo)")
    p.add_argument("--domain-id", type=int, default=None, help="ROS_DOMAIN_ID for the demo (default: environment's)")
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser("record", help="record topics to an MCAP bag",
                       description="Record topics to a rosbag2 MCAP bag until Ctrl-C/SIGTERM; nothing "
                                   "received is lost on stop.")
    recorder.add_arguments(p)
    p.set_defaults(func=_cmd_record)

    p = sub.add_parser("replay", help="publish a bag's topics with the original timing",
                       description="Publish a bag's topics with their recorded timing; latched topics "
                                   "are re-published transient-local.")
    replayer.add_arguments(p)
    p.set_defaults(func=_cmd_replay)

    p = sub.add_parser("sim", help="generate synthetic smart-room bags with ground truth",
                       description="Render synthetic smart-room recordings (seeded, deterministic) as MCAP "
                                   "bags in the documented layout, with ground truth and a PNG contact sheet.")
    sim_sub = p.add_subparsers(dest="sim_kind", metavar="KIND", required=True)
    import importlib

    for kind, (module_name, help_text) in SIM_COMMANDS.items():
        sp = sim_sub.add_parser(kind, help=help_text, description=help_text)
        try:
            importlib.import_module(module_name).add_arguments(sp)
        except ImportError as err:  # a partial checkout: say so instead of failing every command
            sp.description = f"{help_text} (unavailable: {err})"
        sp.set_defaults(func=_cmd_sim, sim_module=module_name)

    p = sub.add_parser("info", help="list a bag's topics, types and counts")
    p.add_argument("bag", help=".mcap file or rosbag2 directory")
    p.set_defaults(func=_cmd_info)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    own, ros_args = _split_ros_args(argv)
    ns = build_parser().parse_args(own)
    return int(ns.func(ns, ros_args) or 0)


if __name__ == "__main__":
    raise SystemExit(main())
