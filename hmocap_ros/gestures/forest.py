"""Offline training of gesture forests (thesis sec. 3.2.3), tree by tree with
:func:`~hmocap_ros.gestures.tree_growth.grow_tree` (sec. 3.2.1).

Boosted learning (sec. 3.2.3): the first tree gets a balanced bag (``samples_per_class`` of
each class, with replacement). Each trained tree classifies its out-of-bag samples; the ones it
gets wrong (at most ``max_boost_fraction`` of a bag, chosen at random, not balanced: mostly
false positives) go into the next tree's bag, which is completed per class with replacement
from the full set until each class has ``samples_per_class``.

Located near-miss negatives (``SampleSet.located``: drawn on and around the hand of a
near-miss frame, or mined there; :mod:`hmocap_ros.gestures.patches`) are a stratum of their own
in every bag, ``located_share x samples_per_class`` of them beside the other background samples:
in the background pool they are a few per cent, so a balanced bag of 10000 background samples
would hold a few hundred of the poses the forest most needs to refuse.

Hard negative mining (:func:`train_forest_on_frames`, ``mining_rounds``): the thesis draws the
negatives uniformly outside the gesture's box (sec. 3.2.3, "Patch collection"), so the pixels a
detector actually gets wrong (other hands, near-miss poses, the frames between two gestures,
clutter shaped like a hand) are rare in the pool and boosting can only carry what the pool
holds. After a forest is trained, it votes on its own training frames like the detector
(sec. 3.2.4); its false-positive pixels join the pool as background and the forest is trained
again, as the online forests mine hard negatives by detection (sec. 3.3.2).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from hmocap_ros.gestures.depth_features import depth_to_metres
from hmocap_ros.gestures.params import FeatureParams, ForestParams, TrainParams
from hmocap_ros.gestures.patches import SampleSet, collect_samples, mine_hard_negatives
from hmocap_ros.gestures.tree_growth import grow_tree
from hmocap_ros.gestures.trees import Forest, apply_tree

__all__ = ["TreeReport", "balanced_error", "frames_to_metres", "train_forest", "train_forest_on_frames",
           "train_forest_on_samples"]


@dataclass(frozen=True)
class TreeReport:
    """What :func:`train_forest_on_samples` reports after each tree (to ``progress``, and in ``meta``)."""

    index: int
    n_trees: int
    bag_size: int
    n_carried: int
    n_nodes: int
    n_leaves: int
    max_depth: int
    seconds: float
    tree_oob_error: float
    forest_oob_error: float


def balanced_error(label: np.ndarray, predicted: np.ndarray, n_classes: int) -> float:
    """Mean over the classes present of the fraction of their samples misclassified (NaN if none)."""
    if label.size == 0:
        return float("nan")
    total = np.bincount(label, minlength=n_classes)
    wrong = np.bincount(label[predicted != label], minlength=n_classes)
    present = total > 0
    return float(np.mean(wrong[present] / total[present]))


def _balanced_bag(rng: np.random.Generator, by_class: list, per_class: np.ndarray) -> np.ndarray:
    parts = [pool[rng.integers(0, pool.size, size=int(k))] for pool, k in zip(by_class, per_class)
             if pool.size and k > 0]
    return np.concatenate(parts) if parts else np.zeros(0, np.int64)


def _tqdm_progress(desc: str = "trees") -> Callable[[TreeReport], None]:
    from tqdm import tqdm

    bar = None

    def report(r: TreeReport) -> None:
        nonlocal bar
        if bar is None:
            bar = tqdm(total=r.n_trees, desc=desc, unit="tree")
        bar.set_postfix(nodes=r.n_nodes, depth=r.max_depth, oob=f"{r.forest_oob_error:.3f}")
        bar.update(1)
        if r.index + 1 == r.n_trees:
            bar.close()

    return report


def train_forest_on_samples(samples: SampleSet, params: ForestParams, features: FeatureParams,
                            rng: np.random.Generator, class_names: Sequence[str] | None = None,
                            progress: Callable[[TreeReport], None] | bool | None = None) -> Forest:
    """Train a forest (boosted, sec. 3.2.3, unless ``params.boosted`` is false) on ``samples``.

    ``progress``: called with a :class:`TreeReport` after each tree; ``True`` shows a tqdm bar.
    ``forest.meta["training"]`` holds the reports, sample counts and speed.
    """
    n_classes = samples.n_classes
    class_names = tuple(class_names) if class_names is not None else default_class_names(n_classes)
    if len(class_names) != n_classes:
        raise ValueError(f"{len(class_names)} class names for {n_classes} classes")
    if len(samples) == 0:
        raise ValueError("no training samples")
    if progress is True:
        progress = _tqdm_progress()
    label = samples.label
    # strata of the bag: the classes, and the located near-miss negatives (module docstring)
    located = samples.located_mask & (params.located_share > 0)
    stratum = np.where(located, n_classes, label)
    by_class = [np.flatnonzero(stratum == c) for c in range(n_classes + 1)]
    present = np.array([p.size > 0 for p in by_class])
    target = np.array([params.samples_per_class] * n_classes
                      + [int(round(params.located_share * params.samples_per_class))])
    bag_size = int(target[present].sum())
    cap = int(params.max_boost_fraction * bag_size)
    oob_sum = np.zeros((len(samples), n_classes), np.float32)
    oob_n = np.zeros(len(samples), np.int32)
    carried = np.zeros(0, np.int64)
    trees, reports = [], []
    t_start = time.perf_counter()
    total_bag = 0
    for m in range(params.n_trees):
        t0 = time.perf_counter()
        have = np.bincount(stratum[carried], minlength=n_classes + 1)
        need = np.where(present, np.maximum(target - have, 0), 0)
        bag = np.concatenate([carried, _balanced_bag(rng, by_class, need)])
        tree = grow_tree(samples, bag, params, features, rng)
        leaves = apply_tree(tree, features, samples.frames, samples.frame, samples.x, samples.y)
        proba = tree.leaf_proba()[leaves]
        predicted = proba.argmax(1)
        oob = np.ones(len(samples), np.bool_)
        oob[bag] = False
        oob_sum[oob] += proba[oob]
        oob_n[oob] += 1
        seen = oob_n > 0
        forest_err = balanced_error(label[seen], oob_sum[seen].argmax(1), n_classes)
        tree_err = balanced_error(label[oob], predicted[oob], n_classes)
        n_carried = carried.size
        if params.boosted:
            wrong = np.flatnonzero(oob & (predicted != label))
            carried = wrong if wrong.size <= cap else rng.choice(wrong, size=cap, replace=False)
        trees.append(tree)
        total_bag += bag.size
        report = TreeReport(m, params.n_trees, int(bag.size), int(n_carried), tree.n_nodes, tree.n_leaves,
                            tree.max_depth, time.perf_counter() - t0, tree_err, forest_err)
        reports.append(report)
        if callable(progress):
            progress(report)
    seconds = time.perf_counter() - t_start
    meta = {"training": {
        "method": "boosted" if params.boosted else "bagged",
        "forest_params": asdict(params),
        "n_samples": len(samples),
        "class_counts": samples.class_counts().tolist(),
        "bag_samples_total": int(total_bag),
        "seconds": seconds,
        "bag_samples_per_s": total_bag / seconds if seconds > 0 else 0.0,
        "trees": [asdict(r) for r in reports],
    }}
    return Forest(trees, class_names, features, "offline", meta)


def default_class_names(n_classes: int) -> tuple:
    return ("background",) + tuple(f"gesture_{c}" for c in range(1, n_classes))


def frames_to_metres(depth_frames, params: TrainParams) -> np.ndarray:
    """Raw depth frames (a sequence of equal-size 2-D arrays, or (F, H, W)) -> (F, H, W) float32 metres."""
    first = np.asarray(depth_frames[0])
    out = np.empty((len(depth_frames),) + first.shape, np.float32)
    for f, frame in enumerate(depth_frames):
        frame = np.asarray(frame)
        if frame.shape != first.shape:
            raise ValueError(f"frame {f} has shape {frame.shape}, expected {first.shape}")
        out[f] = depth_to_metres(frame, params.depth, params.features.background_depth_m)
    return out


def train_forest(depth_frames, labels, params: TrainParams, rng: np.random.Generator,
                 class_names: Sequence[str] | None = None,
                 progress: Callable[[TreeReport], None] | bool | None = None) -> Forest:
    """Train a gesture forest from annotated depth frames: patch collection, then boosted training.

    ``depth_frames``: raw depth images of one camera (unit and invalid value per
    ``params.depth``); ``labels``: per frame ``(class_id, u, v)`` of the gesture's annotated
    pixel (column u, row v), class 0 (or ``None``) for frames without a gesture;
    ``class_names``: names of classes 0..C-1 (0 = background), default from the largest label.
    """
    if len(depth_frames) == 0:
        raise ValueError("no depth frames")
    return train_forest_on_frames(frames_to_metres(depth_frames, params), labels, params, rng, class_names,
                                  progress)


def train_forest_on_frames(frames_m: np.ndarray, labels, params: TrainParams, rng: np.random.Generator,
                           class_names: Sequence[str] | None = None,
                           progress: Callable[[TreeReport], None] | bool | None = None) -> Forest:
    """:func:`train_forest` on converted frames (F, H, W): float32 metres as made by
    :func:`~hmocap_ros.gestures.depth_features.depth_to_metres`, or compact uint16 millimetres
    (:func:`~hmocap_ros.gestures.depth_features.depth_to_millimetres`), with ``params.depth``
    and ``params.features.background_depth_m``; used as is, not copied (big training sets)."""
    if len(frames_m) == 0:
        raise ValueError("no depth frames")
    n_classes = len(class_names) if class_names is not None else None
    fp = params.forest
    samples = collect_samples(frames_m, labels, params.patches, params.features, rng, n_classes)
    forest = train_forest_on_samples(samples, fp, params.features, rng, class_names,
                                     _round_progress(progress, 0, fp.mining_rounds))
    rounds = [forest.meta["training"]]
    for r in range(fp.mining_rounds):
        t0 = time.perf_counter()
        mined = mine_hard_negatives(forest, samples.frames, labels, params.patches, rng, fp.mining_per_frame,
                                    fp.mining_stride, fp.mining_exclusion_scale)
        mining_s = time.perf_counter() - t0
        samples = samples.extended(mined)
        forest = train_forest_on_samples(samples, fp, params.features, rng, forest.class_names,
                                         _round_progress(progress, r + 1, fp.mining_rounds))
        forest.meta["training"].update({"mined_negatives": len(mined), "mining_seconds": mining_s})
        rounds.append(forest.meta["training"])
    training = forest.meta["training"]
    training.update({
        "n_frames": int(frames_m.shape[0]),
        "image_size": [int(frames_m.shape[2]), int(frames_m.shape[1])],
        "depth_format": asdict(params.depth),
        "patch_params": asdict(params.patches),
        "feature_params": asdict(params.features),
        "seconds_total": sum(r["seconds"] + r.get("mining_seconds", 0.0) for r in rounds),
        "rounds": [{k: r[k] for k in ("n_samples", "class_counts", "seconds", "bag_samples_per_s")}
                   | ({"mined_negatives": r["mined_negatives"]} if "mined_negatives" in r else {})
                   for r in rounds],
    })
    return forest


def _round_progress(progress, r: int, n_rounds: int):
    """The per-tree progress of mining round ``r`` (a tqdm bar per round for ``progress=True``)."""
    if progress is True:
        return _tqdm_progress(f"trees (round {r}/{n_rounds})" if n_rounds else "trees")
    return progress
