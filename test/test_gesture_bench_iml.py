"""``hmocap bench iml`` (benchmarks/bench_iml.py): bad input answered in one line; a quick run
writes the JSON layout of the thesis' table 3.3 comparison (slow: a few minutes)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import bench_iml  # noqa: E402 (benchmarks/ joins the path above)


def _unlabelled_bag(path: Path) -> Path:
    from hmocap_ros.io import topics
    from hmocap_ros.io.bag_writer import whole_bag
    from hmocap_ros.io.conversions import numpy_to_image
    from hmocap_ros.io.msg_factory import RosbagsFactory

    factory = RosbagsFactory()
    with whole_bag(path) as bag:
        for k in range(3):
            stamp = (k + 1) * 100_000_000
            bag.write(topics.DEPTH_IMAGE, numpy_to_image(np.full((24, 32), 2000, np.uint16), "16UC1", stamp,
                                                         "depth_optical_frame", factory), stamp)
    return path


def test_bench_refuses_a_bag_without_labels_in_one_line(tmp_path, capsys):
    bag = _unlabelled_bag(tmp_path / "recording.mcap")
    rc = bench_iml.main(["--json", str(tmp_path / "out.json"), "--same-bag", str(bag), "--work", str(tmp_path)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "no gesture labels" in err, err
    rc = bench_iml.main(["--json", str(tmp_path / "out.json"), "--other-bag", str(tmp_path / "missing.mcap")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "missing.mcap" in err, err
    assert not (tmp_path / "out.json").exists()


@pytest.mark.slow
def test_quick_bench_writes_the_table_layout(tmp_path):
    out = tmp_path / "iml.json"
    assert bench_iml.main(["--quick", "--json", str(out), "--work", str(tmp_path / "work")]) == 0
    doc = json.loads(out.read_text())
    assert list(doc["gestures"]) == ["tee"] and len(doc["sessions"]) == 2
    for s in doc["sessions"]:
        for key in ("iml_same_subject", "offline_same_subject", "iml_other_people", "offline_other_people"):
            assert 0.0 <= s[key] <= 1.0
        assert s["train_s"]["recording"] > 0 and s["train_s"]["offline_training"] > 0
    rows = doc["gestures"]["tee"]["sessions"]
    assert [r["session"] for r in rows] == [1, 2] and rows[1]["recorded_frames"] > rows[0]["recorded_frames"]
    assert set(doc["thresholds"]["tee"]) == {f"{rho:g}" for rho in bench_iml.RHOS}
    new = doc["new_gesture"]
    assert new["gesture"] == "thumbs_up"
    assert set(new["sessions"][0]["known_loss"]) == set(new["known_other_people_before"])
    assert doc["thesis"]["iml"] == [0.54, 0.78, 0.82]
