"""Negatives of background frames for online training: hard negative mining by on-the-fly
detection (thesis sec. 3.3.2), or random negatives of the same count.

For a background (negative) training frame ``I_neg`` and the forest as it stands:

1. ``p(c|x)`` of every pixel of a ``stride`` grid from the current leaves (eq. 3.1), and the
   votes of the detector (sec. 3.2.4: a pixel votes for the class that beats background and
   every other class) (:func:`~hmocap_ros.gestures.grid_votes.forest_grid_votes`);
2. the Parzen density of each class's votes (Gaussian kernel, the detector's
   :func:`~hmocap_ros.gestures.detection.parzen_density`), its maximum ``m_c`` and the value
   there, ``max p`` (in [0, 1]);
3. ``round(N_neg * max p)`` negatives drawn without replacement among the valid pixels of the
   square of half side ``hard_half_size_px_m / d`` pixels centred on ``m_c`` (``d`` the depth
   at ``m_c``): the worse the forest fails on the frame, the more of the samples that make it
   fail it learns from (:func:`hard_negative_pixels`).

``random`` mode draws the same number of negatives (the same rule for the count) uniformly
among the frame's valid pixels, so a comparison of the two modes differs only in where the
negatives come from.

Design choices (the thesis trains class-specific forests): with one multi-class forest the
rule runs per gesture class, each with its own maximum and count; the density is the frame's
own (no temporal smoothing, eq. 3.4: training frames are taken in random order); the depth at
``m_c`` is the median depth of the valid grid pixels within 2 cells of it.
"""

from __future__ import annotations

import numpy as np

from hmocap_ros.gestures.detection import parzen_density
from hmocap_ros.gestures.grid_votes import forest_grid_votes, grid_shape, pad_for_forest
from hmocap_ros.gestures.params import OnlineParams
from hmocap_ros.gestures.trees import FlatForest

__all__ = ["frame_negatives", "hard_negative_pixels", "negative_counts", "random_negative_pixels",
           "vote_density"]


def vote_density(class_map: np.ndarray, n_gestures: int, sigma_cells: float) -> np.ndarray:
    """(gh, gw, G) Parzen density of the votes of a ``forest_grid_votes`` class map (step 2)."""
    votes = (class_map[:, :, None] == np.arange(1, n_gestures + 1, dtype=class_map.dtype)).astype(np.float32)
    return parzen_density(votes, sigma_cells)


def negative_counts(density: np.ndarray, n_frame_negatives: int) -> np.ndarray:
    """(G,) int: ``round(N_neg * max p_c)`` per gesture class (step 3)."""
    if density.size == 0:
        return np.zeros(density.shape[-1], np.int64)
    maxp = density.reshape(-1, density.shape[-1]).max(0)
    return np.rint(n_frame_negatives * np.clip(maxp, 0.0, 1.0)).astype(np.int64)


def _depth_at(grid_depth: np.ndarray, gy: int, gx: int, background: float) -> float | None:
    win = grid_depth[max(gy - 2, 0):gy + 3, max(gx - 2, 0):gx + 3]
    valid = win[win < background]
    return float(np.median(valid)) if valid.size else None


def hard_negative_pixels(density: np.ndarray, grid_depth: np.ndarray, depth_m: np.ndarray, stride: int,
                         counts: np.ndarray, half_size_px_m: float, background: float,
                         rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Columns and rows of the hard negatives (step 3): ``counts[c]`` valid pixels of
    ``depth_m`` (metres, invalid = ``background``) drawn without replacement (fewer when the
    square has fewer) in the square of half side ``half_size_px_m / d`` around the maximum of
    ``density[..., c]``; ``grid_depth`` (gh, gw) the depth at the grid pixels."""
    h, w = depth_m.shape
    _, _, offset = grid_shape(h, w, stride)
    xs, ys = [], []
    for c in np.flatnonzero(counts > 0):
        gy, gx = np.unravel_index(int(np.argmax(density[:, :, c])), density.shape[:2])
        d = _depth_at(grid_depth, int(gy), int(gx), background)
        if d is None:
            continue
        u, v = offset + int(gx) * stride, offset + int(gy) * stride
        half = int(round(half_size_px_m / d))
        y0, y1, x0, x1 = max(v - half, 0), min(v + half + 1, h), max(u - half, 0), min(u + half + 1, w)
        wy, wx = np.nonzero(depth_m[y0:y1, x0:x1] < np.float32(background))
        if wy.size == 0:
            continue
        pick = rng.choice(wy.size, size=min(int(counts[c]), wy.size), replace=False)
        xs.append(wx[pick] + x0)
        ys.append(wy[pick] + y0)
    if not xs:
        return np.zeros(0, np.int32), np.zeros(0, np.int32)
    return np.concatenate(xs).astype(np.int32), np.concatenate(ys).astype(np.int32)


def random_negative_pixels(depth_m: np.ndarray, n: int, background: float,
                           rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Columns and rows of ``n`` valid pixels of ``depth_m`` drawn uniformly without replacement."""
    valid = np.flatnonzero(depth_m.ravel() < np.float32(background))
    pick = valid[rng.choice(valid.size, size=min(int(n), valid.size), replace=False)] if valid.size else valid
    return (pick % depth_m.shape[1]).astype(np.int32), (pick // depth_m.shape[1]).astype(np.int32)


def frame_negatives(flat: FlatForest, depth_m: np.ndarray, params: OnlineParams,
                    rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Negatives of one background frame (``depth_m`` float32 metres, invalid = the forest's
    background depth) for the forest ``flat`` as it stands: (columns, rows, per-class counts),
    hard or random per ``params.negatives`` (module docstring)."""
    padded = pad_for_forest(depth_m, flat)
    class_map, grid_depth = forest_grid_votes(flat, padded, params.stride)
    density = vote_density(class_map, flat.n_classes - 1, params.parzen_sigma_px / params.stride)
    counts = negative_counts(density, params.n_frame_negatives)
    if params.negatives == "hard":
        xs, ys = hard_negative_pixels(density, grid_depth, depth_m, params.stride, counts,
                                      params.hard_half_size_px_m, flat.background, rng)
    else:
        xs, ys = random_negative_pixels(depth_m, int(counts.sum()), flat.background, rng)
    return xs, ys, counts
