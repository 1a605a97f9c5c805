"""A short tracker table (``tools/mocap_table.py``, slow): one held-out bag rendered small,
tracked with two methods, against answers that never look at the images computed here from
the bag's ground truth (the tracking body's rest A-pose stood at the true pelvis, the mean
of the true joint positions held still) and absolute bounds near today's figures."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fixtures.image_free import WRISTS, image_free_baselines

pytestmark = pytest.mark.slow

CLIP, SECONDS, SEED = "002_01", 0.6, 103  # the walk, held out (mocap_table's seed of its index)
METHODS = ("dd-hpf", "hpf")


def test_short_tracker_table_beats_image_free_answers(tmp_path, load_tool):
    table = load_tool("mocap_table")
    index = [clip.split(".")[0] for _, clip, _, _ in table.SEQUENCES].index(CLIP)
    assert table.bag_seed(index, False) == SEED
    out = tmp_path / "table.md"
    assert table.main(["--workdir", str(tmp_path), "--clips", CLIP, "--seconds", str(SECONDS),
                       "--methods", *METHODS, "--no-distractors", "--max-people", "1",
                       "--out", str(out), "--figures", str(tmp_path / "figures")]) == 0
    stem = table.bag_stem(f"{CLIP}.bvh", SECONDS, SEED, False)
    bag = tmp_path / f"{stem}.mcap"
    report = json.loads((tmp_path / f"{stem}_keypoints.json").read_text())
    base = image_free_baselines(bag)
    figures = {m: report["methods"][m] for m in METHODS}
    text = out.read_text()
    for m, res in figures.items():
        assert res["frames"] == base["frames"] == 15 and res["frames_with_pose"] == 15, (m, res)
        assert table._cell(res) in text  # the table shows the report's numbers
    dd, hpf = figures["dd-hpf"]["mean_mm"], figures["hpf"]["mean_mm"]
    wrist = np.mean([figures["dd-hpf"]["per_joint"][w]["mean_mm"] for w in WRISTS])
    summary = {"dd-hpf": dd, "hpf": hpf, "dd-hpf wrist": wrist, **base}
    print("short tracker table (mm):", {k: round(float(v), 1) for k, v in summary.items()})
    # Image-free answers on these 15 frames: the A-pose at the true pelvis 123 mm (wrists 343),
    # the mean pose 166 mm (wrists 164).
    assert dd < 0.4 * min(base["a_pose"], base["mean_pose"]), summary
    assert hpf < 0.4 * min(base["a_pose"], base["mean_pose"]), summary
    assert wrist < 0.5 * min(base["a_pose_wrist"], base["mean_pose_wrist"]), summary
    # Today's figures (tracker seed 0): dd-hpf 33.5 mm, hpf 35.6 mm, dd-hpf wrists 59.6 mm.
    assert dd < 45.0 and hpf < 48.0 and wrist < 80.0, summary
