#!/usr/bin/env python3
"""The body tracker's start-up on each bag: when it starts, the body size it settles on, and
what ``start_height_margin`` did there.

The start-up scales the body to the visual hull's height on the frame a track starts on
(thesis sec. 2.3.4) and refines the shape over ``shape_frames`` frames (sec. 2.3.3). This tool
feeds each bag's frames to one tracker (as ``hmocap eval mocap --threads 1`` does, without
scoring) until it tracks, and prints per bag: the frame it tracks from, the estimated global
scale against the simulator subject's, the hull's top on the start frame next to the true
head top and the highest true point there (stop 24: a raised hand tops the hull), and every
growth ``start_height_margin`` applied (the tracker's log line). It is how stop 23 found on
which tuning bags that option acts at all (``docs/tracking.md``, Tuning)::

    .venv/bin/python tools/startup_scan.py /tmp/ev/tune_02_03_s6*_distractors.mcap \\
        --param start_height_margin=0.06

A bag of one of ``tools/tuning_runs.py``'s sets is read with that set's silhouettes (the
guard's exact ones); any other bag is segmented (``fg``).
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hmocap_ros.body import load_body_model  # noqa: E402
from hmocap_ros.eval.mocap_eval import load_frames, tracker_overrides  # noqa: E402
from hmocap_ros.tracking.body_tracker import BodyTracker, TrackerParams  # noqa: E402

sys.path.insert(0, str(ROOT / "tools"))
from tuning_runs import tuning_sets  # noqa: E402


class _Growths(logging.Handler):
    """Collects the tracker's start-up growth log lines."""

    def __init__(self):
        super().__init__(logging.INFO)
        self.lines: list[str] = []

    def emit(self, record):
        msg = record.getMessage()
        if msg.startswith("start-up: the visual hull's top"):
            self.lines.append(msg)


def scan(bag: Path, model, overrides: dict, seed: int, max_frames: int, silhouettes: str,
         growths: _Growths) -> dict:
    """One bag's start-up: ``{"start": frame index or None, "scale", "true_scale",
    "hull_top", "truth_top", "growths"}``; ``truth_top`` is, on the frame the start-up began,
    the true head top's height and the highest true point's name and height (a raised hand
    tops the hull as it tops the body), or None without truth."""
    frames = load_frames(bag, silhouettes, max_frames=max_frames)
    tracker = BodyTracker(model, frames.rig, TrackerParams(method="hpf-apo", **overrides),
                          np.random.default_rng(seed))
    growths.lines.clear()
    out = {"start": None, "scale": None, "hull_top": None, "truth_top": None, "growths": []}
    truth = frames.body_shape
    out["true_scale"] = None if truth is None else float(truth.global_scale)
    for k in range(len(frames.stamps)):
        masks = frames.mask_list(k)
        was = tracker.state
        tracker.update(masks, int(frames.stamps[k]))
        if was == "searching" and tracker.state == "initialising":
            hull = tracker._hull(tracker.fitness.observe(masks, int(frames.stamps[k])))
            out["hull_top"] = None if hull is None else float(hull.top)
            out["truth_top"] = _truth_top(frames, k)
        if tracker.state == "tracking":
            out["start"] = k
            out["scale"] = float(tracker.shape.global_scale)
            break
    out["growths"] = list(growths.lines)
    return out


def _truth_top(frames, k: int) -> tuple | None:
    """(head top height, name of the highest true point, its height) on frame set ``k``."""
    names = list(frames.joint_names or ())
    if frames.truth is None or "head_top" not in names:
        return None
    heights = np.asarray(frames.truth[k])[:, 1]
    if not np.isfinite(heights).all():
        return None
    top = int(np.argmax(heights))
    return float(heights[names.index("head_top")]), names[top], float(heights[top])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bags", nargs="+", type=Path, help="bags in the documented layout")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="tracker setting (as hmocap eval mocap --param)")
    p.add_argument("--seed", type=int, default=6, help="tracker seed (default %(default)s)")
    p.add_argument("--max-frames", type=int, default=60,
                   help="frame sets with truth read per bag (default %(default)s)")
    ns = p.parse_args(argv)
    try:
        overrides = tracker_overrides(ns.param)
    except ValueError as err:
        p.error(str(err))
    missing = [str(b) for b in ns.bags if not b.exists()]
    if missing:
        p.error(f"no such bag: {', '.join(missing)}")
    growths = _Growths()
    logging.getLogger("hmocap_ros.tracking.body_tracker").addHandler(growths)
    logging.getLogger("hmocap_ros.tracking.body_tracker").setLevel(logging.INFO)
    model = load_body_model("tracking")
    silhouettes = {b.name: b.silhouettes for bags in tuning_sets().values() for b in bags}
    acted = 0
    for bag in ns.bags:
        sil = silhouettes.get(bag.stem, "fg")
        r = scan(bag, model, overrides, ns.seed, ns.max_frames, sil, growths)
        if r["start"] is None:
            print(f"{bag.name} ({sil}): no track within {ns.max_frames} frames", flush=True)
            continue
        true = "?" if r["true_scale"] is None else f"{r['true_scale']:.3f}"
        top = "?" if r["hull_top"] is None else f"{r['hull_top']:.2f} m"
        truth = ("" if r["truth_top"] is None else
                 " (truth: head top {:.2f} m, highest {} {:.2f} m)".format(*r["truth_top"]))
        print(f"{bag.name} ({sil}): tracks from frame {r['start']}, global scale "
              f"{r['scale']:.3f} (true {true}), start frame's hull top {top}{truth}",
              flush=True)
        for line in r["growths"]:
            print(f"    {line}", flush=True)
        acted += bool(r["growths"])
    print(f"start_height_margin acted on {acted} of {len(ns.bags)} bags")
    return 0


if __name__ == "__main__":
    sys.exit(main())
