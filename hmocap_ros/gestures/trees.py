"""Random forest of depth-test trees: the in-memory model shared by offline and online training.

A :class:`Tree` is a set of flat node arrays (no Python object per node), so that numba kernels
walk it and :mod:`hmocap_ros.gestures.forest_file` stores it as is:

=============  ==============  =================================================================
 array          shape / dtype   meaning
=============  ==============  =================================================================
 ``feature``    (N, 4) f32      test offsets (u_x, u_y, v_x, v_y) in pixel*metres (eq. 3.3/3.6)
 ``threshold``  (N,) f32        a sample goes left when f < threshold
 ``left``       (N,) i32        left child index, -1 at a leaf
 ``right``      (N,) i32        right child index, -1 at a leaf
 ``counts``     (N, C) f32      class statistics of the training samples that reached the node
                                (integer counts offline; label densities online, alg. 6)
 ``depth``      (N,) i16        depth of the node (root 0)
=============  ==============  =================================================================

Node 0 is the root. A leaf's class distribution ``p_l(c)`` is its ``counts`` normalised
(all zero reads as "no vote"); the forest averages them over trees (eq. 3.1).
Every node keeps its counts (not only leaves): an online tree (alg. 6) splits a leaf and
hands its statistics to the children, and keeps growing after a save/load. An online tree's
unsplit leaves also carry their candidate tests and the per-test left/right statistics
(:class:`PendingTests`), so that training resumes exactly where it stopped (sec. 3.4.2).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numba as nb
import numpy as np

from hmocap_ros.gestures.depth_features import check_stack, pixel_metres, test_value
from hmocap_ros.gestures.params import FeatureParams

__all__ = ["FlatForest", "Forest", "PendingTests", "Tree", "apply_tree"]

FOREST_KINDS = ("offline", "online")


@dataclass(eq=False)
class PendingTests:
    """Candidate tests of an online tree's unsplit leaves (thesis sec. 3.3.1, alg. 6).

    ``node`` (P,) i32: the leaf each row belongs to; ``feature`` (P, K, 4) f32 and
    ``threshold`` (P, K) f32: its K random tests; ``counts`` (P, K, 2, C) f32: class
    statistics of the samples that went left (0) / right (1) of each test.
    """

    node: np.ndarray
    feature: np.ndarray
    threshold: np.ndarray
    counts: np.ndarray

    @classmethod
    def empty(cls, n_tests: int, n_classes: int) -> "PendingTests":
        return cls(np.zeros(0, np.int32), np.zeros((0, n_tests, 4), np.float32),
                   np.zeros((0, n_tests), np.float32), np.zeros((0, n_tests, 2, n_classes), np.float32))

    @property
    def n_tests(self) -> int:
        return int(self.feature.shape[1])


@dataclass(eq=False)
class Tree:
    """One binary tree as flat node arrays (see the module docstring)."""

    feature: np.ndarray
    threshold: np.ndarray
    left: np.ndarray
    right: np.ndarray
    counts: np.ndarray
    depth: np.ndarray
    pending: PendingTests | None = None

    @classmethod
    def single_leaf(cls, counts) -> "Tree":
        """A tree that is only a root leaf with class statistics ``counts`` (an online start)."""
        counts = np.asarray(counts, np.float32).reshape(1, -1)
        return cls(np.zeros((1, 4), np.float32), np.zeros(1, np.float32), np.full(1, -1, np.int32),
                   np.full(1, -1, np.int32), counts, np.zeros(1, np.int16))

    @property
    def n_nodes(self) -> int:
        return int(self.left.shape[0])

    @property
    def is_leaf(self) -> np.ndarray:
        return self.left < 0

    @property
    def n_leaves(self) -> int:
        return int(np.count_nonzero(self.left < 0))

    @property
    def max_depth(self) -> int:
        return int(self.depth.max()) if self.n_nodes else 0

    def leaf_proba(self) -> np.ndarray:
        """(N, C) float32 class distribution of every node (rows of zeros where it has no samples)."""
        total = self.counts.sum(axis=1, keepdims=True)
        return np.divide(self.counts, total, out=np.zeros_like(self.counts), where=total > 0).astype(np.float32)

    def validate(self, n_classes: int) -> None:
        """Raise ``ValueError`` unless the arrays form a proper tree rooted at node 0."""
        n = self.n_nodes
        shapes = {"feature": (n, 4), "threshold": (n,), "left": (n,), "right": (n,),
                  "counts": (n, n_classes), "depth": (n,)}
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                raise ValueError(f"tree array {name} has shape {getattr(self, name).shape}, expected {shape}")
        if n == 0:
            raise ValueError("tree has no nodes")
        if not (np.all(np.isfinite(self.feature)) and np.all(np.isfinite(self.threshold))
                and np.all(np.isfinite(self.counts)) and np.all(self.counts >= 0)):
            raise ValueError("tree has non-finite tests or negative/non-finite counts")
        leaf = self.left < 0
        if np.any((self.right < 0) != leaf):
            raise ValueError("a node has exactly one child")
        inner = np.flatnonzero(~leaf)
        kids = np.concatenate([self.left[inner], self.right[inner]])
        if kids.size and (kids.min() < 1 or kids.max() >= n):
            raise ValueError("child index out of range")
        # Each non-root node is the child of exactly one node: a tree, no cycles, no sharing.
        if kids.size != n - 1 or np.unique(kids).size != n - 1:
            raise ValueError("node links do not form a tree")
        parent_depth = np.concatenate([self.depth[inner], self.depth[inner]])
        if np.any(self.depth[kids] != parent_depth + 1) or self.depth[0] != 0:
            raise ValueError("node depths are inconsistent with the links")
        if self.pending is not None:
            p = self.pending
            k = p.feature.shape[1] if p.feature.ndim == 3 else -1
            if (p.node.ndim != 1 or p.feature.shape != (p.node.shape[0], k, 4)
                    or p.threshold.shape != (p.node.shape[0], k)
                    or p.counts.shape != (p.node.shape[0], k, 2, n_classes)):
                raise ValueError("pending test arrays have inconsistent shapes")
            if p.node.size and (p.node.min() < 0 or p.node.max() >= n or not np.all(leaf[p.node])):
                raise ValueError("pending tests refer to a node that is not a leaf")
            if not (np.all(np.isfinite(p.feature)) and np.all(np.isfinite(p.threshold))
                    and np.all(np.isfinite(p.counts))):
                raise ValueError("pending tests are not finite")


@dataclass(frozen=True, eq=False)
class FlatForest:
    """All trees packed for the detection kernels.

    ``nodes`` (N, 8) float32, one 32-byte record per node: offsets u_x, u_y, v_x, v_y,
    threshold, then (read through ``links = nodes.view(int32)``) the global indices of the left
    and right child (-1 at a leaf) and padding; one record is one memory fetch, which is what
    bounds the speed of a walk down a tree. ``roots`` (M,) are the trees' root nodes, ``proba``
    (N, C) each node's normalised class distribution, ``max_depth`` the deepest node.
    """

    nodes: np.ndarray
    proba: np.ndarray
    roots: np.ndarray
    max_depth: int
    clipped: bool
    kappa: float
    background: float
    border: bool

    @property
    def links(self) -> np.ndarray:
        return self.nodes.view(np.int32)

    @property
    def n_classes(self) -> int:
        return int(self.proba.shape[1])


@dataclass(eq=False)
class Forest:
    """A gesture forest: trees, the classes (0 = background) and the tests they were grown with.

    ``meta`` is free JSON-able information (training parameters, data, timings) stored in the
    forest file; ``kind`` is ``"offline"`` (sec. 3.2) or ``"online"`` (sec. 3.3).
    """

    trees: list
    class_names: tuple
    features: FeatureParams = field(default_factory=FeatureParams)
    kind: str = "offline"
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        self.class_names = tuple(str(c) for c in self.class_names)
        if len(self.class_names) < 2:
            raise ValueError("a forest needs background (class 0) and at least one gesture class")
        if self.kind not in FOREST_KINDS:
            raise ValueError(f"forest kind must be one of {FOREST_KINDS}")

    @property
    def n_classes(self) -> int:
        return len(self.class_names)

    @property
    def n_nodes(self) -> int:
        return sum(t.n_nodes for t in self.trees)

    @property
    def training_focal_px(self) -> float | None:
        """Focal length (px) of the camera the forest was trained on (``meta["training"]``), or None."""
        value = self.meta.get("training", {}).get("focal_px")
        return float(value) if value else None

    @property
    def training_width(self) -> int | None:
        """Image width of the training frames, or None when not recorded."""
        size = self.meta.get("training", {}).get("image_size")
        return int(size[0]) if size else None

    def for_focal(self, focal_px: float) -> tuple["Forest", float]:
        """This forest for a camera of focal length ``focal_px``: the test offsets (pixel*metres,
        eq. 3.3/3.6, proportional to f) scaled by ``focal_px / training_focal_px``; returns
        (forest, factor), ``self`` and 1 when the focal lengths match or none was recorded."""
        trained = self.training_focal_px
        if not trained:
            return self, 1.0
        s = float(focal_px) / trained
        if abs(s - 1.0) < 1e-6:
            return self, 1.0
        trees = [Tree((t.feature * np.float32(s)).astype(np.float32), t.threshold, t.left, t.right, t.counts,
                      t.depth) for t in self.trees]
        features = replace(self.features, patch_half_size_px_m=self.features.patch_half_size_px_m * s)
        meta = dict(self.meta)
        meta["training"] = dict(meta.get("training", {}), focal_px=float(focal_px))
        meta["rescaled_from_focal_px"] = trained
        return Forest(trees, self.class_names, features, self.kind, meta), s

    def flat(self) -> FlatForest:
        """Pack the trees for the kernels (call again after the trees change)."""
        if not self.trees:
            raise ValueError("forest has no trees")
        sizes = np.array([t.n_nodes for t in self.trees], np.int64)
        base = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        nodes = np.zeros((int(sizes.sum()), 8), np.float32)
        links = nodes.view(np.int32)
        for t, b in zip(self.trees, base):
            rows = slice(int(b), int(b) + t.n_nodes)
            nodes[rows, 0:4] = t.feature
            nodes[rows, 4] = t.threshold
            links[rows, 5] = np.where(t.left >= 0, t.left + b, -1)
            links[rows, 6] = np.where(t.right >= 0, t.right + b, -1)
        return FlatForest(
            nodes=nodes,
            proba=np.ascontiguousarray(np.concatenate([t.leaf_proba() for t in self.trees]), np.float32),
            roots=base.astype(np.int32),
            max_depth=max(t.max_depth for t in self.trees),
            clipped=self.features.clipped,
            kappa=float(self.features.kappa_m),
            background=float(self.features.background_depth_m),
            border=self.features.border,
        )

    def predict_proba(self, frames: np.ndarray, s_frame, s_x, s_y) -> np.ndarray:
        """Eq. 3.1: (S, C) mean of the leaf distributions over the trees at the sample pixels."""
        flat = self.flat()
        frames, s_frame, s_x, s_y = _sample_arrays(frames, s_frame, s_x, s_y)
        out = np.zeros((s_frame.shape[0], flat.n_classes), np.float32)
        _forest_proba(frames, s_frame, s_x, s_y, flat.nodes, flat.links, flat.proba, flat.roots,
                      flat.clipped, flat.kappa, flat.background, flat.border, out)
        return out


def _sample_arrays(frames, s_frame, s_x, s_y):
    frames = check_stack(frames)
    return (frames, np.ascontiguousarray(s_frame, np.int32), np.ascontiguousarray(s_x, np.int32),
            np.ascontiguousarray(s_y, np.int32))


@nb.njit(inline="always")
def descend(img, x, y, d, inv_d, node, feature, threshold, left, right, clipped, kappa, background, border):
    """Leaf reached from ``node`` by the pixel ``(x, y)`` of depth ``d``."""
    while left[node] >= 0:
        f = test_value(img, x, y, d, inv_d, feature[node, 0], feature[node, 1], feature[node, 2],
                       feature[node, 3], clipped, kappa, background, border)
        node = left[node] if f < threshold[node] else right[node]
    return node


@nb.njit(cache=True, nogil=True)
def _tree_leaves(frames, s_frame, s_x, s_y, feature, threshold, left, right, clipped, kappa, background, border,
                 out):
    kappa = np.float32(kappa)
    background = np.float32(background)
    for i in range(s_frame.shape[0]):
        img = frames[s_frame[i]]
        d = pixel_metres(img[s_y[i], s_x[i]], background)
        out[i] = descend(img, np.float64(s_x[i]), np.float64(s_y[i]), d, 1.0 / np.float64(d), 0,
                         feature, threshold, left, right, clipped, kappa, background, border)


@nb.njit(inline="always")
def descend_packed(img, x, y, d, inv_d, node, nodes, links, clipped, kappa, background, border):
    """:func:`descend` on a :class:`FlatForest`'s packed records."""
    while links[node, 5] >= 0:
        f = test_value(img, x, y, d, inv_d, nodes[node, 0], nodes[node, 1], nodes[node, 2],
                       nodes[node, 3], clipped, kappa, background, border)
        node = links[node, 5 + np.int32(f >= nodes[node, 4])]  # a load, not a branch
    return node


