"""Forest votes on a pixel grid of one depth frame (thesis sec. 3.2.4, step 1; eq. 3.1).

The forest is evaluated on every ``stride``-th pixel of every ``stride``-th row whose depth is
valid; a grid pixel votes for gesture class ``c > 0`` when ``p(c | I_t, x)`` (eq. 3.1, the mean
of the trees' leaf distributions) beats background and every other class (ties go to
background). The image gets a 1-pixel frame (:func:`pad_for_forest`) that holds what a test
reads outside the image, so the kernel clamps probes instead of testing bounds.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from hmocap_ros.gestures.trees import FlatForest

__all__ = ["forest_grid_proba", "forest_grid_votes", "grid_shape", "pad_for_forest"]


#: Pixels walked down a tree together (interleaved): their independent memory fetches overlap
#: instead of each tree walk waiting on one node fetch at a time.
_BATCH = 8


@nb.njit(inline="always")
def _probe_padded(img, x, y, ox, oy, inv_d):
    """``probe`` on an image with a 1-pixel frame (:func:`pad_for_forest`): the clamp to the frame
    replaces the bounds test (same rounding as ``probe_index``)."""
    px = int(min(max(x + ox * inv_d + 0.5, -1.0), img.shape[1] - 1.5) + 1.0)
    py = int(min(max(y + oy * inv_d + 0.5, -1.0), img.shape[0] - 1.5) + 1.0)
    return img[py, px]


@nb.njit(inline="always")
def _valid_grid_pixels(padded, stride, offset, background, class_map, grid_depth, px, py):
    """Fill ``grid_depth`` and mark ``class_map`` 0 (valid depth) or -1 at each grid cell; the
    valid cells' pixel coordinates go to ``px``, ``py``. Returns their number."""
    gh, gw = class_map.shape
    n = 0
    for gy in range(gh):
        y = offset + gy * stride
        for gx in range(gw):
            x = offset + gx * stride
            d = padded[y + 1, x + 1]
            grid_depth[gy, gx] = d
            if d < background:
                px[n] = x
                py[n] = y
                class_map[gy, gx] = 0
                n += 1
            else:
                class_map[gy, gx] = -1
    return n


@nb.njit(inline="always")
def _add_tree_votes(padded, px, py, active, n_active, root, nodes, links, proba, max_depth, clipped, kappa, acc):
    """Add one tree's leaf distribution to ``acc`` for the ``active`` pixels, ``_BATCH`` pixels
    walked down together."""
    n_classes = proba.shape[1]
    node = np.empty(_BATCH, np.int32)
    lo = np.empty(_BATCH, np.float32)
    hi = np.empty(_BATCH, np.float32)
    inv_d = np.empty(_BATCH, np.float64)
    fx = np.empty(_BATCH, np.float64)
    fy = np.empty(_BATCH, np.float64)
    for p0 in range(0, n_active, _BATCH):
        nb_ = min(_BATCH, n_active - p0)
        for k in range(nb_):
            p = active[p0 + k]
            d = padded[py[p] + 1, px[p] + 1]
            node[k] = root
            # Plain tests clip to +-inf, which leaves the probe as it is (eq. 3.3).
            lo[k] = d - kappa if clipped else np.float32(-np.inf)
            hi[k] = d + kappa if clipped else np.float32(np.inf)
            inv_d[k] = 1.0 / np.float64(d)
            fx[k] = px[p]
            fy[k] = py[p]
        for _ in range(max_depth):
            moving = 0
            for k in range(nb_):
                nd = node[k]
                left = links[nd, 5]
                if left >= 0:
                    a = _probe_padded(padded, fx[k], fy[k], nodes[nd, 0], nodes[nd, 1], inv_d[k])
                    b = _probe_padded(padded, fx[k], fy[k], nodes[nd, 2], nodes[nd, 3], inv_d[k])
                    a = max(min(a, hi[k]), lo[k])
                    b = max(min(b, hi[k]), lo[k])
                    # Children sit in adjacent columns: indexing by the test result is a
                    # load, not an (unpredictable, pipeline-flushing) branch.
                    node[k] = links[nd, 5 + np.int32(a - b >= nodes[nd, 4])]
                    moving += 1
            if moving == 0:
                break
        for k in range(nb_):
            p = active[p0 + k]
            for c in range(n_classes):
                acc[p, c] += proba[node[k], c]


@nb.njit(inline="always")
def _undecided(acc, active, n_active, reach):
    """Keep in ``active`` (compacted in place) the pixels whose background sum does not lead
    every gesture class by more than ``reach`` (what the remaining trees are taken to be able
    to give a gesture over background); returns their number."""
    n_classes = acc.shape[1]
    m = 0
    for i in range(n_active):
        p = active[i]
        best = acc[p, 1]
        for c in range(2, n_classes):
            best = max(best, acc[p, c])
        if acc[p, 0] - best <= reach + np.float32(1e-3):  # margin for rounding
            active[m] = p
            m += 1
    return m


