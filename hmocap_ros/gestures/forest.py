"""Offline training of gesture forests (thesis sec. 3.2.1 and boosted learning, sec. 3.2.3).

Tree growth (sec. 3.2.1): at each node ``n_tests`` random depth tests (offset pairs within
the patch, eq. 3.3 or 3.6) each with ``n_thresholds`` random thresholds (feature values of
random samples of the node) are scored by the information gain (eq. 3.2)

    dIG = H(P) - |L|/|P| H(L) - |R|/|P| H(R)

(the thesis writes it without the constant ``H(P)``, which does not change the argmax) and the
best is kept, until the maximum depth, a pure node, fewer than ``2 min_samples_leaf`` samples
or a gain below ``min_gain``. Leaves keep their class counts.

Growth is breadth first: one numba pass per depth level scores every node of the level. Per
node, the (tests x samples) feature matrix is computed sample by sample (the probes of one
sample stay in its patch, and samples come sorted by frame: cache-friendly); then, per test,
one branchless pass bins the values between the sorted thresholds into class histograms,
whose cumulative sums give the left/right counts of every threshold at once. The random draws
come from a splitmix64 stream per node seeded from the caller's ``numpy.random.Generator``, so
a run repeats bit for bit with the same seed. Python work is per level, not per node or sample.
Memory: the frames (1.2 MB per 640x480 frame) plus 4 * n_tests bytes per bag sample.

Boosted learning (sec. 3.2.3): the first tree gets a balanced bag (``samples_per_class`` of
each class, with replacement). Each trained tree classifies its out-of-bag samples; the ones it
gets wrong (at most ``max_boost_fraction`` of a bag, chosen at random, not balanced: mostly
false positives) go into the next tree's bag, which is completed per class with replacement
from the full set until each class has ``samples_per_class``.

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

import numba as nb
import numpy as np

from hmocap_ros.gestures.depth_features import depth_to_metres, pixel_metres, probe_index
from hmocap_ros.gestures.params import FeatureParams, ForestParams, TrainParams
from hmocap_ros.gestures.patches import SampleSet, collect_samples, mine_hard_negatives
from hmocap_ros.gestures.trees import Forest, Tree, apply_tree

__all__ = ["TreeReport", "balanced_error", "frames_to_metres", "grow_tree", "information_gain",
           "train_forest", "train_forest_on_frames", "train_forest_on_samples"]


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


# ---------------------------------------------------------------------------------------
# Kernels
# ---------------------------------------------------------------------------------------


@nb.njit(inline="always")
def _splitmix_next(state):
    state[0] += np.uint64(0x9E3779B97F4A7C15)
    z = state[0]
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@nb.njit(inline="always")
def _uniform(state):
    """Uniform float64 in [0, 1) with 53 random bits."""
    return np.float64(_splitmix_next(state) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@nb.njit(inline="always")
def _node_test(frames, f, x, y, d, inv_d, ux, uy, vx, vy, clipped, kappa, background, border):
    """``test_value`` on frame ``f`` of the stack (3-D indexing, no per-call view)."""
    h = frames.shape[1]
    w = frames.shape[2]
    ax = probe_index(x, ux, inv_d, w)
    ay = probe_index(y, uy, inv_d, h)
    bx = probe_index(x, vx, inv_d, w)
    by = probe_index(y, vy, inv_d, h)
    if border:
        a = pixel_metres(frames[f, min(max(ay, 0), h - 1), min(max(ax, 0), w - 1)], background)
        b = pixel_metres(frames[f, min(max(by, 0), h - 1), min(max(bx, 0), w - 1)], background)
    else:
        a = pixel_metres(frames[f, ay, ax], background) if (ax >= 0 and ay >= 0 and ax < w and ay < h) \
            else background
        b = pixel_metres(frames[f, by, bx], background) if (bx >= 0 and by >= 0 and bx < w and by < h) \
            else background
    if clipped:
        a = max(min(a, d + kappa), d - kappa)
        b = max(min(b, d + kappa), d - kappa)
    return a - b


@nb.njit(cache=True, nogil=True)
def _best_splits(frames, s_frame, s_x, s_y, s_label, live, node_start, node_count, node_seed,
                 n_classes, n_tests, n_thresholds, half_size, clipped, kappa, background, border, min_leaf,
                 xlogx, out_feature, out_threshold, out_gain, go_left):
    """Best of ``n_tests x n_thresholds`` random tests for each node of a level (eq. 3.2).

    Node ``a`` owns samples ``live[node_start[a]:node_start[a] + node_count[a]]``. Writes the
    winning test, its threshold and gain (-1 when no split leaves ``min_leaf`` on both sides)
    and, for the winner, ``go_left`` at the node's positions of ``live``.
    """
    kappa = np.float32(kappa)
    background = np.float32(background)
    max_n = 0
    for a in range(node_count.shape[0]):
        max_n = max(max_n, node_count[a])
    # The node's samples gathered once, contiguous.
    labels = np.empty(max_n, np.int32)
    fr = np.empty(max_n, np.int32)
    fx = np.empty(max_n, np.float64)
    fy = np.empty(max_n, np.float64)
    dd = np.empty(max_n, np.float32)
    inv_d = np.empty(max_n, np.float64)
    vals = np.empty((n_tests, max_n), np.float32)
    tests = np.empty((n_tests, 4), np.float32)
    thr = np.empty(n_thresholds, np.float32)
    hist = np.zeros((n_thresholds + 1, n_classes), np.int64)
    parent = np.zeros(n_classes, np.int64)
    left = np.zeros(n_classes, np.int64)
    state = np.zeros(1, np.uint64)
    for a in range(node_count.shape[0]):
        s0 = node_start[a]
        n = node_count[a]
        parent[:] = 0
        for j in range(n):
            i = live[s0 + j]
            labels[j] = s_label[i]
            parent[s_label[i]] += 1
            fr[j] = s_frame[i]
            fx[j] = s_x[i]
            fy[j] = s_y[i]
            dd[j] = pixel_metres(frames[s_frame[i], s_y[i], s_x[i]], background)
            inv_d[j] = 1.0 / np.float64(dd[j])
        sum_parent = 0.0
        for c in range(n_classes):
            sum_parent += xlogx[parent[c]]
        h_parent = (xlogx[n] - sum_parent) / n
        state[0] = node_seed[a]
        for t in range(n_tests):
            for q in range(4):
                tests[t, q] = np.float32((2.0 * _uniform(state) - 1.0) * half_size)
        # Samples outer, tests inner: all probes of one sample fall in its patch of one frame,
        # and the samples come sorted by frame, so the probes stay in cache (tests outer would
        # sweep every frame of the stack once per test).
        for j in range(n):
            for t in range(n_tests):
                vals[t, j] = _node_test(frames, fr[j], fx[j], fy[j], dd[j], inv_d[j], tests[t, 0],
                                        tests[t, 1], tests[t, 2], tests[t, 3], clipped, kappa, background,
                                        border)
        best_gain = -1.0
        best_test = 0
        best_thr = np.float32(0.0)
        for t in range(n_tests):
            for k in range(n_thresholds):
                v = vals[t, int(_uniform(state) * n)]
                m = k
                while m > 0 and thr[m - 1] > v:  # insertion sort: n_thresholds is small
                    thr[m] = thr[m - 1]
                    m -= 1
                thr[m] = v
            hist[:, :] = 0
            for j in range(n):
                # Branchless upper bound: b = number of thresholds <= v (left of threshold k iff
                # b <= k); a branchy binary search mispredicts half of its steps.
                v = vals[t, j]
                base = 0
                length = n_thresholds
                while length > 1:
                    half = length >> 1
                    base += np.int64(thr[base + half - 1] <= v) * half
                    length -= half
                base += np.int64(thr[base] <= v)
                hist[base, labels[j]] += 1
            left[:] = 0
            n_left = 0
            for k in range(n_thresholds):
                for c in range(n_classes):
                    left[c] += hist[k, c]
                    n_left += hist[k, c]
                n_right = n - n_left
                if n_left < min_leaf or n_right < min_leaf:
                    continue
                if k + 1 < n_thresholds and thr[k + 1] == thr[k]:
                    continue  # same split as the next threshold
                sum_l = 0.0
                sum_r = 0.0
                for c in range(n_classes):
                    sum_l += xlogx[left[c]]
                    sum_r += xlogx[parent[c] - left[c]]
                gain = h_parent - (xlogx[n_left] - sum_l + xlogx[n_right] - sum_r) / n
                if gain > best_gain:
                    best_gain = gain
                    best_test = t
                    best_thr = thr[k]
        bux, buy, bvx, bvy = tests[best_test, 0], tests[best_test, 1], tests[best_test, 2], tests[best_test, 3]
        out_gain[a] = best_gain
        out_feature[a, 0] = bux
        out_feature[a, 1] = buy
        out_feature[a, 2] = bvx
        out_feature[a, 3] = bvy
        out_threshold[a] = best_thr
        if best_gain >= 0.0:
            for j in range(n):
                go_left[s0 + j] = vals[best_test, j] < best_thr


# ---------------------------------------------------------------------------------------
# One tree
# ---------------------------------------------------------------------------------------


def information_gain(counts: np.ndarray) -> np.ndarray:
    """Eq. 3.2 (with the parent entropy, in nats) of splits given as class counts (..., 2, C):
    ``[..., 0, :]`` left, ``[..., 1, :]`` right. Vectorised over the leading axes, e.g. the
    (P, K, 2, C) statistics of an online tree's candidate tests (alg. 6, ``shouldSplit``)."""
    counts = np.asarray(counts, dtype=np.float64)

    def entropy(c):
        n = c.sum(-1, keepdims=True)
        p = np.divide(c, n, out=np.zeros_like(c), where=n > 0)
        return -np.sum(np.where(p > 0, p * np.log(np.where(p > 0, p, 1.0)), 0.0), axis=-1)

    side = counts.sum(-1)
    total = side.sum(-1)
    weights = np.divide(side, total[..., None], out=np.zeros_like(side), where=total[..., None] > 0)
    return entropy(counts.sum(-2)) - np.sum(weights * entropy(counts), axis=-1)


