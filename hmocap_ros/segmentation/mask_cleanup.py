"""Morphological clean-up of a raw foreground mask: opening, closing, small blobs, small holes.

Xu et al. [128] (the segmentation of thesis sec. 2.4) correct the errors of per-pixel
background subtraction and shadow removal with blob-level morphology; here that is an opening
(speckle), a closing (gaps along edges that shadow removal or camouflage cut), removal of
connected foreground components below an area and filling of enclosed background holes
below an area. Masks are uint8 0/255.

Component areas are counted with numba over the labels of ``cv2.connectedComponents``:
``cv2.connectedComponentsWithStats`` gives the same areas but also computes statistics
(bounding boxes, centroids) that cost far more than the labelling itself (docs/development.md,
"Costs the code is shaped by").
"""

from __future__ import annotations

import cv2
import numba as nb
import numpy as np

__all__ = ["clean_mask", "fill_small_holes", "remove_small_blobs", "structuring_element"]


@nb.njit(cache=True, nogil=True)
def component_areas(labels, n_labels):
    """Pixel count of every label ``0 .. n_labels - 1``."""
    areas = np.zeros(n_labels, np.int64)
    h, w = labels.shape
    for y in range(h):
        for x in range(w):
            areas[labels[y, x]] += 1
    return areas


@nb.njit(cache=True, nogil=True)
def _mark_border_labels(labels, flags):
    """``flags[l] = True`` for every label ``l`` that touches the image border."""
    h, w = labels.shape
    for x in range(w):
        flags[labels[0, x]] = True
        flags[labels[h - 1, x]] = True
    for y in range(h):
        flags[labels[y, 0]] = True
        flags[labels[y, w - 1]] = True


@nb.njit(cache=True, nogil=True)
def _keep_labels(labels, keep, mask):
    """``mask = 255`` where ``keep[label]``, else 0."""
    h, w = labels.shape
    for y in range(h):
        for x in range(w):
            mask[y, x] = 255 if keep[labels[y, x]] else 0


@nb.njit(cache=True, nogil=True)
def _fill_labels(labels, fill, mask):
    """``mask = 255`` where ``fill[label]``, elsewhere unchanged."""
    h, w = labels.shape
    for y in range(h):
        for x in range(w):
            if fill[labels[y, x]]:
                mask[y, x] = 255


def structuring_element(size: int) -> np.ndarray | None:
    """Elliptic ``size`` x ``size`` structuring element, or None when ``size`` <= 1 (no-op)."""
    if size <= 1:
        return None
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))


def remove_small_blobs(mask: np.ndarray, min_area: int) -> np.ndarray:
    """Drop 8-connected foreground components with fewer than ``min_area`` pixels (in place)."""
    if min_area <= 1:
        return mask
    n, labels = cv2.connectedComponents(mask, connectivity=8, ltype=cv2.CV_32S)
    if n <= 1:
        return mask
    keep = component_areas(labels, n) >= min_area
    keep[0] = False
    if not keep[1:].all():
        _keep_labels(labels, keep, mask)
    return mask


def fill_small_holes(mask: np.ndarray, max_area: int) -> np.ndarray:
    """Fill 4-connected background regions of at most ``max_area`` pixels that do not touch the
    image border (holes enclosed by foreground), in place."""
    if max_area <= 0:
        return mask
    n, labels = cv2.connectedComponents(cv2.bitwise_not(mask), connectivity=4, ltype=cv2.CV_32S)
    if n <= 2:  # label 0 is the foreground; a single background region touches the border
        return mask
    fill = component_areas(labels, n) <= max_area
    border = np.zeros(n, np.bool_)
    _mark_border_labels(labels, border)
    fill &= ~border
    fill[0] = False
    if fill.any():
        _fill_labels(labels, fill, mask)
    return mask


def clean_mask(raw: np.ndarray, opening: np.ndarray | None, closing: np.ndarray | None,
               min_blob_area: int, max_hole_area: int) -> np.ndarray:
    """Opening, closing, removal of blobs under ``min_blob_area`` pixels, then filling of the
    remaining blobs' holes up to ``max_hole_area`` pixels. ``opening``/``closing`` are
    structuring elements (see :func:`structuring_element`) or None to skip. Returns a new
    array; ``raw`` is unchanged.
    """
    mask = raw
    if opening is not None:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, opening)
    if closing is not None:
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, closing)
    if mask is raw:
        mask = raw.copy()
    remove_small_blobs(mask, min_blob_area)
    fill_small_holes(mask, max_hole_area)
    return mask
