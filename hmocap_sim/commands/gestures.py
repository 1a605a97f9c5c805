"""``hmocap sim gestures``: a depth bag of people gesturing among clutter, with ground truth
(the recording: :mod:`hmocap_sim.gesture_dataset`)."""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from hmocap_sim import gesture_set as gs
from hmocap_sim.depth_scene import BACKGROUNDS
from hmocap_sim.depth_sensor import DEFAULT_SENSOR, SENSOR_NAMES
from hmocap_sim.gesture_dataset import generate, sidecar_paths
from hmocap_sim.gesture_takes import HOLD_FRAMES, NEGATIVES_PER_BLOCK

__all__ = ["add_arguments", "main_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, help="bag to write (.mcap file, or a rosbag2 folder)")
    parser.add_argument("--seed", type=int, default=0, help="random seed: rooms, poses, noise (default 0)")
    parser.add_argument("--subjects", type=int, default=2, help="number of subjects (default 2)")
    parser.add_argument("--subject-offset", type=int, default=0,
                        help="identity of the first subject; use disjoint ranges for train and test (default 0)")
    parser.add_argument("--frames", type=int, default=200, help="number of depth frames (default 200)")
    parser.add_argument("--width", type=int, default=640, help="image width (default 640)")
    parser.add_argument("--height", type=int, default=480, help="image height (default 480)")
    parser.add_argument("--fps", type=float, default=10.0, help="frame rate of the stamps (default 10)")
    parser.add_argument("--hold", type=int, nargs=2, default=list(HOLD_FRAMES), metavar=("MIN", "MAX"),
                        help=f"frames per take, drawn in [MIN, MAX] (default {HOLD_FRAMES[0]} {HOLD_FRAMES[1]})")
    parser.add_argument("--background", choices=BACKGROUNDS, default="room",
                        help="room: back wall 0.4-2.3 m behind the person (default); close: 0.15-0.85 m")
    parser.add_argument("--gestures", nargs="*", default=list(gs.GESTURE_CLASSES), metavar="NAME",
                        help=f"gestures held in each block of takes (default the six: {' '.join(gs.GESTURE_CLASSES)}; "
                             f"also {' '.join(gs.NEW_GESTURES)}; none for a bag without gestures)")
    parser.add_argument("--negatives", type=int, default=NEGATIVES_PER_BLOCK,
                        help=f"everyday negative takes per block (default {NEGATIVES_PER_BLOCK})")
    parser.add_argument("--near-misses", type=int, default=0,
                        help="near-miss takes per block, drawn among the near misses of --near-misses-of "
                             "(default 0)")
    parser.add_argument("--near-misses-of", nargs="+", default=None, metavar="NAME",
                        help="the gestures whose near misses are drawn (default: --gestures)")
    parser.add_argument("--room", type=int, default=None, metavar="SEED",
                        help="every take in the room of the simulated teacher of this seed "
                             "(hmocap sim teacher --seed SEED): the same room as a teaching session")
    parser.add_argument("--sensor", choices=SENSOR_NAMES, default=DEFAULT_SENSOR,
                        help="depth sensor family: structured_light (Kinect v1-like, default), stereo "
                             "(RealSense D4xx-like) or ideal (exact depth, no holes); docs/gestures.md")
    parser.add_argument("--no-contact-sheet", action="store_true", help="do not write BAG.contact.png")
    parser.add_argument("--force", action="store_true", help="overwrite the bag and its side files")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def main_from_args(ns) -> int:
    out = Path(ns.out)
    labels_path, contact_path = sidecar_paths(out)
    if out.exists():
        if not ns.force:
            print(f"error: {out} exists (use --force to overwrite)", file=sys.stderr)
            return 2
        shutil.rmtree(out) if out.is_dir() else out.unlink()
        for p in (labels_path, contact_path):
            p.unlink(missing_ok=True)
    try:
        s = generate(out, seed=ns.seed, subjects=ns.subjects, frames=ns.frames, width=ns.width,
                     height=ns.height, subject_offset=ns.subject_offset, fps=ns.fps,
                     contact=not ns.no_contact_sheet, progress=not ns.quiet, hold=tuple(ns.hold),
                     background=ns.background, gestures=tuple(ns.gestures), negatives=ns.negatives,
                     near_misses=ns.near_misses,
                     near_of=None if ns.near_misses_of is None else tuple(ns.near_misses_of), room=ns.room,
                     sensor=ns.sensor)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    counts = ", ".join(f"{k} {v}" for k, v in s.per_class.items())
    print(f"{out}: {s.frames} frames ({counts}); {s.visible} labelled frames with a visible reference "
          f"point; {s.bag_bytes / 1e6:.2f} MB; {s.seconds:.1f} s ({s.frames / s.seconds:.1f} frames/s)")
    print(f"labels: {s.labels_path}")
    if s.contact_path:
        print(f"contact sheet: {s.contact_path}")
    return 0
