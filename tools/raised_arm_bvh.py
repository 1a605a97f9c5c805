#!/usr/bin/env python3
"""Write the tuning clips with a hand held up: CMU 13_29 with its left arm posed up.

The start-up scales the body to the visual hull's top (thesis sec. 2.3.4); a hand held above
the head tops the hull instead of the head (stop 24's held-out laugh). No CMU clip in
``../shared/data/bvh`` holds an upright subject with a hand well over the head while the
start-up runs (stop 25: the jumping jacks lift the hands 5-14 cm over a bobbing head), so this
tool makes two from 13_29's upright stretch (8.5-12.5 s): its left shoulder and elbow channels
overwritten in every frame, the rest of the motion as captured::

    .venv/bin/python tools/raised_arm_bvh.py      # writes tools/tuning_bvh/13_29_*.bvh

- ``13_29_left_arm_up.bvh``: the arm straight up beside the head (the hand tip about 34 cm
  above the head top and 25 cm beside it, outside ``start_height_column``'s 15 cm);
- ``13_29_left_hand_over_head.bvh``: the elbow bent, the hand over the head (about 17 cm
  above the head top, 12 cm from it: inside the column, as the held-out laugh's hand).

The cgspeed file's frame 0 (its added T-pose) is kept as the first frame. Only tuning uses
these clips (``tools/tuning_runs.py --set arm_up``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT.parent / "shared" / "data" / "bvh" / "CMU_13_29.bvh"
OUT_DIR = ROOT / "tools" / "tuning_bvh"
sys.path.insert(0, str(ROOT))
from hmocap_ros.sim.bvh import parse_bvh  # noqa: E402
WINDOW = (8.5, 12.5)  # seconds of 13_29: upright, the hands below the head
#: clip name -> (LeftArm, LeftForeArm) channels (Zrotation, Yrotation, Xrotation), degrees
POSES = {
    "13_29_left_arm_up": ((80.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    "13_29_left_hand_over_head": ((75.0, 0.0, -20.0), (75.0, 0.0, 0.0)),
}


def posed_clip(text: str, arm, forearm, window=WINDOW) -> str:
    """The BVH ``text`` cut to ``window`` (seconds; frame 0 kept first) with the LeftArm and
    LeftForeArm channels set to ``arm`` and ``forearm`` in every frame but frame 0."""
    bvh = parse_bvh(text)
    header, motion = text.split("MOTION", 1)
    lines = motion.strip().splitlines()
    rows = lines[2:]
    first, last = (int(round(t / bvh.frame_time)) for t in window)
    if not 1 <= first < last <= len(rows):
        raise ValueError(f"window {window} s lies outside the clip ({len(rows)} frames)")
    cols = {j: int(bvh.channel_start[bvh.joint_index(j)]) for j in ("LeftArm", "LeftForeArm")}
    out = [rows[0]]
    for row in rows[first:last]:
        values = row.split()
        for joint, angles in (("LeftArm", arm), ("LeftForeArm", forearm)):
            c = cols[joint]
            values[c:c + 3] = [f"{a:g}" for a in angles]
        out.append(" ".join(values))
    return (header + "MOTION\n" + f"Frames: {len(out)}\n" + lines[1].strip() + "\n"
            + "\n".join(out) + "\n")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--source", type=Path, default=SOURCE)
    p.add_argument("--out-dir", type=Path, default=OUT_DIR)
    ns = p.parse_args(argv)
    text = ns.source.read_text()
    for name, (arm, forearm) in POSES.items():
        path = ns.out_dir / f"{name}.bvh"
        path.write_text(posed_clip(text, arm, forearm))
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
