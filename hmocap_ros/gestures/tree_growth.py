"""Growth of one offline gesture tree (thesis sec. 3.2.1).

At each node ``n_tests`` random depth tests (offset pairs within the patch, eq. 3.3 or 3.6)
each with ``n_thresholds`` random thresholds (feature values of random samples of the node)
are scored by the information gain (eq. 3.2)

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
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from hmocap_ros.gestures.depth_features import pixel_metres, probe_index
from hmocap_ros.gestures.params import FeatureParams, ForestParams
from hmocap_ros.gestures.patches import SampleSet
from hmocap_ros.gestures.trees import Tree

__all__ = ["grow_tree", "information_gain"]


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


@nb.njit(inline="always")
def _gather_node(frames, s_frame, s_x, s_y, s_label, node_samples, background, labels, fr, fx, fy, dd, inv_d,
                 parent):
    """Copy the node's samples (``node_samples`` indexes the bag) into contiguous buffers, with
    their reference depth ``dd`` and its inverse; ``parent`` receives the class counts."""
    parent[:] = 0
    for j in range(node_samples.shape[0]):
        i = node_samples[j]
        labels[j] = s_label[i]
        parent[s_label[i]] += 1
        fr[j] = s_frame[i]
        fx[j] = s_x[i]
        fy[j] = s_y[i]
        dd[j] = pixel_metres(frames[s_frame[i], s_y[i], s_x[i]], background)
        inv_d[j] = 1.0 / np.float64(dd[j])


@nb.njit(inline="always")
def _node_entropy_times_n(xlogx, counts, n):
    """``n H`` of a node with class ``counts`` summing to ``n`` (nats): ``n log n - sum c log c``."""
    total = 0.0
    for c in range(counts.shape[0]):
        total += xlogx[counts[c]]
    return xlogx[n] - total


@nb.njit(inline="always")
def _feature_values(frames, fr, fx, fy, dd, inv_d, n, tests, clipped, kappa, background, border, vals):
    """``vals[t, j]``: test ``t`` (eq. 3.3 / 3.6) on the node's sample ``j``.

    Samples outer, tests inner: all probes of one sample fall in its patch of one frame, and the
    samples come sorted by frame, so the probes stay in cache (tests outer would sweep every
    frame of the stack once per test)."""
    for j in range(n):
        for t in range(tests.shape[0]):
            vals[t, j] = _node_test(frames, fr[j], fx[j], fy[j], dd[j], inv_d[j], tests[t, 0], tests[t, 1],
                                    tests[t, 2], tests[t, 3], clipped, kappa, background, border)


@nb.njit(inline="always")
def _draw_thresholds(state, values, n, thr):
    """``thr``: feature values of random samples of the node (with repetition), ascending."""
    for k in range(thr.shape[0]):
        v = values[int(_uniform(state) * n)]
        m = k
        while m > 0 and thr[m - 1] > v:  # insertion sort: n_thresholds is small
            thr[m] = thr[m - 1]
            m -= 1
        thr[m] = v


@nb.njit(inline="always")
def _threshold_histogram(values, labels, n, thr, hist):
    """``hist[b, c]``: samples of class ``c`` with exactly ``b`` thresholds <= their value, so the
    samples left of threshold ``k`` (value < thr[k]) are the rows ``b <= k``."""
    n_thresholds = thr.shape[0]
    hist[:, :] = 0
    for j in range(n):
        # Branchless upper bound: a branchy binary search mispredicts half of its steps.
        v = values[j]
        base = 0
        length = n_thresholds
        while length > 1:
            half = length >> 1
            base += np.int64(thr[base + half - 1] <= v) * half
            length -= half
        base += np.int64(thr[base] <= v)
        hist[base, labels[j]] += 1


@nb.njit(inline="always")
def _best_threshold(hist, parent, n, thr, n_h_parent, min_leaf, xlogx, left):
    """The highest information gain (eq. 3.2) over the thresholds of one test and the first
    threshold reaching it, from the test's :func:`_threshold_histogram`; gain -1 when no
    threshold leaves ``min_leaf`` samples on both sides."""
    n_thresholds, n_classes = hist.shape[0] - 1, hist.shape[1]
    best_gain = -1.0
    best_thr = np.float32(0.0)
    h_parent = n_h_parent / n
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
            best_thr = thr[k]
    return best_gain, best_thr


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
        _gather_node(frames, s_frame, s_x, s_y, s_label, live[s0:s0 + n], background, labels, fr, fx, fy, dd,
                     inv_d, parent)
        n_h_parent = _node_entropy_times_n(xlogx, parent, n)
        state[0] = node_seed[a]
        for t in range(n_tests):
            for q in range(4):
                tests[t, q] = np.float32((2.0 * _uniform(state) - 1.0) * half_size)
        _feature_values(frames, fr, fx, fy, dd, inv_d, n, tests, clipped, kappa, background, border, vals)
        best_gain = -1.0
        best_test = 0
        best_thr = np.float32(0.0)
        for t in range(n_tests):
            _draw_thresholds(state, vals[t], n, thr)
            _threshold_histogram(vals[t], labels, n, thr, hist)
            gain, threshold = _best_threshold(hist, parent, n, thr, n_h_parent, min_leaf, xlogx, left)
            if gain > best_gain:
                best_gain = gain
                best_test = t
                best_thr = threshold
        out_gain[a] = best_gain
        for q in range(4):
            out_feature[a, q] = tests[best_test, q]
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


@dataclass(frozen=True)
class _Bag:
    """A bag's samples as the kernel takes them: int32 arrays sorted by frame, row and column
    (a node's probes then walk memory in order), the frame stack and ``x log x`` up to its size."""

    frames: np.ndarray
    frame: np.ndarray
    x: np.ndarray
    y: np.ndarray
    label: np.ndarray
    n_classes: int
    xlogx: np.ndarray


def _sorted_bag(samples: SampleSet, bag) -> _Bag:
    bag = np.asarray(bag, dtype=np.int64)
    if bag.size == 0:
        raise ValueError("empty bag")
    bag = bag[np.lexsort((samples.x[bag], samples.y[bag], samples.frame[bag]))]
    frames = samples.frames
    if frames.dtype not in (np.float32, np.uint16) or not frames.flags.c_contiguous:
        raise ValueError("sample frames must be C-contiguous float32 metres or uint16 millimetres")
    frame, x, y, label = (np.ascontiguousarray(a[bag], np.int32)
                          for a in (samples.frame, samples.x, samples.y, samples.label))
    return _Bag(frames, frame, x, y, label, samples.n_classes, _xlogx_table(bag.size))


class _NodeArrays:
    """The flat node arrays of a tree growing level by level (children of a level numbered in
    the order of their parents, left before right)."""

    def __init__(self, root_counts: np.ndarray):
        self.feature = np.zeros((1, 4), np.float32)
        self.threshold = np.zeros(1, np.float32)
        self.left = np.full(1, -1, np.int32)
        self.right = np.full(1, -1, np.int32)
        self.counts = [root_counts]
        self.depth = [np.zeros(1, np.int16)]
        self.n_nodes = 1

    def split(self, parents: np.ndarray, feature: np.ndarray, threshold: np.ndarray) -> int:
        """Give ``parents`` their tests and two children each; returns the id of the first child."""
        first = self.n_nodes
        child_left = first + 2 * np.arange(parents.size)
        self.feature[parents] = feature
        self.threshold[parents] = threshold
        self.left[parents] = child_left
        self.right[parents] = child_left + 1
        return first

    def add_level(self, child_counts: np.ndarray, depth: int) -> np.ndarray:
        """Append the children made by :meth:`split` (leaves until split); returns their ids."""
        n_new = child_counts.shape[0]
        self.feature = np.concatenate([self.feature, np.zeros((n_new, 4), np.float32)])
        self.threshold = np.concatenate([self.threshold, np.zeros(n_new, np.float32)])
        self.left = np.concatenate([self.left, np.full(n_new, -1, np.int32)])
        self.right = np.concatenate([self.right, np.full(n_new, -1, np.int32)])
        self.counts.append(child_counts)
        self.depth.append(np.full(n_new, depth, np.int16))
        ids = np.arange(self.n_nodes, self.n_nodes + n_new, dtype=np.int64)
        self.n_nodes += n_new
        return ids

    def tree(self) -> Tree:
        return Tree(self.feature, self.threshold, self.left, self.right, np.concatenate(self.counts),
                    np.concatenate(self.depth))


def _level_splits(bag: _Bag, live: np.ndarray, live_node: np.ndarray, active: np.ndarray,
                  params: ForestParams, features: FeatureParams, rng: np.random.Generator):
    """The best test of each node of ``active`` (:func:`_best_splits`): features (A, 4),
    thresholds (A,), gains (A,; -1 = no valid split) and ``go_left`` per sample of ``live``."""
    pos = np.searchsorted(live_node, active)
    node_count = np.diff(np.append(pos, live.size)).astype(np.int64)
    node_start = pos.astype(np.int64)
    seeds = rng.integers(0, np.iinfo(np.int64).max, size=active.size, dtype=np.int64).view(np.uint64)
    out_feature = np.zeros((active.size, 4), np.float32)
    out_threshold = np.zeros(active.size, np.float32)
    out_gain = np.full(active.size, -1.0)
    go_left = np.zeros(live.size, np.bool_)
    _best_splits(bag.frames, bag.frame, bag.x, bag.y, bag.label, live, node_start, node_count,
                 seeds, bag.n_classes, params.n_tests, params.n_thresholds,
                 float(features.patch_half_size_px_m), features.clipped, float(features.kappa_m),
                 float(features.background_depth_m), features.border, params.min_samples_leaf, bag.xlogx,
                 out_feature, out_threshold, out_gain, go_left)
    return out_feature, out_threshold, out_gain, go_left


def _route_to_children(live, live_node, go_left, parents, first_child: int):
    """Samples of the split ``parents`` moved to their child, grouped by child id (bag order
    inside); the samples of the other nodes are done (their node is a leaf)."""
    rank = np.full(first_child, -1, np.int64)
    rank[parents] = np.arange(parents.size)
    r = rank[live_node]
    moved = r >= 0
    live = live[moved]
    child = first_child + 2 * r[moved] + (~go_left[moved]).astype(np.int64)
    order = np.argsort(child, kind="stable")
    return live[order], child[order]


def grow_tree(samples: SampleSet, bag: np.ndarray, params: ForestParams, features: FeatureParams,
              rng: np.random.Generator) -> Tree:
    """Grow one tree (sec. 3.2.1, eq. 3.2) on ``samples[bag]`` (``bag`` may repeat samples: bootstrap)."""
    data = _sorted_bag(samples, bag)
    n_classes = data.n_classes
    nodes = _NodeArrays(np.bincount(data.label, minlength=n_classes)[None].astype(np.float32))
    min_split = 2 * params.min_samples_leaf
    # Samples still in splittable nodes, grouped by node (ascending id, bag order inside).
    live = np.arange(data.label.size, dtype=np.int64)
    live_node = np.zeros(data.label.size, np.int64)
    level_nodes = np.zeros(1, np.int64)  # ids of this level's nodes, ascending
    level_counts = nodes.counts[0]
    for level in range(params.max_depth):
        totals = level_counts.sum(1)
        active = level_nodes[(totals >= min_split) & (level_counts.max(1) < totals)]
        if active.size == 0:
            break
        keep = np.isin(live_node, active)
        live, live_node = live[keep], live_node[keep]
        feature, threshold, gain, go_left = _level_splits(data, live, live_node, active, params, features, rng)
        split = gain > params.min_gain
        if not np.any(split):
            break
        parents = active[split]
        first_child = nodes.split(parents, feature[split], threshold[split])
        live, live_node = _route_to_children(live, live_node, go_left, parents, first_child)
        n_new = 2 * parents.size
        level_counts = np.bincount((live_node - first_child) * n_classes + data.label[live],
                                   minlength=n_new * n_classes).reshape(n_new, n_classes).astype(np.float32)
        level_nodes = nodes.add_level(level_counts, level + 1)
    return nodes.tree()
