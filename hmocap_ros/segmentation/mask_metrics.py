"""Pixel scores of a foreground mask against a ground-truth silhouette: precision, recall, F1, IoU.

Masks are boolean-like arrays (nonzero = foreground) of shape (..., H, W); leading axes
(frames, cameras) are kept, so a whole sequence is scored in one vectorised call, and mask and
truth broadcast against each other (several cameras' masks against one truth stack). An optional
``valid`` mask (broadcastable) excludes pixels from every count, e.g. a band around the true
silhouette's outline where the rendering is ambiguous.

Where a ratio is 0/0: all scores are 1.0 when there is nothing to find and nothing was found
(both masks empty), otherwise that ratio is 0.0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MaskScores", "mask_scores"]


@dataclass(frozen=True)
class MaskScores:
    """Counts (int64) and scores (float64), each of shape (...) = the masks' leading axes."""

    true_positives: np.ndarray
    false_positives: np.ndarray
    false_negatives: np.ndarray
    true_negatives: np.ndarray
    precision: np.ndarray
    recall: np.ndarray
    f1: np.ndarray
    iou: np.ndarray


def _ratio(num: np.ndarray, den: np.ndarray, both_empty: np.ndarray) -> np.ndarray:
    out = np.divide(num, den, out=np.zeros(np.shape(num), np.float64), where=den > 0)
    return np.where(both_empty, 1.0, out)


def mask_scores(mask: np.ndarray, truth: np.ndarray, valid: np.ndarray | None = None) -> MaskScores:
    """Score ``mask`` against ``truth`` (broadcastable shapes (..., H, W); nonzero = foreground).

    precision = TP / (TP + FP), recall = TP / (TP + FN), F1 = 2 TP / (2 TP + FP + FN),
    IoU = TP / (TP + FP + FN); pixels where ``valid`` is zero are not counted.
    """
    mask = np.asarray(mask)
    truth = np.asarray(truth)
    if mask.ndim < 2 or truth.ndim < 2:
        raise ValueError(f"masks must be (..., H, W), got shapes {mask.shape} and {truth.shape}")
    if mask.shape[-2:] != truth.shape[-2:]:
        raise ValueError(f"mask {mask.shape} and truth {truth.shape} differ in image size")
    try:
        shape = np.broadcast_shapes(mask.shape, truth.shape)
    except ValueError:
        raise ValueError(f"mask shape {mask.shape} and truth shape {truth.shape} do not broadcast") from None
    m = np.broadcast_to(mask.astype(bool, copy=False), shape)
    t = np.broadcast_to(truth.astype(bool, copy=False), shape)
    if valid is not None:
        v = np.broadcast_to(np.asarray(valid).astype(bool, copy=False), m.shape)
        m = m & v
        t = t & v
        n_valid = np.count_nonzero(v, axis=(-2, -1))
    else:
        n_valid = np.int64(m.shape[-2] * m.shape[-1])
    axes = (-2, -1)
    tp = np.count_nonzero(m & t, axis=axes).astype(np.int64)
    n_mask = np.count_nonzero(m, axis=axes).astype(np.int64)
    n_truth = np.count_nonzero(t, axis=axes).astype(np.int64)
    fp = n_mask - tp
    fn = n_truth - tp
    tn = (n_valid - tp - fp - fn).astype(np.int64)
    both_empty = (n_mask == 0) & (n_truth == 0)
    return MaskScores(
        true_positives=tp,
        false_positives=fp,
        false_negatives=fn,
        true_negatives=tn,
        precision=_ratio(tp, tp + fp, both_empty),
        recall=_ratio(tp, tp + fn, both_empty),
        f1=_ratio(2 * tp, 2 * tp + fp + fn, both_empty),
        iou=_ratio(tp, tp + fp + fn, both_empty),
    )
