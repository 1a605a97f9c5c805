"""Per-gesture thresholds from held-out curves (false events per minute and recall), stored in the
forest file and used by the node's code (``node_detections``) and the evaluator by default."""

from __future__ import annotations

import numpy as np
import pytest
from fixtures.toy_depth import TOY_CLASSES, toy_forest, toy_sequence

from hmocap_ros.eval.gesture_eval import GestureBag, run_detector, score_run
from hmocap_ros.eval.gesture_thresholds import (
    ThresholdCurve,
    choose_threshold,
    gesture_threshold_curves,
    set_gesture_thresholds,
)
from hmocap_ros.gestures.forest_file import load_forest, save_forest

SHAPE = (240, 320)


def test_the_lowest_threshold_that_keeps_the_budget_above_it():
    curve = ThresholdCurve("g", (0.1, 0.2, 0.3, 0.4, 0.5), (1.0, 0.9, 0.8, 0.6, 0.2), (5.0, 0.5, 1.5, 0.2, 0.0), 10)
    assert choose_threshold(curve, 1.0) == 0.4  # 0.2 meets the budget, but 0.3 above it does not
    assert choose_threshold(curve, 10.0) == 0.1
    never = ThresholdCurve("g", (0.1, 0.2), (1.0, 0.5), (3.0, 2.0), 10)
    assert choose_threshold(never, 1.0) == 0.2
    # a budget that costs more than the recall floor allows: the highest threshold that keeps the floor
    assert choose_threshold(curve, 1.0, min_recall=0.8) == 0.3
    assert choose_threshold(curve, 1.0, min_recall=0.5) == 0.4
    assert choose_threshold(never, 1.0, min_recall=0.9) == 0.1


def _bag(seed: int, n: int) -> GestureBag:
    frames, labels = toy_sequence(np.random.default_rng(seed), n, SHAPE)
    labels = [None if lab[0] == 0 else lab for lab in labels]
    stamps = 1_000_000_000 + np.arange(n, dtype=np.int64) * 100_000_000
    return GestureBag(np.stack(frames), stamps, labels, np.ones(n, bool), 525.0 * SHAPE[1] / 640.0, TOY_CLASSES,
                      [f"toy{seed}"])


def test_thresholds_from_held_out_curves_are_stored_and_keep_the_node_within_budget(tmp_path):
    forest = toy_forest(shape=SHAPE)
    forest = load_forest(save_forest(forest, tmp_path / "copy.npz"))  # the cached forest stays as it is
    val = _bag(21, 60)
    curves = gesture_threshold_curves([val], forest)
    assert [c.name for c in curves] == list(TOY_CLASSES[1:])
    for c in curves:
        assert c.positives > 0 and all(a >= b for a, b in zip(c.recall, c.recall[1:]))  # recall falls with th
    budget = 2.0  # per minute for the node: 1 per gesture
    chosen = set_gesture_thresholds(forest, curves, budget, val.sources, min_recall=0.0)
    assert set(chosen) == set(TOY_CLASSES[1:])
    save_forest(forest, tmp_path / "f.npz")
    stored = load_forest(tmp_path / "f.npz")
    assert stored.meta["gesture_thresholds"] == pytest.approx(chosen)
    assert stored.meta["threshold_curves"]["bags"] == ["toy21"]

    # scored by default at the stored thresholds: each gesture within its share of the budget
    r = score_run(val, stored, run_detector(val, stored))
    assert r["node_thresholds"]["taught"] == pytest.approx(chosen)
    for name in TOY_CLASSES[1:]:
        assert r["false_detections"]["per_class"][name]["events_per_minute"] <= budget / 2 + 1e-9
        k = [c.name for c in curves].index(name)
        j = list(curves[k].grid).index(chosen[name])
        assert r["per_class"][name]["found_at_node_thresholds"] == pytest.approx(
            curves[k].recall[j] * curves[k].positives, abs=1)
