"""``hmocap sim teacher``: a simulated user who follows gesture_trainer's instructions over DDS
(the loop: :mod:`hmocap_sim.nodes.simulated_teacher`). Exit status 2 with one line on bad
options, when the trainer refuses the request or does not answer, or when the session ends
without teaching."""

from __future__ import annotations

import argparse
import sys

from hmocap_sim.depth_sensor import DEFAULT_SENSOR, SENSOR_NAMES

__all__ = ["add_arguments", "main_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--teach", metavar="GESTURE", default="",
                        help="ask gesture_trainer to teach this gesture and run until the session is done "
                             "(without it: follow the trainer's state until --duration or Ctrl-C)")
    parser.add_argument("--forest", default="", help="forest file of the teach request (default: the trainer's "
                                                     "forest_file parameter)")
    parser.add_argument("--new-forest", action="store_true", help="start a new forest in --forest")
    parser.add_argument("--extend", action="store_true", help="keep teaching a gesture the forest knows")
    parser.add_argument("--hold-after", type=float, default=0.0, metavar="SECONDS",
                        help="after the session, hold the gesture in the box this many simulated seconds")
    parser.add_argument("--duration", type=float, default=None, metavar="SECONDS",
                        help="stop after this many simulated seconds")
    parser.add_argument("--wait", type=float, default=2.0, metavar="SECONDS",
                        help="wall seconds to wait for the trainer's state of each frame (0 = publish at "
                             "the frame rate without waiting)")
    parser.add_argument("--trainer", default="gesture_trainer",
                        help="the trainer's name: its services and state topic are NAME/teach, NAME/state")
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulated person and room")
    parser.add_argument("--subject", type=int, default=0, help="subject id of the simulated person")
    parser.add_argument("--layout", type=int, default=0, help="room layout id")
    parser.add_argument("--width", type=int, default=320, help="depth image width (pixels)")
    parser.add_argument("--height", type=int, default=240, help="depth image height (pixels)")
    parser.add_argument("--fps", type=float, default=30.0, help="frame rate of the stamps")
    parser.add_argument("--sensor", choices=SENSOR_NAMES, default=DEFAULT_SENSOR,
                        help="depth sensor family of the simulated camera (hmocap sim gestures "
                             "--help; default: %(default)s)")


def _check(ns) -> str:
    problems = [(ns.width < 16 or ns.height < 16, "--width and --height must be >= 16"),
                (not ns.fps > 0, "--fps must be > 0"),
                (ns.wait < 0 or ns.hold_after < 0, "--wait and --hold-after must be >= 0"),
                (ns.duration is not None and not ns.duration > 0, "--duration must be > 0"),
                ((ns.new_forest or ns.extend or ns.forest) and not ns.teach,
                 "--forest, --new-forest and --extend go with --teach")]
    return next((text for bad, text in problems if bad), "")


def main_from_args(ns: argparse.Namespace) -> int:
    """Run ``hmocap sim teacher`` with parsed options."""
    error = _check(ns)
    if error:
        print(f"hmocap sim teacher: {error}", file=sys.stderr)
        return 2
    from hmocap_sim.nodes.simulated_teacher import TeacherError, run_teacher

    try:
        return run_teacher(ns)
    except TeacherError as err:
        print(f"hmocap sim teacher: {err}", file=sys.stderr)
        return 2
