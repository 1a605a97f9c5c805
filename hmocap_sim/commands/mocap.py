"""``hmocap sim mocap``: a multi-view RGB recording of a retargeted BVH clip, with ground truth
(the recording: :mod:`hmocap_sim.mocap_dataset`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hmocap_sim.mocap_dataset import generate
from hmocap_sim.params import DEFAULT_BVH, MocapSimConfig

__all__ = ["add_arguments", "main_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``hmocap sim mocap``."""
    parser.add_argument("--bvh", type=Path, default=DEFAULT_BVH,
                        help="BVH clip (CMU MotionBuilder, Daz or iClone skeleton; default: the "
                             "packaged 13_26 'direct traffic, wave')")
    parser.add_argument("--out", type=Path, required=True,
                        help="output bag (.mcap); the rig YAML and contact sheet go next to it")
    parser.add_argument("--cameras", type=int, default=4, help="number of cameras, 1-8 (default 4)")
    parser.add_argument("--width", type=int, default=640, help="image width (default 640)")
    parser.add_argument("--height", type=int, default=480, help="image height (default 480)")
    parser.add_argument("--rig", type=Path, default=None,
                        help="use this rig YAML instead of generating one (overrides "
                             "--cameras/--width/--height)")
    parser.add_argument("--fps", type=float, default=25.0, help="frame rate (default 25)")
    parser.add_argument("--start", type=float, default=0.0,
                        help="seconds into the clip where the recording's motion starts")
    parser.add_argument("--seconds", type=float, default=4.0,
                        help="seconds of motion to render (default 4)")
    parser.add_argument("--background-seconds", type=float, default=1.0,
                        help="seconds of empty room before the subject appears (default 1)")
    parser.add_argument("--still-seconds", type=float, default=0.0,
                        help="seconds the subject first stands still in the clip's first pose "
                             "(default 0)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of subject shape, look, room, placement and noise (default 0)")
    parser.add_argument("--people", type=int, default=1,
                        help="people with ground truth, 1-4 (default 1): the subject, then "
                             "people each playing another shipped clip with a body of their "
                             "own, truth under /ground_truth/body_<k>/")
    parser.add_argument("--distractors", action="store_true",
                        help="add a door that opens, a rolling ball and a second person")
    parser.add_argument("--lighting-changes", action="store_true",
                        help="the lamp dims and comes back, auto-exposure follows, a cloud passes")
    parser.add_argument("--no-shadow", dest="shadows", action="store_false",
                        help="no shadow map (faster; the lamp lights everything)")
    parser.add_argument("--no-noise", dest="noise", action="store_false",
                        help="no sensor noise (clean renderings)")
    parser.add_argument("--supersample", type=int, default=0,
                        help="anti-aliasing factor (default 0 = 2 up to 320 px wide, else 1)")
    parser.add_argument("--contact-frames", type=int, default=4,
                        help="frames (rows) in the contact sheet (default 4)")
    parser.add_argument("--threads", type=int, default=None,
                        help="numba threads for rendering (default: all cores)")
    parser.add_argument("--force", action="store_true", help="overwrite existing outputs")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def main_from_args(ns: argparse.Namespace) -> int:
    """Run ``hmocap sim mocap`` with parsed options; print a summary."""
    if getattr(ns, "threads", None):
        import numba
        numba.set_num_threads(max(1, min(int(ns.threads), numba.config.NUMBA_NUM_THREADS)))
    config = MocapSimConfig(
        out=ns.out, bvh=ns.bvh, cameras=ns.cameras, width=ns.width, height=ns.height, fps=ns.fps,
        start=ns.start, seconds=ns.seconds, background_seconds=ns.background_seconds,
        still_seconds=ns.still_seconds, seed=ns.seed, people=ns.people,
        distractors=ns.distractors, lighting_changes=ns.lighting_changes,
        shadows=ns.shadows, noise=ns.noise,
        supersample=ns.supersample, rig=ns.rig, contact_frames=ns.contact_frames,
        force=ns.force, progress=not ns.quiet)
    try:
        r = generate(config)
    except (FileExistsError, FileNotFoundError, ValueError) as err:
        print(f"hmocap sim mocap: error: {err}", file=sys.stderr)
        return 2
    t = r.timings
    print(f"{r.bag}: {r.n_frames} frames ({r.n_motion_frames} with the subject) x "
          f"{r.n_cameras} cameras {r.width}x{r.height}, {r.bag_bytes / 1e6:.2f} MB")
    print(f"  render {r.render_seconds_per_frame:.3f} s per frame ({int(t.get('threads', 0))} "
          f"threads: shade {t.get('shade', 0):.3f}, raster {t.get('raster', 0):.3f}, sensor "
          f"{t.get('sensor', 0):.3f}, shadow {t.get('shadow', 0):.3f}); total "
          f"{r.total_seconds:.1f} s")
    print(f"  rig {r.rig_yaml}")
    print(f"  contact sheet {r.contact_sheet}")
    return 0
