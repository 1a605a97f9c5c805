"""Tests of ``hmocap train gestures`` and ``hmocap eval gestures`` (hmocap_ros.commands.train_gestures,
hmocap_ros.eval.gesture_eval) and of the shipped gesture forest on the shipped demo bag."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from hmocap_ros.commands import train_gestures
from hmocap_ros.eval import gesture_eval as ge
from hmocap_ros.gestures import load_forest, save_forest
from hmocap_ros.sim import gesture_dataset as gd
from hmocap_ros.sim.gesture_set import GESTURE_CLASSES

DATA = Path(ge.__file__).resolve().parents[1] / "data"
DEMO = DATA / "demo" / "gestures_depth.mcap"
SHIPPED = DATA / "gesture_forest.npz"


def shuffled_votes(seed: int = 0):
    """A ``forest_grid_votes`` whose votes are the forest's own, moved at random among the
    grid pixels with depth: a detector that knows how often each class is voted (its prior)
    but not where."""
    from hmocap_ros.gestures import grid_votes

    rng = np.random.default_rng(seed)

    def votes(flat, padded, stride):
        class_map, grid_depth = grid_votes.forest_grid_votes(flat, padded, stride)
        valid = class_map >= 0
        class_map[valid] = rng.permutation(class_map[valid])
        return class_map, grid_depth

    return votes


def _args(module, argv):
    parser = argparse.ArgumentParser()
    module.add_arguments(parser)
    return parser.parse_args([str(a) for a in argv])


@pytest.fixture(scope="module")
def tiny_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("gestures") / "tiny.mcap"
    gd.generate(out, seed=7, subjects=1, frames=30, width=160, height=120, subject_offset=500,
                contact=False, progress=False)
    return out


def test_average_precision_all_point_interpolated():
    ap, precision, recall, _ = ge.average_precision([0.9, 0.8, 0.7], [True, False, True], 2)
    assert np.allclose(precision, [1.0, 0.5, 2 / 3]) and np.allclose(recall, [0.5, 0.5, 1.0])
    assert ap == pytest.approx(0.5 * 1.0 + 0.5 * 2 / 3)
    assert ge.average_precision([0.5, 0.4], [True, True], 4)[0] == pytest.approx(0.5)
    assert ge.average_precision([], [], 3)[0] == 0.0


def test_train_then_eval_end_to_end(tmp_path, tiny_bag, capsys, monkeypatch):
    model = tmp_path / "tiny.npz"
    argv = [tiny_bag, "--out", model, "--trees", 2, "--depth", 8, "--samples-per-class", 300, "--quiet"]
    assert train_gestures.main_from_args(_args(train_gestures, argv)) == 0
    forest = load_forest(model)
    assert forest.class_names == ("background",) + GESTURE_CLASSES
    assert len(forest.trees) == 2 and forest.features.clipped
    assert forest.meta["training"]["focal_px"] == pytest.approx(575.0 * 160 / 640)
    # pixel*metre sizes follow the focal length (575/4 px here, 525 px for the defaults)
    assert forest.features.patch_half_size_px_m == pytest.approx(85.0 * 143.75 / 525.0)
    assert train_gestures.main_from_args(_args(train_gestures, argv)) == 2  # refuses to overwrite
    assert "exists" in capsys.readouterr().err

    out_json, out_png = tmp_path / "eval.json", tmp_path / "pr.png"
    argv = [tiny_bag, "--model", model, "--json", out_json, "--plot", out_png]
    assert ge.main_from_args(_args(ge, argv)) == 0
    result = json.loads(out_json.read_text())
    for key in ("per_class", "mean_ap", "fps", "criterion", "tolerance_px", "frames", "image_size"):
        assert key in result
    assert result["frames"] == 30 and result["image_size"] == [160, 120]
    assert result["tolerance_px"] == pytest.approx(2.5)
    assert set(result["per_class"]) == set(GESTURE_CLASSES)
    assert 0.0 <= result["mean_ap"] <= 1.0 and result["fps"] > 0
    # on its own training frames, against the same votes moved at random (today 1.0 against 0.0)
    monkeypatch.setattr("hmocap_ros.gestures.detection.forest_grid_votes", shuffled_votes())
    prior = ge.evaluate_gestures(ge.read_gesture_bag(tiny_bag), forest)
    assert result["mean_ap"] > 0.8 and result["mean_ap"] > prior["mean_ap"] + 0.5, (result["mean_ap"], prior["mean_ap"])
    for c in result["per_class"].values():
        assert 0.0 <= c["ap"] <= 1.0 and c["true_positives"] <= c["positives"]
        assert len(c["pr"]["precision"]) == len(c["pr"]["recall"]) == c["detections"]
    assert out_png.stat().st_size > 1000


def test_plain_unboosted_training(tmp_path, tiny_bag):
    model = tmp_path / "plain.npz"
    argv = [tiny_bag, "--out", model, "--trees", 1, "--depth", 6, "--samples-per-class", 200,
            "--kappa", "none", "--no-boost", "--quiet"]
    assert train_gestures.main_from_args(_args(train_gestures, argv)) == 0
    forest = load_forest(model)
    assert not forest.features.clipped and forest.meta["training"]["method"] == "bagged"


def test_forest_offsets_follow_the_focal_length():
    forest = load_forest(SHIPPED)
    f0 = forest.training_focal_px
    scaled, s = forest.for_focal(2 * f0)
    assert s == pytest.approx(2.0)
    assert np.allclose(scaled.trees[0].feature, 2 * forest.trees[0].feature)
    assert scaled.training_focal_px == pytest.approx(2 * f0)
    assert forest.for_focal(f0)[0] is forest


def test_shipped_forest_detects_gestures_on_the_demo_bag(monkeypatch):
    """The shipped forest (trained at 640x480, fx 575) on the 320x240 demo bag (fx 287.5): the
    detector halves its offsets; held-out subjects and rooms. A detector that outputs nothing
    scores 0; the forest's votes moved at random (the class prior without the image) score 0.0
    against the forest's 0.99."""
    forest = load_forest(SHIPPED)
    assert forest.class_names == ("background",) + GESTURE_CLASSES
    assert SHIPPED.stat().st_size < 2_500_000
    assert len(forest.trees) == 15 and max(t.max_depth for t in forest.trees) <= 20
    assert forest.features.clipped and forest.features.kappa_m == pytest.approx(0.15)
    assert forest.training_focal_px == pytest.approx(575.0)
    result = ge.evaluate_gestures(ge.read_gesture_bag(DEMO), forest)
    assert result["offset_scale"] == pytest.approx(0.5)
    assert result["mean_ap"] > 0.8, result["mean_ap"]
    assert all(c["ap"] > 0.5 for c in result["per_class"].values()), {k: c["ap"] for k, c in result["per_class"].items()}
    monkeypatch.setattr("hmocap_ros.gestures.detection.forest_grid_votes", shuffled_votes())
    prior = ge.evaluate_gestures(ge.read_gesture_bag(DEMO), forest)
    assert result["mean_ap"] > prior["mean_ap"] + 0.5, (result["mean_ap"], prior["mean_ap"])


def test_corrupt_model_and_missing_bag_give_clear_errors(tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"PK\x03\x04 not really a zip")
    argv = [DEMO, "--model", bad, "--json", tmp_path / "r.json"]
    assert ge.main_from_args(_args(ge, argv)) == 2
    assert "cannot load the gesture forest" in capsys.readouterr().err
    argv = [tmp_path / "none.mcap", "--model", SHIPPED, "--json", tmp_path / "r.json"]
    assert ge.main_from_args(_args(ge, argv)) == 2
    assert "error" in capsys.readouterr().err
    assert not (tmp_path / "r.json").exists()


def test_forest_file_round_trip_keeps_the_focal_length(tmp_path):
    forest = load_forest(SHIPPED)
    save_forest(forest, tmp_path / "copy.npz")
    assert load_forest(tmp_path / "copy.npz").meta["training"]["focal_px"] == forest.meta["training"]["focal_px"]
