"""``hmocap export BAG --format bvh|trc|csv``: write one body's recorded motion to a file.

The motion is what ``body_tracker`` publishes (``--source tracked``: ``skeleton``,
``joint_states``, ``body_shape``) or the simulator's ground truth (``--source truth``); the
formats are :data:`hmocap_ros.export.formats.EXPORT_FORMATS` (docs/export.md). Bad input (a
bag that cannot be read, one without the topics a format needs, an unknown body id) is one
line on stderr and exit status 2; the file is written whole or not at all.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_arguments", "default_out", "main_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from hmocap_ros.export.formats import EXPORT_FORMATS
    from hmocap_ros.export.motion import MOTION_SOURCES

    parser.add_argument("bag", help=".mcap file or rosbag2 directory")
    parser.add_argument("--format", required=True, choices=sorted(EXPORT_FORMATS),
                        help="; ".join(f"{name}: {fmt.help}" for name, fmt in EXPORT_FORMATS.items()))
    parser.add_argument("--out", type=Path, default=None,
                        help="output file (default: the bag's name with the format's suffix, beside it)")
    parser.add_argument("--body-id", default=None,
                        help="body to export (default: the first body on the skeleton topic)")
    parser.add_argument("--source", default="tracked", choices=sorted(MOTION_SOURCES),
                        help="tracked: body_tracker's skeleton, joint_states and body_shape; truth: the "
                             "simulator's /ground_truth/ topics (default tracked)")


def default_out(bag: Path, suffix: str) -> Path:
    """``run.mcap`` -> ``run<suffix>``; a rosbag2 folder ``run/`` -> ``run<suffix>`` beside it."""
    bag = Path(bag)
    return bag.with_suffix(suffix) if bag.suffix == ".mcap" else bag.parent / f"{bag.name}{suffix}"


def main_from_args(ns: argparse.Namespace) -> int:
    from hmocap_ros.export.atomic_file import write_text_atomically
    from hmocap_ros.export.formats import EXPORT_FORMATS
    from hmocap_ros.export.motion import ExportError, read_motion
    from hmocap_ros.io.bag_reader import BagReadError

    fmt = EXPORT_FORMATS[ns.format]
    bag = Path(ns.bag)
    out = Path(ns.out) if ns.out is not None else default_out(bag, fmt.suffix)
    try:
        if out.exists() and bag.exists() and out.resolve() == bag.resolve():
            raise ExportError(f"{out}: the output would replace the bag")
        motion = read_motion(bag, ns.source, ns.body_id)
        result = fmt.render(motion, out)
        write_text_atomically(out, result.text)
    except (BagReadError, ExportError) as err:
        print(f"hmocap export: {err}", file=sys.stderr)
        return 2
    except OSError as err:
        print(f"hmocap export: cannot write {out}: {err.strerror or err}", file=sys.stderr)
        return 2
    for note in result.notes:
        print(f"hmocap export: note: {note}", file=sys.stderr)
    print(f"{out}: {result.n_frames} frames of {motion.body_id} ({ns.source}, {ns.format})")
    return 0
