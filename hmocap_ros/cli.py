"""The ``hmocap`` command: demo, bag record/replay and info, view, sim, eval, render, train and bench.

ROS arguments go after ``--ros-args`` as usual, e.g. ``hmocap replay run.mcap --ros-args -r __ns:=/room``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path


def _split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    if "--ros-args" in argv:
        i = argv.index("--ros-args")
        return argv[:i], argv[i:]
    return argv, []


def _cmd_info(ns, _ros_args):
    """The bag's summary, then the whole bag read (:meth:`BagReader.verify`): exit status 2 and
    one line naming the part that cannot be read when it is damaged."""
    from hmocap_ros.io.bag_reader import BagReader, BagReadError

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


def _cmd_demo(ns, _ros_args):
    from hmocap_ros import demo

    return demo.run_demo(ns.out, domain_id=ns.domain_id)


BENCH_DIR = Path(__file__).resolve().parents[1] / "benchmarks"


def _benchmarks() -> list[str]:
    return sorted(p.stem[len("bench_"):] for p in BENCH_DIR.glob("bench_*.py"))


def _cmd_bench(ns, _ros_args):
    import subprocess

    available = _benchmarks()
    if not available:
        print(f"hmocap bench: no benchmarks/ folder next to the package ({BENCH_DIR}): the benchmark "
              "scripts live in the source checkout", file=sys.stderr)
        return 2
    names = ns.names or available
    unknown = [n for n in names if n not in available]
    if unknown:
        print(f"hmocap bench: unknown {', '.join(unknown)}; available: {', '.join(available)}", file=sys.stderr)
        return 2
    for name in names:
        print(f"== benchmarks/bench_{name}.py", flush=True)
        rc = subprocess.call([sys.executable, str(BENCH_DIR / f"bench_{name}.py"), *ns.extra])
        if rc:
            return rc
    return 0


def _bench_arguments(own: list[str]) -> tuple[list[str], list[str]]:
    """Split ``bench NAME... [ARGS]`` into hmocap's part and the scripts': everything after
    ``--``, or after the leading benchmark names (``hmocap bench pipeline BAG --json OUT``)."""
    if "--" in own:
        i = own.index("--")
        return own[:i], own[i + 1:]
    available = set(_benchmarks())
    n = 1
    while n < len(own) and own[n] in available:
        n += 1
    return (own[:n], own[n:]) if n > 1 else (own, [])


def _cmd_group(ns, _ros_args):
    import importlib

    return importlib.import_module(ns.group_module).main_from_args(ns)


# `hmocap <group> <kind>`: each kind is a module with add_arguments(parser) and main_from_args(ns).
COMMAND_GROUPS = {
    "sim": (
        "generate synthetic smart-room bags with ground truth",
        "Render synthetic smart-room recordings (seeded, deterministic) as MCAP bags in the documented "
        "layout, with ground truth and a PNG contact sheet.",
        {
            "mocap": ("hmocap_sim.commands.mocap", "multi-view RGB bag of a retargeted BVH clip, with ground truth"),
            "gestures": ("hmocap_sim.commands.gestures", "depth bag of gestures among clutter, with ground truth"),
            "calibration": ("hmocap_sim.commands.calibration", "multi-view bag of a ChArUco board carried through the room, with the true rig"),
            "teacher": ("hmocap_sim.commands.teacher", "a simulated user who follows gesture_trainer's instructions over DDS"),
        },
    ),
    "eval": (
        "evaluate the algorithms offline on bags with ground truth, or a tracked body against the images",
        "Replay a bag through the same algorithm code the nodes run (no DDS, seeded) and report the "
        "errors against the bag's ground truth as JSON and a plot; consistency checks a bag "
        "without ground truth against its own images.",
        {
            "mocap": ("hmocap_ros.commands.eval_mocap", "3D joint error and speed of the body tracker on a multi-view bag"),
            "gestures": ("hmocap_ros.commands.eval_gestures", "precision-recall and AP per gesture on a depth bag"),
            "extremities": ("hmocap_ros.commands.eval_extremities", "precision, recall and 3D error of the extremity detection on a multi-view bag"),
            "consistency": ("hmocap_ros.commands.eval_consistency", "the tracked body against the images of a bag without ground truth: reprojection, silhouettes, triangulation"),
        },
    ),
    "detect": (
        "run a detector offline on any bag, writing its messages to a bag",
        "Run a node's detector over a bag (no DDS, no ground truth needed) and write the messages "
        "the node would publish, with the input frames' stamps, to a new bag.",
        {
            "gestures": ("hmocap_ros.commands.detect_gestures", "gesture_detection's gestures on a depth bag"),
        },
    ),
    "render": (
        "draw what the nodes saw: the skeleton over the cameras, gestures over depth",
        "Draw a bag's frames with the tracked skeletons or detected gestures over the images, as a "
        "video or PNG frames.",
        {
            "overlay": ("hmocap_ros.commands.render_overlay", "the skeleton projected onto every camera, tiled "
                                                             "(per-joint error colours with ground truth); "
                                                             "gesture boxes and scores on depth"),
        },
    ),
    "import": (
        "turn other tools' recordings into bags",
        "Turn recordings made outside ROS (synchronised video files and another tool's camera "
        "calibration) into bags in the documented layout.",
        {
            "videos": ("hmocap_ros.commands.import_videos", "synchronised videos and their calibration into a multi-view bag"),
        },
    ),
    "rig": (
        "camera rig files",
        "Read and write camera calibrations in other tools' formats.",
        {
            "convert": ("hmocap_ros.commands.rig_convert", "a calibration from one format into another (rig YAML, Pose2Sim/Anipose TOML, Qualisys QCA, OpenCV/EasyMocap, ROS camera_info)"),
        },
    ),
    "train": (
        "train models offline",
        "Train models from bags with ground truth.",
        {
            "gestures": ("hmocap_ros.commands.train_gestures", "train a gesture forest from depth bags"),
        },
    ),
}


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``hmocap`` parser. Of the ``sim``/``eval``/``train`` kinds only the one ``argv`` names
    is imported (to add its options): ``hmocap record`` must not depend on the gesture trainer."""
    from hmocap_ros.commands import record, replay, view

    argv = list(argv or [])
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
    record.add_arguments(p)
    p.set_defaults(func=record.main_from_args)

    p = sub.add_parser("replay", help="publish a bag's topics with the original timing",
                       description="Publish a bag's topics with their recorded timing; latched topics "
                                   "are re-published transient-local.")
    replay.add_arguments(p)
    p.set_defaults(func=replay.main_from_args)

    p = sub.add_parser("view", help="serve the live topics to Foxglove (WebSocket, 127.0.0.1:8765)",
                       description="Serve the ROS graph's topics to Foxglove over its WebSocket protocol "
                                   "(foxglove-sdk): open ws://127.0.0.1:8765 in Foxglove and load "
                                   "config/hmocap_foxglove.json; no ROS install needed on the viewing side.")
    view.add_arguments(p)
    p.set_defaults(func=view.main_from_args)

    import importlib

    for group, (group_help, group_description, kinds) in COMMAND_GROUPS.items():
        p = sub.add_parser(group, help=group_help, description=group_description)
        group_sub = p.add_subparsers(dest=f"{group}_kind", metavar="KIND", required=True)
        for kind, (module_name, help_text) in kinds.items():
            sp = group_sub.add_parser(kind, help=help_text, description=help_text)
            sp.set_defaults(func=_cmd_group, group_module=module_name)
            if argv[:2] == [group, kind]:
                module = importlib.import_module(module_name)
                module.add_arguments(sp)

    p = sub.add_parser("bench", help="run the benchmark scripts (source checkout)",
                       description="Run benchmarks/bench_NAME.py of the source checkout with this "
                                   "interpreter (all of them when no NAME is given); the scripts "
                                   "print what they measure. Options after -- go to the script.")
    p.add_argument("names", nargs="*", metavar="NAME",
                   help=f"benchmarks to run ({', '.join(_benchmarks()) or 'none found'})")
    p.set_defaults(func=_cmd_bench)

    from hmocap_ros.commands import repair

    p = sub.add_parser("repair", help="rewrite a bag whose recording did not close, with its summary",
                       description="Rewrite a bag whose recording was cut short (killed, power cut, disk "
                                   "full) whole: every complete record kept, indexes and statistics added.")
    repair.add_arguments(p)
    p.set_defaults(func=lambda ns, _ros_args: repair.main_from_args(ns))

    from hmocap_ros.commands import export

    p = sub.add_parser("export", help="write a bag's tracked motion as BVH, TRC or CSV",
                       description="Write one body's motion of a bag (body_tracker's output, or the "
                                   "simulator's ground truth) as a BVH, OpenSim TRC or CSV file.")
    export.add_arguments(p)
    p.set_defaults(func=lambda ns, _ros_args: export.main_from_args(ns))

    from hmocap_ros.commands import track

    p = sub.add_parser("track", help="run the body tracker on a multi-view bag, writing its topics to a bag",
                       description="Track the people of a multi-view bag with the nodes' code (no DDS, "
                                   "no ground truth needed) and write body_tracker's topics, with the "
                                   "frame sets' stamps, to a new bag.")
    track.add_arguments(p)
    p.set_defaults(func=lambda ns, _ros_args: track.main_from_args(ns))

    from hmocap_ros.commands import calibrate

    p = sub.add_parser("calibrate", help="calibrate the camera rig from a bag (or live topics) of a ChArUco board",
                       description="Estimate every camera's intrinsics and pose in the room from a bag of "
                                   "the room cameras seeing a ChArUco board carried through the room "
                                   "(and laid on the floor first); write the rig YAML and a report.")
    calibrate.add_arguments(p)
    p.set_defaults(func=lambda ns, ros_args: calibrate.main_from_args(ns, ros_args))

    p = sub.add_parser("info", help="list a bag's topics, types and counts")
    p.add_argument("bag", help=".mcap file or rosbag2 directory")
    p.set_defaults(func=_cmd_info)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    own, ros_args = _split_ros_args(argv)
    extra = []
    if own[:1] == ["bench"]:
        own, extra = _bench_arguments(own)
    ns = build_parser(own).parse_args(own)
    ns.extra = extra
    return int(ns.func(ns, ros_args) or 0)


if __name__ == "__main__":
    raise SystemExit(main())