def _xlogx_table(n: int) -> np.ndarray:
    x = np.arange(n + 1, dtype=np.float64)
    out = np.zeros(n + 1)
    out[1:] = x[1:] * np.log(x[1:])
    return out


def grow_tree(samples: SampleSet, bag: np.ndarray, params: ForestParams, features: FeatureParams,
              rng: np.random.Generator) -> Tree:
    """Grow one tree (sec. 3.2.1) on ``samples[bag]`` (``bag`` may repeat samples: bootstrap)."""
    bag = np.asarray(bag, dtype=np.int64)
    if bag.size == 0:
        raise ValueError("empty bag")
    # Sorting the bag by frame and row makes a node's probes walk memory in order.
    bag = bag[np.lexsort((samples.x[bag], samples.y[bag], samples.frame[bag]))]
    s_frame = np.ascontiguousarray(samples.frame[bag], np.int32)
    s_x = np.ascontiguousarray(samples.x[bag], np.int32)
    s_y = np.ascontiguousarray(samples.y[bag], np.int32)
    s_label = np.ascontiguousarray(samples.label[bag], np.int32)
    n_classes = samples.n_classes
    frames = samples.frames
    if frames.dtype not in (np.float32, np.uint16) or not frames.flags.c_contiguous:
        raise ValueError("sample frames must be C-contiguous float32 metres or uint16 millimetres")
    xlogx = _xlogx_table(bag.size)
    min_split = 2 * params.min_samples_leaf

    feature = [np.zeros((1, 4), np.float32)]
    threshold = [np.zeros(1, np.float32)]
    left = [np.full(1, -1, np.int32)]
    right = [np.full(1, -1, np.int32)]
    counts = [np.bincount(s_label, minlength=n_classes)[None].astype(np.float32)]
    depth = [np.zeros(1, np.int16)]
    n_nodes = 1

    # Samples still in splittable nodes, grouped by node (ascending id, bag order inside).
    live = np.arange(bag.size, dtype=np.int64)
    live_node = np.zeros(bag.size, np.int64)
    level_nodes = np.zeros(1, np.int64)  # ids of this level's nodes, ascending
    level_counts = counts[0]
    for level in range(params.max_depth):
        splittable = (level_counts.sum(1) >= min_split) & (level_counts.max(1) < level_counts.sum(1))
        active = level_nodes[splittable]
        if active.size == 0:
            break
        keep = np.isin(live_node, active)
        live, live_node = live[keep], live_node[keep]
        pos = np.searchsorted(live_node, active)
        node_count = np.diff(np.append(pos, live.size)).astype(np.int64)
        node_start = pos.astype(np.int64)
        seeds = rng.integers(0, np.iinfo(np.int64).max, size=active.size, dtype=np.int64).view(np.uint64)
        out_feature = np.zeros((active.size, 4), np.float32)
        out_threshold = np.zeros(active.size, np.float32)
        out_gain = np.full(active.size, -1.0)
        go_left = np.zeros(live.size, np.bool_)
        _best_splits(frames, s_frame, s_x, s_y, s_label, live, node_start, node_count,
                     seeds, n_classes, params.n_tests, params.n_thresholds,
                     float(features.patch_half_size_px_m), features.clipped, float(features.kappa_m),
                     float(features.background_depth_m), features.border, params.min_samples_leaf, xlogx,
                     out_feature, out_threshold, out_gain, go_left)
        split = out_gain > params.min_gain
        if not np.any(split):
            break
        parents = active[split]
        n_new = 2 * parents.size
        child_left = n_nodes + 2 * np.arange(parents.size)
        # Write the tests into the parents (which live in earlier chunks: patch via concatenation).
        all_feature = np.concatenate(feature)
        all_threshold = np.concatenate(threshold)
        all_left = np.concatenate(left)
        all_right = np.concatenate(right)
        all_feature[parents] = out_feature[split]
        all_threshold[parents] = out_threshold[split]
        all_left[parents] = child_left
        all_right[parents] = child_left + 1
        feature, threshold, left, right = [all_feature], [all_threshold], [all_left], [all_right]

        # Samples of split nodes move to a child; the others are done (their node is a leaf).
        rank = np.full(n_nodes, -1, np.int64)
        rank[parents] = np.arange(parents.size)
        r = rank[live_node]
        moved = r >= 0
        live = live[moved]
        child = n_nodes + 2 * r[moved] + (~go_left[moved]).astype(np.int64)
        order = np.argsort(child, kind="stable")
        live, live_node = live[order], child[order]
        child_counts = np.bincount((live_node - n_nodes) * n_classes + s_label[live],
                                   minlength=n_new * n_classes).reshape(n_new, n_classes).astype(np.float32)
        feature.append(np.zeros((n_new, 4), np.float32))
        threshold.append(np.zeros(n_new, np.float32))
        left.append(np.full(n_new, -1, np.int32))
        right.append(np.full(n_new, -1, np.int32))
        counts.append(child_counts)
        depth.append(np.full(n_new, level + 1, np.int16))
        level_nodes = np.arange(n_nodes, n_nodes + n_new, dtype=np.int64)
        level_counts = child_counts
        n_nodes += n_new

    return Tree(np.concatenate(feature), np.concatenate(threshold), np.concatenate(left).astype(np.int32),
                np.concatenate(right).astype(np.int32), np.concatenate(counts), np.concatenate(depth))


# ---------------------------------------------------------------------------------------
# Forest
# ---------------------------------------------------------------------------------------


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


def _tqdm_progress(desc: str = "trees"):
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
    by_class = [np.flatnonzero(label == c) for c in range(n_classes)]
    present = np.array([p.size > 0 for p in by_class])
    bag_size = params.samples_per_class * int(present.sum())
    cap = int(params.max_boost_fraction * bag_size)
    oob_sum = np.zeros((len(samples), n_classes), np.float32)
    oob_n = np.zeros(len(samples), np.int32)
    carried = np.zeros(0, np.int64)
    trees, reports = [], []
    t_start = time.perf_counter()
    total_bag = 0
    for m in range(params.n_trees):
        t0 = time.perf_counter()
        have = np.bincount(label[carried], minlength=n_classes)
        need = np.where(present, np.maximum(params.samples_per_class - have, 0), 0)
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
        if progress:
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
