"""Statistics of an online forest's leaves and the split rule (thesis sec. 3.3.1, alg. 6).

Alg. 6 updates, per tree and sample, the leaf the sample reaches (``findLeaf``,
``updateNode``): the leaf's class statistics ``p_j`` and, for each of the leaf's random
candidate tests (eq. 3.6 with a random threshold), the class statistics of the samples that
fall left and right of it. ``shouldSplit`` then asks whether the leaf has seen more than
``alpha`` samples and some test's information gain (eq. 3.2) exceeds ``beta``.

:func:`route_and_count` does ``findLeaf`` and ``updateNode`` for a whole batch (the patches of
a frame) and every tree in one numba pass, samples outer and trees inner, so that all the
probes of one sample stay in its patch. Online bagging enters as an integer weight per tree
and sample: a weight ``k`` adds ``k`` to the statistics, as ``k`` updates in a row would.
:func:`best_splits` is ``shouldSplit`` + ``findBestTest`` for the leaves the batch touched.

Design choice (alg. 6 checks ``shouldSplit`` after every sample): the split rule is applied
once per batch, after the batch's statistics are in; a leaf that crosses ``alpha`` in the
middle of a frame splits at the end of that frame, and the rest of that frame's samples are
in the statistics the children inherit.

Storage (the ``PendingTests`` layout of :mod:`~hmocap_ros.gestures.trees`): an open leaf owns a
*slot*: ``slot_feature`` (K, 4) offsets, ``slot_threshold`` (K,), ``slot_counts`` (K, 2, C)
left (0) / right (1) class statistics; ``node_slot`` maps a node to its slot (-1: inner node
or a leaf at the maximum depth, which never splits). Candidate tests are stored one row per
(offset pair, threshold); consecutive rows with the same offsets share one evaluation.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from hmocap_ros.gestures.depth_features import pixel_metres, test_value
from hmocap_ros.gestures.trees import descend

__all__ = ["best_splits", "reached_leaves", "route_and_count", "split_decision"]


@nb.njit(inline="always")
def _same_offsets(feature, slot, k):
    return (feature[slot, k, 0] == feature[slot, k - 1, 0] and feature[slot, k, 1] == feature[slot, k - 1, 1]
            and feature[slot, k, 2] == feature[slot, k - 1, 2] and feature[slot, k, 3] == feature[slot, k - 1, 3])


@nb.njit(cache=True, nogil=True)
def route_and_count(frames, s_frame, s_x, s_y, s_label, weights, roots, feature, threshold, left, right, counts,
                    node_slot, slot_feature, slot_threshold, slot_counts, clipped, kappa, background, border,
                    touched):
    """Alg. 6 ``findLeaf`` + ``updateNode`` for a batch: sample ``i`` (pixel ``(s_x[i], s_y[i])``
    of ``frames[s_frame[i]]``, class ``s_label[i]``) is added ``weights[t, i]`` times to the leaf
    of tree ``t`` (root ``roots[t]``) it reaches: to the leaf's ``counts`` and, when the leaf has
    a slot, to the left/right statistics of each candidate test. ``touched[slot]`` is set for
    every slot that received a sample."""
    kappa = np.float32(kappa)
    background = np.float32(background)
    n_trees = roots.shape[0]
    n_cand = slot_feature.shape[1]
    for i in range(s_frame.shape[0]):
        img = frames[s_frame[i]]
        d = pixel_metres(img[s_y[i], s_x[i]], background)
        x = np.float64(s_x[i])
        y = np.float64(s_y[i])
        inv_d = 1.0 / np.float64(d)
        c = s_label[i]
        for t in range(n_trees):
            w = weights[t, i]
            if w == 0:
                continue
            wf = np.float32(w)
            leaf = descend(img, x, y, d, inv_d, roots[t], feature, threshold, left, right, clipped, kappa,
                           background, border)
            counts[leaf, c] += wf
            slot = node_slot[leaf]
            if slot < 0:
                continue
            touched[slot] = True
            f = np.float32(0.0)
            for k in range(n_cand):
                if k == 0 or not _same_offsets(slot_feature, slot, k):
                    f = test_value(img, x, y, d, inv_d, slot_feature[slot, k, 0], slot_feature[slot, k, 1],
                                   slot_feature[slot, k, 2], slot_feature[slot, k, 3], clipped, kappa,
                                   background, border)
                slot_counts[slot, k, np.int64(f >= slot_threshold[slot, k]), c] += wf


@nb.njit(cache=True, nogil=True)
def reached_leaves(frames, s_frame, s_x, s_y, weights, roots, feature, threshold, left, right, clipped, kappa,
                   background, border, out):
    """``findLeaf`` only: ``out[t, i]`` the leaf of tree ``t`` sample ``i`` reaches (-1 where its
    weight is 0), as :func:`route_and_count` would route it."""
    kappa = np.float32(kappa)
    background = np.float32(background)
    for i in range(s_frame.shape[0]):
        img = frames[s_frame[i]]
        d = pixel_metres(img[s_y[i], s_x[i]], background)
        x = np.float64(s_x[i])
        y = np.float64(s_y[i])
        inv_d = 1.0 / np.float64(d)
        for t in range(roots.shape[0]):
            out[t, i] = -1 if weights[t, i] == 0 else descend(
                img, x, y, d, inv_d, roots[t], feature, threshold, left, right, clipped, kappa, background, border)


@nb.njit(inline="always")
def _n_entropy(counts):
    """``n H`` (nats) of class statistics ``counts`` summing to ``n``: ``n log n - sum c log c``."""
    n = 0.0
    s = 0.0
    for c in range(counts.shape[0]):
        v = np.float64(counts[c])
        if v > 0.0:
            n += v
            s += v * np.log(v)
    return n * np.log(n) - s if n > 0.0 else 0.0


@nb.njit(cache=True, nogil=True)
def best_splits(slots, slot_counts, alpha, beta, out_test, out_gain):
    """Alg. 6 ``shouldSplit`` + ``findBestTest`` for each slot of ``slots``.

    A slot's own samples ``n`` are the sum of any one test's left and right statistics. When
    ``n > alpha``, every candidate's information gain (eq. 3.2 with the parent entropy, nats)
    ``dI = H(P) - |L|/n H(L) - |R|/n H(R)`` is computed and the first best kept: ``out_gain``
    gets it, ``out_test`` its index if it exceeds ``beta``, else -1 (-1 and gain -1 when
    ``n <= alpha``). A test with an empty side has gain exactly 0 (both entropies are the same
    sums), so a pure leaf or a useless test never splits for ``beta >= 0``.
    """
    n_classes = slot_counts.shape[3]
    parent = np.empty(n_classes, np.float64)
    for a in range(slots.shape[0]):
        s = slots[a]
        for c in range(n_classes):
            parent[c] = np.float64(slot_counts[s, 0, 0, c]) + np.float64(slot_counts[s, 0, 1, c])
        n = parent.sum()
        out_test[a] = -1
        out_gain[a] = -1.0
        if not n > alpha:
            continue
        n_h = _n_entropy(parent)
        best = -1
        best_gain = -np.inf
        for k in range(slot_counts.shape[1]):
            gain = (n_h - _n_entropy(slot_counts[s, k, 0]) - _n_entropy(slot_counts[s, k, 1])) / n
            if gain > best_gain:
                best_gain = gain
                best = k
        out_gain[a] = best_gain
        if best_gain > beta:
            out_test[a] = best


def split_decision(stats, alpha: float, beta: float) -> tuple[int, float]:
    """``shouldSplit`` of one leaf from its candidate statistics ``stats`` (K, 2, C): (the index of
    the test it splits on, or -1; the best gain, or -1 when it has seen ``alpha`` samples or fewer)."""
    stats = np.ascontiguousarray(np.asarray(stats, np.float32)[None])
    test = np.zeros(1, np.int64)
    gain = np.zeros(1, np.float64)
    best_splits(np.zeros(1, np.int64), stats, float(alpha), float(beta), test, gain)
    return int(test[0]), float(gain[0])
