"""Online random forest of depth-test trees (thesis sec. 3.3.1, alg. 6; Saffari et al. 2009).

Each of the T trees starts as one leaf with random candidate tests (eq. 3.6 offset pairs
within the patch, each with random thresholds). A batch of samples (the patches of a frame)
goes through :meth:`OnlineForest.update`:

1. **Online bagging** (Oza; alg. 6 line 2): tree ``t`` takes sample ``i`` ``k ~ Poisson(lambda)``
   times (:func:`bagging_weights`).
2. **findLeaf / updateNode** for every tree and sample in one numba pass
   (:func:`~hmocap_ros.gestures.online_statistics.route_and_count`): the leaf's class
   statistics and the left/right class statistics of each of its candidate tests.
3. **shouldSplit**: a leaf touched by the batch splits when it has seen more than ``alpha``
   samples and its best candidate's information gain (eq. 3.2) exceeds ``beta``; the chosen
   test becomes the node's test, and its left/right statistics become the two children's class
   statistics (so they classify at once), and the children draw fresh candidate tests. Leaves
   at ``max_depth`` keep no candidate tests.

Design choices where the thesis is silent:

- **No class balancing**: every sample is taken at the same rate ``lambda``, as in alg. 6, so
  the leaves see the background as often as it comes (the offline trainer balances its bags,
  sec. 3.2.3). Undersampling the frequent classes to the rarest one's count online (UOB) is
  not done: the trees would see too little background to reject it (docs/gestures.md,
  "Online forests and hard negatives", "Choices where the thesis is vague").
- **Thresholds**: uniform in ``[-2 kappa, 2 kappa]``, the range of a clipped test (eq. 3.6)
  (plain tests use the same range); alg. 6 has no data to draw them from when a leaf is made.

The forest is a :class:`~hmocap_ros.gestures.trees.Forest` of kind ``"online"`` at any moment
(:meth:`OnlineForest.to_forest`): the detector, ``hmocap eval gestures`` and the forest file
take it as any forest; the open leaves' candidate tests and statistics are its trees'
``PendingTests``, and ``meta["online"]`` holds the parameters and class counts, so that
:meth:`OnlineForest.from_forest` continues growing it exactly where it stopped. All node
arrays of all trees live in one set of growable flat arrays (global node ids, children after
their parents); a split is vectorised over the leaves that qualify, ordered by (tree, node).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace

import numpy as np

from hmocap_ros.gestures.depth_features import check_stack, stack_metres
from hmocap_ros.gestures.hard_negatives import frame_negatives
from hmocap_ros.gestures.online_statistics import best_splits, reached_leaves, route_and_count
from hmocap_ros.gestures.params import FeatureParams, OnlineParams, PatchParams
from hmocap_ros.gestures.patches import collect_samples, frame_labels
from hmocap_ros.gestures.trees import FlatForest, Forest, PendingTests, Tree

__all__ = ["OnlineForest", "PassReport", "bagging_weights", "frame_batch",
           "train_online_on_frames"]


def bagging_weights(rng: np.random.Generator, n_samples: int, lam: float, n_trees: int) -> np.ndarray:
    """(T, S) int32 online bagging weights ``k[t, i] ~ Poisson(lam)``: one ``rng.poisson`` draw
    for the whole batch (alg. 6, line 2)."""
    return rng.poisson(lam, size=(int(n_trees), int(n_samples))).astype(np.int32)


def _grow(a: np.ndarray, n: int, fill=0) -> np.ndarray:
    """``a`` with its first axis at least ``n`` long (capacity doubled), new rows ``fill``."""
    if a.shape[0] >= n:
        return a
    out = np.full((max(n, 2 * a.shape[0]),) + a.shape[1:], fill, a.dtype)
    out[:a.shape[0]] = a
    return out


class OnlineForest:
    """An online gesture forest that grows batch by batch (module docstring).

    ``class_names``: classes 0..C-1 (0 = background); ``features``: the tests (eq. 3.3/3.6);
    ``params``: alg. 6's parameters; ``rng``: draws the root leaves' candidate tests.
    ``meta``: free JSON-able information kept in the forest file (``meta["online"]`` is this
    class's).
    """

    def __init__(self, class_names, features: FeatureParams, params: OnlineParams, rng: np.random.Generator,
                 meta: dict | None = None):
        self.class_names = tuple(str(c) for c in class_names)
        self.features = features
        self.params = params
        self.meta = dict(meta or {})
        c, t, k = len(self.class_names), params.n_trees, params.n_candidates
        if c < 2:
            raise ValueError("a forest needs background (class 0) and at least one gesture class")
        self.seen = np.zeros(c, np.int64)
        self.n_nodes = t
        self.feature = np.zeros((t, 4), np.float32)
        self.threshold = np.zeros(t, np.float32)
        self.left = np.full(t, -1, np.int32)
        self.right = np.full(t, -1, np.int32)
        self.counts = np.zeros((t, c), np.float32)
        self.depth = np.zeros(t, np.int16)
        self.node_tree = np.arange(t, dtype=np.int32)
        self.node_local = np.zeros(t, np.int32)
        self.node_slot = np.full(t, -1, np.int32)
        self.roots = np.arange(t, dtype=np.int32)
        self.tree_size = np.ones(t, np.int64)
        self.slot_feature = np.zeros((0, k, 4), np.float32)
        self.slot_threshold = np.zeros((0, k), np.float32)
        self.slot_counts = np.zeros((0, k, 2, c), np.float32)
        self.slot_node = np.zeros(0, np.int32)
        self._open(np.arange(t, dtype=np.int64), rng)

    # ------------------------------------------------------------------ candidate tests

    def _draw_tests(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """``n`` leaves' candidate tests: (n, K, 4) offsets (each pair repeated for its
        thresholds) and (n, K) thresholds uniform in +-2 kappa."""
        p = self.params
        r = np.float32(self.features.patch_half_size_px_m)
        pairs = rng.uniform(-r, r, size=(n, p.n_tests, 4)).astype(np.float32)
        span = 2.0 * self.features.kappa_m
        thr = rng.uniform(-span, span, size=(n, p.n_candidates)).astype(np.float32)
        return np.repeat(pairs, p.n_thresholds, axis=1), thr

    def _open(self, nodes: np.ndarray, rng: np.random.Generator) -> None:
        """Give the leaves ``nodes`` slots with fresh candidate tests and zero statistics."""
        if nodes.size == 0:
            return
        free = np.flatnonzero(self.slot_node < 0)[:nodes.size]
        n_old = self.slot_node.shape[0]
        n_new = nodes.size - free.size
        slots = np.concatenate([free, np.arange(n_old, n_old + n_new)]).astype(np.int64)
        if n_new:
            need = n_old + n_new
            self.slot_feature = _grow(self.slot_feature, need)
            self.slot_threshold = _grow(self.slot_threshold, need)
            self.slot_counts = _grow(self.slot_counts, need)
            self.slot_node = _grow(self.slot_node, need, -1)
        feature, threshold = self._draw_tests(nodes.size, rng)
        self.slot_feature[slots] = feature
        self.slot_threshold[slots] = threshold
        self.slot_counts[slots] = 0.0
        self.slot_node[slots] = nodes
        self.node_slot[nodes] = slots

    # ------------------------------------------------------------------ alg. 6

    def update(self, frames: np.ndarray, s_frame, s_x, s_y, s_label, rng: np.random.Generator) -> int:
        """Alg. 6 for a batch of samples (pixel ``(s_x[i], s_y[i])`` of ``frames[s_frame[i]]``,
        class ``s_label[i]``; frames as the offline trainer takes them: float32 metres or uint16
        millimetres). Returns the number of leaves split."""
        label = np.ascontiguousarray(s_label, np.int32)
        if label.size == 0:
            return 0
        if label.min() < 0 or label.max() >= len(self.class_names):
            raise ValueError(f"sample classes must be in [0, {len(self.class_names) - 1}]")
        self.seen += np.bincount(label, minlength=self.seen.size)
        weights = bagging_weights(rng, label.size, self.params.poisson_lambda, self.params.n_trees)
        f = self.features
        if self.n_dormant:
            self._wake(frames, s_frame, s_x, s_y, label, weights, rng)
        touched = np.zeros(self.slot_node.shape[0], np.bool_)
        route_and_count(check_stack(frames), np.ascontiguousarray(s_frame, np.int32),
                        np.ascontiguousarray(s_x, np.int32), np.ascontiguousarray(s_y, np.int32), label, weights,
                        self.roots, self.feature, self.threshold, self.left, self.right, self.counts,
                        self.node_slot, self.slot_feature, self.slot_threshold, self.slot_counts, f.clipped,
                        f.kappa_m, f.background_depth_m, f.border, touched)
        return self.split_leaves(self.slot_node[np.flatnonzero(touched)], rng)

    @property
    def dormant(self) -> np.ndarray:
        """Node ids of the dormant leaves: leaves above ``max_depth`` without candidate tests (the
        leaves of an offline forest continued online, :meth:`from_offline`)."""
        n = self.n_nodes
        return np.flatnonzero((self.left[:n] < 0) & (self.node_slot[:n] < 0) & (self.depth[:n] < self.params.max_depth))

    @property
    def n_dormant(self) -> int:
        if not hasattr(self, "_n_dormant"):
            self._n_dormant = int(self.dormant.size)
        return self._n_dormant

    def _wake(self, frames, s_frame, s_x, s_y, label, weights, rng: np.random.Generator) -> None:
        """Give the dormant leaves that a gesture sample of the batch reaches candidate tests (they
        collect split statistics from this batch on)."""
        gesture = np.flatnonzero(label > 0)
        if gesture.size == 0:
            return
        f = self.features
        leaves = np.empty((self.params.n_trees, gesture.size), np.int32)
        reached_leaves(check_stack(frames), np.ascontiguousarray(np.asarray(s_frame)[gesture], np.int32),
                       np.ascontiguousarray(np.asarray(s_x)[gesture], np.int32),
                       np.ascontiguousarray(np.asarray(s_y)[gesture], np.int32),
                       np.ascontiguousarray(weights[:, gesture]), self.roots, self.feature, self.threshold, self.left,
                       self.right, f.clipped, f.kappa_m, f.background_depth_m, f.border, leaves)
        reached = np.unique(leaves[leaves >= 0])
        wake = reached[(self.node_slot[reached] < 0) & (self.depth[reached] < self.params.max_depth)]
        if wake.size:
            self._open(wake.astype(np.int64), rng)
            self._n_dormant -= int(wake.size)

    def split_leaves(self, nodes, rng: np.random.Generator) -> int:
        """Alg. 6 ``shouldSplit`` on the open leaves among ``nodes``: each that has seen more
        than ``alpha`` samples and has a candidate test of gain above ``beta`` takes its best
        test, and its two new children that test's left/right statistics and fresh candidate
        tests (drawn from ``rng``). Returns the number of leaves split."""
        nodes = np.asarray(nodes, np.int64)
        slots = self.node_slot[nodes[(nodes >= 0) & (nodes < self.n_nodes)]].astype(np.int64)
        slots = np.unique(slots[slots >= 0])
        test = np.zeros(slots.size, np.int64)
        gain = np.zeros(slots.size, np.float64)
        best_splits(slots, self.slot_counts, float(self.params.alpha), float(self.params.beta), test, gain)
        split = test >= 0
        self._split(slots[split], test[split], rng)
        return int(np.count_nonzero(split))

    def _split(self, slots: np.ndarray, test: np.ndarray, rng: np.random.Generator) -> None:
        """Split the leaves owning ``slots`` on their candidate ``test``; in (tree, node) order,
        so the draws and node numbers do not depend on how the arrays are laid out."""
        if slots.size == 0:
            return
        parents = self.slot_node[slots].astype(np.int64)
        order = np.lexsort((self.node_local[parents], self.node_tree[parents]))
        slots, test, parents = slots[order], test[order], parents[order]
        m = parents.size
        first = self.n_nodes
        kids = first + np.arange(2 * m)
        for name in ("feature", "threshold", "left", "right", "counts", "depth", "node_tree", "node_local",
                     "node_slot"):
            setattr(self, name, _grow(getattr(self, name), first + 2 * m, -1 if name in (
                "left", "right", "node_slot") else 0))
        self.n_nodes = first + 2 * m
        self.feature[parents] = self.slot_feature[slots, test]
        self.threshold[parents] = self.slot_threshold[slots, test]
        self.left[parents] = kids[0::2]
        self.right[parents] = kids[1::2]
        self.counts[kids] = self.slot_counts[slots, test].reshape(2 * m, -1)
        self.depth[kids] = np.repeat(self.depth[parents] + 1, 2)
        tree = self.node_tree[parents]
        self.node_tree[kids] = np.repeat(tree, 2)
        # Local numbers: the tree's next free numbers, in split order within the tree.
        rank = np.arange(m) - np.searchsorted(tree, tree)  # tree is sorted
        local = self.tree_size[tree] + 2 * rank
        self.node_local[kids] = np.stack([local, local + 1], 1).ravel()
        self.tree_size += np.bincount(tree, minlength=self.params.n_trees) * 2
        self.node_slot[kids] = -1
        self.node_slot[parents] = -1
        self.slot_node[slots] = -1
        self._open(kids[self.depth[kids] < self.params.max_depth], rng)

    # ------------------------------------------------------------------ views of the model

    @property
    def n_open_leaves(self) -> int:
        return int(np.count_nonzero(self.slot_node >= 0))

    def memory_bytes(self) -> dict:
        """Bytes the model holds: ``nodes`` (tests, links, statistics, bookkeeping of every node)
        and ``open_leaves`` (the candidate tests and their statistics of leaves that may split)."""
        n, p = self.n_nodes, self.n_open_leaves
        per_node = sum(a.itemsize * int(np.prod(a.shape[1:])) for a in (
            self.feature, self.threshold, self.left, self.right, self.counts, self.depth, self.node_tree,
            self.node_local, self.node_slot))
        per_slot = sum(a.itemsize * int(np.prod(a.shape[1:])) for a in (
            self.slot_feature, self.slot_threshold, self.slot_counts, self.slot_node))
        return {"nodes": n * per_node, "open_leaves": p * per_slot, "total": n * per_node + p * per_slot}

    def flat(self) -> FlatForest:
        """The forest packed for the detection kernels, straight from the global arrays."""
        n = self.n_nodes
        nodes = np.zeros((n, 8), np.float32)
        links = nodes.view(np.int32)
        nodes[:, 0:4] = self.feature[:n]
        nodes[:, 4] = self.threshold[:n]
        links[:, 5] = self.left[:n]
        links[:, 6] = self.right[:n]
        counts = self.counts[:n]
        total = counts.sum(1, keepdims=True)
        proba = np.divide(counts, total, out=np.zeros_like(counts), where=total > 0).astype(np.float32)
        f = self.features
        return FlatForest(nodes, proba, self.roots.copy(), int(self.depth[:n].max()), f.clipped,
                          float(f.kappa_m), float(f.background_depth_m), f.border)

    def _state_meta(self) -> dict:
        return {"params": asdict(self.params), "seen": self.seen.tolist()}

    def to_forest(self) -> Forest:
        """This forest as a :class:`Forest` of kind ``"online"`` (copies; open leaves as ``PendingTests``)."""
        n = self.n_nodes
        order = np.argsort(self.node_tree[:n], kind="stable")  # per tree, in local order
        bounds = np.searchsorted(self.node_tree[:n][order], np.arange(self.params.n_trees + 1))
        trees = []
        for t in range(self.params.n_trees):
            ids = order[bounds[t]:bounds[t + 1]]
            kids_l, kids_r = self.left[ids], self.right[ids]
            tree = Tree(self.feature[ids].copy(), self.threshold[ids].copy(),
                        np.where(kids_l >= 0, self.node_local[np.maximum(kids_l, 0)], -1).astype(np.int32),
                        np.where(kids_r >= 0, self.node_local[np.maximum(kids_r, 0)], -1).astype(np.int32),
                        self.counts[ids].copy(), self.depth[ids].copy())
            open_ids = ids[self.node_slot[ids] >= 0]
            s = self.node_slot[open_ids]
            tree.pending = PendingTests(self.node_local[open_ids].astype(np.int32), self.slot_feature[s].copy(),
                                        self.slot_threshold[s].copy(), self.slot_counts[s].copy())
            trees.append(tree)
        meta = dict(self.meta)
        meta["online"] = dict(meta.get("online", {}), **self._state_meta())
        return Forest(trees, self.class_names, self.features, "online", meta)

    @classmethod
    def from_offline(cls, forest: Forest, params: OnlineParams) -> "OnlineForest":
        """Continue an offline ``forest`` (sec. 3.2, e.g. the shipped one) online: its trees,
        tests and leaf counts as they are, every leaf above ``params.max_depth`` *dormant*: it
        gets candidate tests (alg. 6) only when a sample of a gesture reaches it, so the trees
        grow where a taught gesture lands and elsewhere keep their offline structure (only
        their counts move); the open leaves' statistics stay as few as the taught gesture needs."""
        if forest.kind != "offline":
            raise ValueError(f"from_offline takes an offline forest, got a {forest.kind} one")
        if len(forest.trees) != params.n_trees:
            params = replace(params, n_trees=len(forest.trees))
        trees = [Tree(t.feature, t.threshold, t.left, t.right, t.counts, t.depth) for t in forest.trees]
        meta = dict(forest.meta)
        meta["online"] = {"params": asdict(params), "seen": [0] * forest.n_classes, "from_offline": True}
        return cls.from_forest(Forest(trees, forest.class_names, forest.features, "online", meta), params)

    @classmethod
    def from_forest(cls, forest: Forest, params: OnlineParams | None = None) -> "OnlineForest":
        """Continue growing an online ``forest`` (e.g. loaded from a file) where it stopped;
        ``params`` default to the ones it was grown with (``meta["online"]["params"]``)."""
        if forest.kind != "online" or "online" not in forest.meta:
            raise ValueError("only an online forest (kind 'online', with its meta['online']) can keep growing")
        state = forest.meta["online"]
        try:
            params = params if params is not None else OnlineParams(**state["params"])
            seen = np.asarray(state["seen"], np.int64).reshape(forest.n_classes)
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(f"the forest's online state (meta['online']) is not usable: {err}") from err
        k = params.n_candidates
        if len(forest.trees) != params.n_trees:
            raise ValueError(f"the forest has {len(forest.trees)} trees, the parameters say {params.n_trees}")
        for tree in forest.trees:
            if tree.pending is not None and tree.pending.node.size and tree.pending.n_tests != k:
                raise ValueError(f"the forest's leaves keep {tree.pending.n_tests} candidate tests, "
                                 f"the parameters say {k}")
        self = cls.__new__(cls)
        self.class_names, self.features, self.params = forest.class_names, forest.features, params
        self.meta = dict(forest.meta)
        self.seen = seen
        base = np.concatenate([[0], np.cumsum([t.n_nodes for t in forest.trees])]).astype(np.int64)
        self.n_nodes = int(base[-1])
        cat = np.concatenate
        self.feature = cat([t.feature for t in forest.trees]).astype(np.float32)
        self.threshold = cat([t.threshold for t in forest.trees]).astype(np.float32)
        self.left = cat([np.where(t.left >= 0, t.left + b, -1) for t, b in zip(forest.trees, base)]).astype(np.int32)
        self.right = cat([np.where(t.right >= 0, t.right + b, -1) for t, b in zip(forest.trees, base)]).astype(
            np.int32)
        self.counts = cat([t.counts for t in forest.trees]).astype(np.float32)
        self.depth = cat([t.depth for t in forest.trees]).astype(np.int16)
        self.node_tree = cat([np.full(t.n_nodes, m, np.int32) for m, t in enumerate(forest.trees)])
        self.node_local = cat([np.arange(t.n_nodes, dtype=np.int32) for t in forest.trees])
        self.roots = base[:-1].astype(np.int32)
        self.tree_size = np.array([t.n_nodes for t in forest.trees], np.int64)
        pend = [t.pending if t.pending is not None else PendingTests.empty(k, forest.n_classes) for t in forest.trees]
        self.slot_node = cat([p.node.astype(np.int64) + b for p, b in zip(pend, base[:-1])]).astype(np.int32)
        self.slot_feature = cat([p.feature for p in pend]).astype(np.float32).reshape(-1, k, 4)
        self.slot_threshold = cat([p.threshold for p in pend]).astype(np.float32).reshape(-1, k)
        self.slot_counts = cat([p.counts for p in pend]).astype(np.float32).reshape(-1, k, 2, forest.n_classes)
        self.node_slot = np.full(self.n_nodes, -1, np.int32)
        self.node_slot[self.slot_node] = np.arange(self.slot_node.size, dtype=np.int32)
        return self