@nb.njit(cache=True, nogil=True)
def _grid_votes(padded, stride, offset, nodes, links, proba, roots, max_depth, clipped, kappa, background,
                vote_reach, class_map, grid_depth, proba_out):
    """Forest votes on the stride grid of ``padded`` (the metres image with a 1-pixel frame).

    Trees outer, pixels inner (one tree's records stay in cache while the grid walks it),
    ``_BATCH`` pixels interleaved. With ``vote_reach`` > 0, after each tree a pixel whose
    background sum leads every gesture class by more than ``vote_reach`` times the number of
    trees left is dropped: it votes background (:func:`forest_grid_votes`). ``proba_out``
    (gh, gw, C), unless empty, receives eq. 3.1 at every grid pixel (complete only with
    ``vote_reach`` 0, which drops nothing).
    """
    gh, gw = class_map.shape
    n_classes = proba.shape[1]
    n_trees = roots.shape[0]
    kappa = np.float32(kappa)
    background = np.float32(background)
    px = np.empty(gh * gw, np.int32)
    py = np.empty(gh * gw, np.int32)
    n = _valid_grid_pixels(padded, stride, offset, background, class_map, grid_depth, px, py)
    acc = np.zeros((n, n_classes), np.float32)
    active = np.arange(n)
    n_active = n
    for t in range(n_trees):
        _add_tree_votes(padded, px, py, active, n_active, roots[t], nodes, links, proba, max_depth, clipped,
                        kappa, acc)
        remaining = np.float32(n_trees - t - 1)
        if vote_reach > 0.0:
            n_active = _undecided(acc, active, n_active, np.float32(vote_reach) * remaining)
    for p in range(n):
        best = 0
        for c in range(1, n_classes):
            if acc[p, c] > acc[p, best]:
                best = c
        class_map[(py[p] - offset) // stride, (px[p] - offset) // stride] = best
    if proba_out.shape[0] > 0:
        proba_out[:, :, :] = 0.0
        for p in range(n):
            for c in range(n_classes):
                proba_out[(py[p] - offset) // stride, (px[p] - offset) // stride, c] = acc[p, c] / n_trees


def grid_shape(height: int, width: int, stride: int) -> tuple[int, int, int]:
    """(rows, columns, offset) of the evaluation grid: pixels ``offset + k * stride``."""
    offset = stride // 2
    return (height - offset + stride - 1) // stride, (width - offset + stride - 1) // stride, offset


def pad_for_forest(depth_m: np.ndarray, flat: FlatForest, out: np.ndarray | None = None) -> np.ndarray:
    """``depth_m`` (a ``depth_to_metres`` image) with the 1-pixel frame that
    :func:`forest_grid_votes` takes: what the forest's tests read outside the image
    (``FeatureParams.outside``): a copy of the image's edge pixels, or the background depth."""
    background, border = flat.background, flat.border
    h, w = depth_m.shape
    if out is None or out.shape != (h + 2, w + 2):
        out = np.empty((h + 2, w + 2), np.float32)
    out[1:-1, 1:-1] = depth_m
    if border:
        out[0, 1:-1], out[-1, 1:-1] = depth_m[0], depth_m[-1]
        out[:, 0], out[:, -1] = out[:, 1], out[:, -2]
    else:
        out[0, :] = out[-1, :] = out[:, 0] = out[:, -1] = np.float32(background)
    return out


def forest_grid_votes(flat: FlatForest, padded: np.ndarray, stride: int,
                      vote_reach: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel forest votes (sec. 3.2.4) on the stride grid of a metres image.

    ``padded``: a ``depth_to_metres`` image with the 1-pixel frame of :func:`pad_for_forest`.
    Returns ``class_map`` (gh, gw) int8: -1 invalid depth, 0 background, ``c`` a vote for class
    ``c``; and ``grid_depth`` (gh, gw) float32.

    ``vote_reach`` in (0, 1]: after each tree, a pixel whose background sum leads every gesture
    class by more than ``vote_reach`` x the trees left is decided (background) and walks no
    further tree. With 1 (a tree gives a class at most 1) it is exact: such a pixel can only
    vote background. Below 1 it is a bound on what the trees left are taken to give a gesture
    over background: background pixels of a trained forest stop after a few trees (most of the
    grid is wall and floor), at the risk of dropping a pixel the last trees would have turned.
    """
    if not 0.0 < vote_reach <= 1.0:
        raise ValueError(f"vote_reach must be in (0, 1], got {vote_reach}")
    padded = np.ascontiguousarray(padded, dtype=np.float32)
    gh, gw, offset = grid_shape(padded.shape[0] - 2, padded.shape[1] - 2, stride)
    class_map = np.empty((gh, gw), np.int8)
    grid_depth = np.empty((gh, gw), np.float32)
    _grid_votes(padded, stride, offset, flat.nodes, flat.links, flat.proba, flat.roots, flat.max_depth,
                flat.clipped, flat.kappa, flat.background, float(vote_reach), class_map, grid_depth,
                np.zeros((0, 0, flat.n_classes), np.float32))
    return class_map, grid_depth


def forest_grid_proba(flat: FlatForest, padded: np.ndarray, stride: int) -> np.ndarray:
    """Eq. 3.1 on the stride grid: (gh, gw, C) mean leaf distributions, zeros at invalid pixels.

    Slower than :func:`forest_grid_votes` (no pixel is decided early); for the on-the-fly
    hard negative mining of the online trainer (sec. 3.3.2) and for inspection.
    """
    padded = np.ascontiguousarray(padded, dtype=np.float32)
    gh, gw, offset = grid_shape(padded.shape[0] - 2, padded.shape[1] - 2, stride)
    out = np.empty((gh, gw, flat.n_classes), np.float32)
    _grid_votes(padded, stride, offset, flat.nodes, flat.links, flat.proba, flat.roots, flat.max_depth,
                flat.clipped, flat.kappa, flat.background, 0.0, np.empty((gh, gw), np.int8),
                np.empty((gh, gw), np.float32), out)
    return out
