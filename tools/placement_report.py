#!/usr/bin/env python3
"""Where the simulator puts the subject of each held-out table bag, without rendering it.

For every bag of ``tools/mocap_table.py`` (the shipped clips at seeds 101.. and, with
distractors, 201..) this prints what :func:`hmocap_ros.sim.mocap_dataset.placement_report`
computes from the same random streams as ``hmocap sim mocap``: the fraction of frames in
which every camera sees the whole body (joints and end sites inside the image, 3 % margin),
the frames seen whole by fewer than three cameras, the pelvis' nearest approach to a wall or
piece of furniture (negative: inside it) and its extent on the floor. It is how stop 26 saw
that the shipped run cannot stay in every view of the default room, and checks that no
table bag takes its subject through a wall (docs/tracking.md, Results)::

    .venv/bin/python tools/placement_report.py        # 8 bags, a few seconds
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

from hmocap_ros.sim.mocap_dataset import MocapSimConfig, placement_report  # noqa: E402
from mocap_table import BVH, SEQUENCES, bag_seed, bag_stem  # noqa: E402


def main() -> int:
    print("| bag | frames | in every view | seen by < 3 cameras | fewest views | pelvis "
          "clearance (m) | pelvis x (m) | pelvis z (m) |")
    print("|---|---|---|---|---|---|---|---|")
    for i, (_, clip, start, seconds) in enumerate(SEQUENCES):
        for distractors in (False, True):
            seed = bag_seed(i, distractors)
            r = placement_report(MocapSimConfig(out=Path("unused.mcap"), bvh=BVH / clip,
                                                start=start, seconds=seconds, seed=seed,
                                                distractors=distractors, progress=False))
            print(f"| {bag_stem(clip, seconds, seed, distractors)} | {r['frames']} | "
                  f"{100 * r['all_views']:.0f} % | {r['under_3_views']} | {r['min_views']} | "
                  f"{r['min_clearance']:.2f} | {r['x'][0]:+.2f} .. {r['x'][1]:+.2f} | "
                  f"{r['z'][0]:+.2f} .. {r['z'][1]:+.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