@nb.njit(cache=True, nogil=True)
def _forest_proba(frames, s_frame, s_x, s_y, nodes, links, proba, roots, clipped, kappa, background, border, out):
    kappa = np.float32(kappa)
    background = np.float32(background)
    n_classes = proba.shape[1]
    for i in range(s_frame.shape[0]):
        img = frames[s_frame[i]]
        d = pixel_metres(img[s_y[i], s_x[i]], background)
        x = np.float64(s_x[i])
        y = np.float64(s_y[i])
        inv_d = 1.0 / np.float64(d)
        for t in range(roots.shape[0]):
            leaf = descend_packed(img, x, y, d, inv_d, roots[t], nodes, links, clipped, kappa, background,
                                  border)
            for c in range(n_classes):
                out[i, c] += proba[leaf, c]
        for c in range(n_classes):
            out[i, c] /= roots.shape[0]


def apply_tree(tree: Tree, features: FeatureParams, frames: np.ndarray, s_frame, s_x, s_y) -> np.ndarray:
    """(S,) int32 index of the leaf of ``tree`` that each sample pixel reaches."""
    frames, s_frame, s_x, s_y = _sample_arrays(frames, s_frame, s_x, s_y)
    out = np.empty(s_frame.shape[0], np.int32)
    _tree_leaves(frames, s_frame, s_x, s_y, np.ascontiguousarray(tree.feature, np.float32),
                 np.ascontiguousarray(tree.threshold, np.float32), np.ascontiguousarray(tree.left, np.int32),
                 np.ascontiguousarray(tree.right, np.int32), features.clipped, features.kappa_m,
                 features.background_depth_m, features.border, out)
    return out
