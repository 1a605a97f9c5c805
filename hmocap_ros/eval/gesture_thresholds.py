"""Per-gesture detection thresholds from held-out curves: false detections per minute and recall
of each gesture as its threshold sweeps (the node's output, not only the ranking that AP scores).

The detector runs once over each validation bag (:func:`~hmocap_ros.eval.gesture_eval.run_detector`,
sweep thresholds); for a gesture ``c`` and a threshold ``th`` (score ``th``, volume
``th x min_volume / min_score``, :func:`~hmocap_ros.gestures.detection.gesture_thresholds`)
:func:`~hmocap_ros.eval.gesture_eval.score_run` gives, from the same candidates, the frames of
``c`` the node would find and its false events (a false detection of ``c`` in a frame after one
without), pooled over the bags and their minutes. The chosen threshold is the lowest of the
grid at and above which ``c``'s false events stay within ``max_false_per_minute / G`` (G
gestures: the budget of the whole node split evenly), which is the highest recall that budget
allows, unless that recall is below ``min_recall``: then the highest threshold that keeps
``min_recall`` of the gesture's frames (a detector that misses the gesture is no use, however
quiet; the thesis' automatic threshold of sec. 3.4.1 sets it from running score averages
instead; with held-out bags the trade-off is measured, not assumed). A gesture whose budget no
threshold of the grid meets gets the grid's top. The choice is stored in the forest's header,
``meta["gesture_thresholds"]`` (the node and ``hmocap eval gestures`` use it by default) and
``meta["threshold_curves"]`` (the rule, the bags and the curves).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hmocap_ros.eval.gesture_eval import GestureBag, run_detector, score_run
from hmocap_ros.gestures.params import DetectorParams
from hmocap_ros.gestures.trees import Forest

__all__ = ["THRESHOLD_GRID", "ThresholdCurve", "choose_threshold", "gesture_threshold_curves",
           "set_gesture_thresholds"]

#: Score thresholds swept (the density at the maximum is in [0, 1]).
THRESHOLD_GRID = tuple(round(0.1 + 0.025 * k, 3) for k in range(35))


@dataclass(frozen=True)
class ThresholdCurve:
    """One gesture's curves over ``grid``: recall (found frames / positives) and false events per
    minute, pooled over the validation bags."""

    name: str
    grid: tuple
    recall: tuple
    false_per_minute: tuple
    positives: int


def choose_threshold(curve: ThresholdCurve, max_false_per_minute: float, min_recall: float = 0.0) -> float:
    """The lowest threshold of ``curve.grid`` at and above which the false events per minute stay
    within ``max_false_per_minute`` (the grid's top when none does); when its recall is below
    ``min_recall``, the highest threshold whose recall reaches ``min_recall`` (the lowest of
    the grid when none does)."""
    fpm = np.asarray(curve.false_per_minute, np.float64)
    recall = np.asarray(curve.recall, np.float64)
    over = np.flatnonzero(fpm > max_false_per_minute)
    k = min(int(over[-1]) + 1 if over.size else 0, len(curve.grid) - 1)
    if recall[k] < min_recall:
        enough = np.flatnonzero(recall >= min_recall)
        k = int(enough[-1]) if enough.size else 0
    return float(curve.grid[k])


def gesture_threshold_curves(bags: list[GestureBag], forest: Forest, grid=THRESHOLD_GRID,
                             node_params: DetectorParams | None = None) -> list[ThresholdCurve]:
    """Recall and false events per minute of each gesture over ``grid``, pooled over ``bags``
    (the detector run once per bag; each gesture's threshold swept while the others keep the
    node's ``min_score`` and ``min_volume``)."""
    node_params = node_params if node_params is not None else DetectorParams()
    runs = [(bag, run_detector(bag, forest)) for bag in bags]
    names = forest.class_names[1:]
    found = np.zeros((len(names), len(grid)))
    false = np.zeros((len(names), len(grid)))
    positives = np.zeros(len(names), int)
    minutes = 0.0
    for bag, run in runs:
        first = True
        for j, th in enumerate(grid):
            # one threshold for every gesture at once: each gesture's counts depend on its own
            # threshold, except where two classes compete for one place (suppression)
            r = score_run(bag, forest, run, node_params, {n: float(th) for n in names})
            for k, n in enumerate(names):
                c = r["per_class"][n]
                found[k, j] += c["found_at_node_thresholds"]
                false[k, j] += r["false_detections"]["per_class"][n]["events"]
                if first:
                    positives[k] += c["positives"]
            if first:
                minutes += r["false_detections"]["minutes"]
            first = False
    return [ThresholdCurve(n, tuple(grid), tuple(np.round(found[k] / max(positives[k], 1), 4).tolist()),
                           tuple(np.round(false[k] / minutes if minutes > 0 else false[k], 4).tolist()),
                           int(positives[k]))
            for k, n in enumerate(names)]


def set_gesture_thresholds(forest: Forest, curves: list[ThresholdCurve], max_false_per_minute: float,
                           sources: list, min_recall: float = 0.8) -> dict:
    """Each gesture's threshold (:func:`choose_threshold` with ``max_false_per_minute / G`` and
    ``min_recall``) into ``forest.meta["gesture_thresholds"]``, and the rule, ``sources`` (the
    validation bags) and the curves into ``forest.meta["threshold_curves"]``; returns the thresholds."""
    if max_false_per_minute <= 0 or not 0.0 <= min_recall <= 1.0:
        raise ValueError("max_false_per_minute must be > 0 and min_recall in [0, 1]")
    budget = max_false_per_minute / max(len(curves), 1)
    chosen = {c.name: choose_threshold(c, budget, min_recall) for c in curves}
    forest.meta["gesture_thresholds"] = dict(chosen)
    forest.meta["threshold_curves"] = {
        "rule": f"lowest threshold with at most {budget:.4g} false events per minute per gesture "
                f"({max_false_per_minute:g} per minute for the node, split over {len(curves)} gestures), "
                f"unless its recall is below {min_recall:g}: then the highest with that recall",
        "max_false_per_minute": max_false_per_minute,
        "min_recall": min_recall,
        "bags": [str(s) for s in sources],
        "curves": {c.name: {"grid": list(c.grid), "recall": list(c.recall),
                            "false_per_minute": list(c.false_per_minute), "positives": c.positives}
                   for c in curves},
    }
    return chosen
