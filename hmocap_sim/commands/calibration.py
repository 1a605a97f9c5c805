"""``hmocap sim calibration``: a rig calibration session, a ChArUco board seen by every camera
(the recording: :mod:`hmocap_sim.calibration_session`)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from hmocap_ros.calibration.board import add_board_arguments, board_from_args
from hmocap_sim.calibration_session import CalibrationSimConfig, generate

__all__ = ["add_arguments", "main_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``hmocap sim calibration``."""
    parser.add_argument("--out", type=Path, required=True,
                        help="output bag (.mcap); the true rig goes next to it as <stem>_rig.yaml")
    parser.add_argument("--cameras", type=int, default=4, help="number of cameras, 1-8 (default 4)")
    parser.add_argument("--seconds", type=float, default=60.0,
                        help="seconds of the board carried through the room (default 60)")
    parser.add_argument("--floor-seconds", type=float, default=1.0,
                        help="seconds of the board lying on the floor first (default 1)")
    parser.add_argument("--fps", type=float, default=3.0, help="frame rate (default 3)")
    parser.add_argument("--width", type=int, default=640, help="image width (default 640)")
    parser.add_argument("--height", type=int, default=480, help="image height (default 480)")
    parser.add_argument("--seed", type=int, default=0, help="seed of path, background and noise (default 0)")
    parser.add_argument("--rig", type=Path, default=None,
                        help="the cameras of this rig YAML (e.g. a mocap bag's <stem>_rig.yaml) "
                             "instead of --cameras/--width/--height")
    add_board_arguments(parser)
    parser.add_argument("--force", action="store_true", help="overwrite existing outputs")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")


def main_from_args(ns: argparse.Namespace) -> int:
    """Run ``hmocap sim calibration`` with parsed options; print a summary."""
    from hmocap_ros.geometry.rig import load_rig

    try:
        config = CalibrationSimConfig(
            out=ns.out, cameras=ns.cameras, width=ns.width, height=ns.height, fps=ns.fps,
            seconds=ns.seconds, floor_seconds=ns.floor_seconds, seed=ns.seed,
            board=board_from_args(ns), rig=ns.rig, force=ns.force, progress=not ns.quiet)
        t0 = time.perf_counter()
        bag, rig_path, n_frames = generate(config)
    except (FileExistsError, ValueError, OSError) as err:
        print(f"hmocap sim calibration: error: {err}", file=sys.stderr)
        return 2
    rig = load_rig(rig_path)
    print(f"{bag}: {n_frames} frames x {len(rig)} cameras {rig[0].width}x{rig[0].height}, board "
          f"{config.board.describe()}, {bag.stat().st_size / 1e6:.1f} MB, "
          f"{time.perf_counter() - t0:.1f} s")
    print(f"  true rig {rig_path}")
    return 0
