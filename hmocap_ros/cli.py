"""The ``hmocap`` command: demo, bag record/replay and info, view, sim, eval, render, train and bench.

ROS arguments go after ``--ros-args`` as usual, e.g. ``hmocap replay run.mcap --ros-args -r __ns:=/room``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from hmocap_ros.terminal import TerminalManners


def _split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    if "--ros-args" in argv:
        i = argv.index("--ros-args")
        return argv[:i], argv[i:]
    return argv, []


# `hmocap <command>`: module (add_arguments(parser), main_from_args(ns)), help, description, and
# whether main_from_args takes the ROS arguments too (main_from_args(ns, ros_args)).
COMMANDS = {
    "demo": ("hmocap_ros.commands.demo", "run the pipeline on the shipped data over DDS and report",
             "Replay the shipped bag through the nodes (separate processes over DDS on loopback), "
             "record their outputs and print what went in and out.", False),
    "record": ("hmocap_ros.commands.record", "record topics to an MCAP bag",
               "Record topics to a rosbag2 MCAP bag until Ctrl-C/SIGTERM; nothing received is lost "
               "on stop.", True),
    "replay": ("hmocap_ros.commands.replay", "publish a bag's topics with the original timing",
               "Publish a bag's topics with their recorded timing; latched topics are re-published "
               "transient-local.", True),
    "view": ("hmocap_ros.commands.view", "serve the live topics to Foxglove (WebSocket, 127.0.0.1:8765)",
             "Serve the ROS graph's topics to Foxglove over its WebSocket protocol (foxglove-sdk): open "
             "ws://127.0.0.1:8765 in Foxglove and load config/hmocap_foxglove.json; no ROS install "
             "needed on the viewing side.", True),
    "bench": ("hmocap_ros.commands.bench", "run the benchmark scripts (source checkout)",
              "Run benchmarks/bench_NAME.py of the source checkout with this interpreter (all of them "
              "when no NAME is given); the scripts print what they measure. Options after -- go to "
              "the script.", False),
    "repair": ("hmocap_ros.commands.repair", "rewrite a bag whose recording did not close, with its summary",
               "Rewrite a bag whose recording was cut short (killed, power cut, disk full) whole: every "
               "complete record kept, indexes and statistics added.", False),
    "export": ("hmocap_ros.commands.export", "write a bag's tracked motion as BVH, TRC or CSV",
               "Write one body's motion of a bag (body_tracker's output, or the simulator's ground "
               "truth) as a BVH, OpenSim TRC or CSV file.", False),
    "track": ("hmocap_ros.commands.track", "run the body tracker on a multi-view bag, writing its topics to a bag",
              "Track the people of a multi-view bag with the nodes' code (no DDS, no ground truth "
              "needed) and write body_tracker's topics, with the frame sets' stamps, to a new bag.", False),
    "calibrate": ("hmocap_ros.commands.calibrate",
                  "calibrate the camera rig from a bag (or live topics) of a ChArUco board",
                  "Estimate every camera's intrinsics and pose in the room from a bag of the room "
                  "cameras seeing a ChArUco board carried through the room (and laid on the floor "
                  "first); write the rig YAML and a report.", True),
    "info": ("hmocap_ros.commands.info", "list a bag's topics, types and counts",
             "List a bag's topics, types and counts, then read the whole bag: exit status 2 and one "
             "line naming the part that cannot be read when it is damaged.", False),
}


def _run(ns, ros_args):
    import importlib

    module = importlib.import_module(ns.command_module)
    return module.main_from_args(ns, ros_args) if ns.takes_ros_args else module.main_from_args(ns)


# `hmocap <group> <kind>`: each kind is a module with add_arguments(parser) and main_from_args(ns).
COMMAND_GROUPS = {
    "sim": (
        "generate synthetic smart-room bags with ground truth",
        "Render synthetic smart-room recordings (seeded, deterministic) as MCAP bags in the documented "
        "layout, with ground truth and a PNG contact sheet.",
        {
            "mocap": ("hmocap_sim.commands.mocap", "multi-view RGB bag of a retargeted BVH clip, with ground truth"),
            "gestures": ("hmocap_sim.commands.gestures", "depth bag of gestures among clutter, with ground truth"),
            "calibration": ("hmocap_sim.commands.calibration",
                            "multi-view bag of a ChArUco board carried through the room, with the true rig"),
            "teacher": ("hmocap_sim.commands.teacher",
                        "a simulated user who follows gesture_trainer's instructions over DDS"),
        },
    ),
    "eval": (
        "evaluate the algorithms offline on bags with ground truth, or a tracked body against the images",
        "Replay a bag through the same algorithm code the nodes run (no DDS, seeded) and report the "
        "errors against the bag's ground truth as JSON and a plot; consistency checks a bag "
        "without ground truth against its own images.",
        {
            "mocap": ("hmocap_ros.commands.eval_mocap",
                      "3D joint error and speed of the body tracker on a multi-view bag"),
            "gestures": ("hmocap_ros.commands.eval_gestures", "precision-recall and AP per gesture on a depth bag"),
            "extremities": ("hmocap_ros.commands.eval_extremities",
                            "precision, recall and 3D error of the extremity detection on a multi-view bag"),
            "consistency": ("hmocap_ros.commands.eval_consistency",
                            "the tracked body against the images of a bag without ground truth: reprojection, "
                            "silhouettes, triangulation"),
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
            "videos": ("hmocap_ros.commands.import_videos",
                       "synchronised videos and their calibration into a multi-view bag"),
        },
    ),
    "rig": (
        "camera rig files",
        "Read and write camera calibrations in other tools' formats.",
        {
            "convert": ("hmocap_ros.commands.rig_convert",
                        "a calibration from one format into another (rig YAML, Pose2Sim/Anipose TOML, Qualisys QCA, "
                        "OpenCV/EasyMocap, ROS camera_info)"),
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


class DefaultsShown(argparse.HelpFormatter):
    """Help that states every option's default: one whose text does not name it gets
    ``(default VALUE)`` appended; options without a value by default (None, off) are left as
    they are."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if (not action.option_strings or "default" in text.lower() or action.default is None
                or action.default is False or action.default is argparse.SUPPRESS or action.default in ("", [])):
            return action.help
        return f"{text} (default %(default)s)"


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The ``hmocap`` parser from :data:`COMMANDS` and :data:`COMMAND_GROUPS`. Only the command
    ``argv`` names is imported (to add its options): ``hmocap record`` must not depend on the
    gesture trainer, and ``hmocap --help`` imports none."""
    import importlib

    argv = list(argv or [])
    parser = argparse.ArgumentParser(
        prog="hmocap",
        description="hmocap_ros: multi-view body tracking and depth gestures for smart rooms.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, (module_name, help_text, description, takes_ros_args) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=description, formatter_class=DefaultsShown)
        p.set_defaults(func=_run, command_module=module_name, takes_ros_args=takes_ros_args)
        if argv[:1] == [name]:
            importlib.import_module(module_name).add_arguments(p)
    for group, (group_help, group_description, kinds) in COMMAND_GROUPS.items():
        p = sub.add_parser(group, help=group_help, description=group_description)
        group_sub = p.add_subparsers(dest=f"{group}_kind", metavar="KIND", required=True)
        for kind, (module_name, help_text) in kinds.items():
            sp = group_sub.add_parser(kind, help=help_text, description=help_text, formatter_class=DefaultsShown)
            sp.set_defaults(func=_run, command_module=module_name, takes_ros_args=False)
            if argv[:2] == [group, kind]:
                importlib.import_module(module_name).add_arguments(sp)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    own, ros_args = _split_ros_args(argv)
    extra: list[str] = []
    if own[:1] == ["bench"]:
        from hmocap_ros.commands.bench import split_arguments

        own, extra = split_arguments(own)
    manners = TerminalManners()
    with manners:
        ns = build_parser(own).parse_args(own)
        ns.extra = extra
        status = int(ns.func(ns, ros_args) or 0)
        sys.stdout.flush()  # here, where a closed pipe is caught, not at the interpreter's exit
        return status
    assert manners.status is not None  # it ended Ctrl-C or a closed pipe
    return manners.status


if __name__ == "__main__":
    raise SystemExit(main())
