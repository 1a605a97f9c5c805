#!/usr/bin/env python3
"""How often the body tracker starts on the subject when a second person is in the room.

The simulator's ``--distractors`` scenes put a second person at the side of the room (plus a
door and a ball). A single-person tracker has to choose whom to follow; the scene's subject is
the one its ground truth describes. The tracker takes the person the cameras see best, then
the largest (``visual_hull._person_component``), once that person is seen whole in
``min_full_views`` views. This tool replays distractor bags through the tracker's start
(foreground segmentation, visual hull, person choice) and counts the bags whose start-up began
on the subject (the hull's centroid within ``--radius`` m of the subject's pelvis on the floor
plan). For each bag it also prints the people the coarse hull held at that frame (voxels,
mean views seeing them, floor position), which shows why the choice went as it did.

Default: short bags of the *tuning* clips (13_29, 02_05, 01_01 and 14_27 from
``../shared/data/bvh``, simulator seeds 301..), plus 6 s of 01_01's forward jumps, which cross
3.6 m of the room as a run does (the simulator places such a motion to stay in view as long as
it can, so it starts at the edge of the common view; the first 0.6 s are tracked).
``--run``: the shipped run (09_01, an evaluation clip) at seeds 401.., which no other tool
renders::

    .venv/bin/python tools/person_choice.py            # 40 tuning bags, ~20 min (rendering)
    .venv/bin/python tools/person_choice.py --run      # 12 run bags, ~5 min

Bags are cached in ``--workdir`` (60-200 MB each).
"""
from __future__ import annotations

import argparse
import io
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hmocap_ros.body import load_body_model  # noqa: E402
from hmocap_ros.eval.mocap_eval import load_frames  # noqa: E402
from hmocap_ros.sim.mocap_dataset import MocapSimConfig, generate  # noqa: E402
from hmocap_ros.tracking.body_tracker import BodyTracker, TrackerParams  # noqa: E402
from hmocap_ros.tracking.visual_hull import coarse_people  # noqa: E402

SHARED_BVH = ROOT.parent / "shared" / "data" / "bvh"
#: (name, clip, start s, seconds or None for --seconds): tuning clips, never the evaluation
#: table's; "01_01_travel" crosses the room
CLIPS = (("CMU_13_29", "CMU_13_29.bvh", 5.0, None), ("002_05", "002_05.bvh", 2.0, None),
         ("01_01", "01_01.bvh", 4.0, None), ("14_27", "14_27.bvh", 3.0, None),
         ("01_01_travel", "01_01.bvh", 2.0, 6.0))
#: ``--run``: the shipped run, whole
RUN = (("09_01_run", "09_01.bvh", 0.0, 1.2),)


def _bag(work: Path, bvh: Path, start: float, seed: int, seconds: float) -> Path:
    path = work / f"{bvh.stem}_from{start:g}_s{seed}_distractors_{seconds:g}s.mcap"
    if not path.exists():
        t0 = time.perf_counter()
        generate(MocapSimConfig(out=path, bvh=bvh, start=start, seconds=seconds, seed=seed,
                                distractors=True, progress=False, contact_frames=0))
        print(f"rendered {path.name} in {time.perf_counter() - t0:.0f} s", flush=True)
    return path


def people_seen(tracker: BodyTracker, obs) -> list[tuple[int, float, list]]:
    """(voxels, mean views seeing them, floor x/z) of the coarse hull's large components."""
    return [(size, round(seen, 2), centroid[[0, 2]].round(2).tolist())
            for size, seen, centroid in coarse_people(
                obs.masks, obs.K, obs.R, obs.t, obs.D, tracker.room,
                max_misses=tracker.params.hull_max_misses,
                bridge_misses=tracker.params.hull_bridge_misses)]


def start_position(frames, model):
    """Where the tracker's start-up began (hull centroid), at which frame set, and the people
    the coarse hull held then."""
    tracker = BodyTracker(model, frames.rig, TrackerParams(method="hpf-apo"),
                          np.random.default_rng(0))
    for k, stamp in enumerate(frames.stamps):
        masks = frames.mask_list(k)
        tracker.update(masks, int(stamp))
        if tracker.state != "searching":
            return (tracker._hull_centroid.copy(), k,
                    people_seen(tracker, tracker.fitness.observe(masks, int(stamp))))
    return None, -1, []


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--workdir", default="/tmp/hmocap_person_choice")
    p.add_argument("--clips", nargs="*", default=None, choices=[c[0] for c in CLIPS],
                   help="subset of the tuning clips")
    p.add_argument("--run", action="store_true",
                   help="the shipped run (09_01) at seeds 401.. instead of the tuning clips")
    p.add_argument("--seeds", type=int, default=8,
                   help="simulator seeds per clip (301.., with --run 401..)")
    p.add_argument("--seconds", type=float, default=0.6, help="motion seconds tracked per bag")
    p.add_argument("--radius", type=float, default=0.5)
    ns = p.parse_args(argv)
    work = Path(ns.workdir)
    work.mkdir(parents=True, exist_ok=True)
    model = load_body_model("tracking")
    clips, bvh_dir, first_seed = ((RUN, ROOT / "hmocap_ros" / "data" / "bvh", 401) if ns.run
                                  else (CLIPS, SHARED_BVH, 301))
    hits = []
    for name, clip, start, seconds in clips:
        if ns.clips and name not in ns.clips:
            continue
        for seed in range(first_seed, first_seed + ns.seeds):
            bag = _bag(work, bvh_dir / clip, start, seed, seconds or ns.seconds)
            frames = load_frames(bag, "fg", max_frames=int(round(25 * ns.seconds)),
                                 out=io.StringIO())
            pelvis = frames.joint_names.index("pelvis") if "pelvis" in frames.joint_names else 0
            centre, k, people = start_position(frames, model)
            if centre is None or not frames.has_truth[k]:
                ok, dist = False, float("nan")
            else:
                dist = float(np.linalg.norm((centre - frames.truth[k, pelvis])[[0, 2]]))
                ok = dist <= ns.radius
            hits.append(ok)
            print(f"{bag.stem:40s} {'subject' if ok else 'OTHER  '} ({dist:.2f} m, frame {k}); "
                  f"people (voxels, views, x/z): {people}", flush=True)
    print(f"\nstarted on the subject in {sum(hits)}/{len(hits)} bags")
    return 0


if __name__ == "__main__":
    sys.exit(main())
