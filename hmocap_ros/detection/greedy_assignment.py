"""Detections assigned to targets by the thesis' greedy rule (eq. 2.19, sec. 2.5).

Used twice: the ``skin`` extremity detector labels its unlabelled surface clusters against the
last skeleton's hands and head (:mod:`.extremity_pipeline`), and the tracker assigns a frame
set's detections to its predicted end-effectors
(:mod:`hmocap_ros.tracking.detection_assignment`).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["classify", "greedy_pairs"]


def greedy_pairs(d: np.ndarray) -> list[tuple[int, int]]:
    """The thesis' greedy solution of an assignment (eq. 2.19): repeatedly the closest finite
    (row, column) pair of ``d`` (modified), each row and column used once."""
    pairs = []
    while np.isfinite(d).any():
        i, e = np.unravel_index(np.argmin(d), d.shape)
        pairs.append((int(i), int(e)))
        d[i, :] = np.inf
        d[:, e] = np.inf
    return pairs


def classify(candidates: np.ndarray, targets: np.ndarray,
             max_distance: Sequence[float] | np.ndarray) -> np.ndarray:
    """Eq. 2.19 by the thesis' greedy rule: (I, 3) assigned candidate per target (NaN: none).

    Repeatedly assigns the closest (target, candidate) pair whose distance is within the
    target's maximum ``Upsilon_i``; each candidate and target is used once.
    """
    targets = np.asarray(targets, dtype=np.float64)
    out = np.full(targets.shape, np.nan)
    if len(candidates) == 0:
        return out
    d = np.linalg.norm(targets[:, None] - candidates[None], axis=2)
    d[d > np.asarray(max_distance, dtype=np.float64)[:, None]] = np.inf
    d[~np.isfinite(targets).all(axis=1)] = np.inf
    for i, e in greedy_pairs(d):
        out[i] = candidates[e]
    return out
