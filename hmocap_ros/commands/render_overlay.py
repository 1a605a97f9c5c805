"""``hmocap render overlay BAG --out FILE.mp4|DIR``: the tracked skeleton drawn over the cameras.

A multi-view bag (a rig and camera images) gives one picture per frame set: every camera's
image with the tracked skeletons projected onto it, tiled, coloured by the 3D error of each
joint where the ground truth is known (green at 0, red from ``viz.overlay.ERROR_SCALE_MM`` on,
the true skeleton thin and white beneath), and the extremity detections as crosses. A depth
bag gives the depth image false-coloured with the detected gestures' boxes and scores (the
true ones in white).
Pictures and reading: :mod:`hmocap_ros.viz.overlay`, :mod:`hmocap_ros.viz.overlay_bag`.

The skeletons and gestures are the bag's own (a recording of the nodes, or what ``hmocap
track`` / ``hmocap detect gestures`` wrote), or those of ``--outputs BAG``, matched by stamp;
``--track`` tracks the bag on the fly first (``hmocap track`` with its defaults, into a
temporary bag). The ground truth is the bag's, or that of ``--truth BAG`` (the recording the
nodes were fed). ``--out`` ending in ``.mp4`` writes an H.264 video (``.webm``: VP9, ``.avi``:
MJPEG) at the bag's frame rate (``--fps``), anything else a folder of PNG frames. Each camera's
tile has its recorded size unless ``--width`` is given; a legend under the banner says what
each colour is.

Bad input (a bag that cannot be read, no rig, no images, no skeletons or gestures, a video
that cannot be written) is one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_arguments", "main_from_args"]

PROG = "hmocap render overlay"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="multi-view bag (rig + camera images) or depth bag (.mcap or rosbag2 folder)")
    parser.add_argument("--out", required=True, type=Path,
                        help="FILE.mp4: an H.264 video that browsers play (FILE.webm: VP9, FILE.avi: MJPEG); "
                             "any other name: a folder of PNG frames")
    parser.add_argument("--outputs", type=Path, default=None,
                        help="bag with the skeletons (/skeleton, /extremities) or gestures (/gestures) to "
                             "draw, matched by stamp (default: BAG's own)")
    parser.add_argument("--truth", type=Path, default=None,
                        help="bag with the ground truth (/ground_truth/...; default: BAG's own, if any)")
    parser.add_argument("--track", action="store_true",
                        help="track the multi-view bag on the fly (hmocap track's defaults) instead of "
                             "reading its skeletons")
    parser.add_argument("--param", action="append", metavar="KEY=VALUE",
                        help="with --track: a tracker setting by its dotted name (repeatable)")
    parser.add_argument("--width", type=int, default=None,
                        help="width in pixels of each camera's tile (default: its recorded width) or of the "
                             "depth picture (default 640)")
    parser.add_argument("--fps", type=float, default=None, help="video frame rate (default: the bag's)")
    parser.add_argument("--frames", type=int, default=None, help="draw at most this many frames (default: all)")


def main_from_args(ns: argparse.Namespace) -> int:
    from hmocap_ros.viz.overlay_bag import OverlayError, render_overlay

    if ns.width is not None and ns.width < 32:
        print(f"{PROG}: --width must be at least 32 pixels, got {ns.width}", file=sys.stderr)
        return 2
    if ns.fps is not None and not ns.fps > 0:
        print(f"{PROG}: --fps must be positive, got {ns.fps}", file=sys.stderr)
        return 2
    try:
        overrides = None
        if ns.param:
            from hmocap_ros.eval.mocap_eval import tracker_overrides

            overrides = tracker_overrides(ns.param)
        count, path = render_overlay(ns.bag, ns.out, outputs=ns.outputs, truth=ns.truth, track=ns.track,
                                     overrides=overrides,
                                     width=ns.width, fps=ns.fps, max_frames=ns.frames,
                                     progress=lambda text: print(f"{PROG}: {text}", file=sys.stderr, flush=True))
    except (OverlayError, OSError, ValueError) as err:
        print(f"{PROG}: {err}", file=sys.stderr)
        return 2
    print(f"{count} pictures -> {path}")
    return 0