@dataclass(frozen=True)
class PassReport:
    """What :func:`train_online_on_frames` reports after each pass over the frames."""

    index: int
    n_passes: int
    frames: int
    samples: int
    frame_negatives: int
    splits: int
    n_nodes: int
    open_leaves: int
    memory_bytes: int
    seconds: float


def frame_batch(forest: OnlineForest, frames_m: np.ndarray, f: int, label, patches: PatchParams,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The samples of frame ``f`` (columns, rows, classes, frame negatives): a gesture frame's
    patches as offline (sec. 3.2.3, "Patch collection"); a background frame's negatives from
    the forest as it stands (sec. 3.3.2, :func:`~hmocap_ros.gestures.hard_negatives.frame_negatives`)."""
    stack = frames_m[f:f + 1]
    if label[0] > 0:
        s = collect_samples(stack, [label], patches, forest.features, rng, len(forest.class_names))
        return s.x, s.y, s.label, 0
    depth = stack_metres(frames_m[f], np.float32(forest.features.background_depth_m))
    xs, ys, _ = frame_negatives(forest.flat(), depth, forest.params, rng)
    return xs, ys, np.zeros(xs.size, np.int32), int(xs.size)


def train_online_on_frames(frames_m: np.ndarray, labels, patches: PatchParams, forest: OnlineForest,
                           rng: np.random.Generator, passes: int = 5,
                           progress: Callable[[PassReport], None] | None = None) -> OnlineForest:
    """Grow ``forest`` (alg. 6) on annotated frames: ``passes`` times over the frames, each pass
    in a new random order, one :meth:`OnlineForest.update` per frame (:func:`frame_batch`).

    ``frames_m`` (F, H, W) float32 metres or uint16 millimetres (as the offline trainer takes
    them); ``labels`` per frame ``(class, u, v)`` or None (background). Design choice: the
    thesis iterates 5 times over its data set (sec. 3.3.3); the order is shuffled per pass so
    that no subject or room decides the first splits. ``forest.meta["online"]["passes"]`` gets
    the reports (appended to those of earlier sessions).
    """
    frames_m = check_stack(frames_m)
    if frames_m.ndim != 3 or frames_m.shape[0] == 0:
        raise ValueError("need a (F, H, W) stack of at least one frame")
    lab = frame_labels(labels, frames_m.shape[0])
    if lab[:, 0].max() >= len(forest.class_names):
        raise ValueError(f"a label's class is >= the forest's {len(forest.class_names)} classes")
    history = forest.meta.setdefault("online", {}).setdefault("passes", [])
    for p in range(int(passes)):
        t0 = time.perf_counter()
        n_samples = n_negatives = n_splits = 0
        for f in rng.permutation(frames_m.shape[0]):
            xs, ys, y, n_neg = frame_batch(forest, frames_m, int(f), lab[f], patches, rng)
            n_splits += forest.update(frames_m[f:f + 1], np.zeros(y.size, np.int32), xs, ys, y, rng)
            n_samples += y.size
            n_negatives += n_neg
        report = PassReport(p, int(passes), int(frames_m.shape[0]), n_samples, n_negatives, n_splits,
                            forest.n_nodes, forest.n_open_leaves, forest.memory_bytes()["total"],
                            time.perf_counter() - t0)
        history.append(asdict(report) | {"negatives": forest.params.negatives})
        if progress is not None:
            progress(report)
    return forest
