"""Gesture localization with a forest on whole depth frames (thesis sec. 3.2.4).

Per frame ``I_t`` (:meth:`GestureDetector.update`):

1. The forest is evaluated on a grid of every ``stride``-th pixel with valid depth; a grid
   pixel votes for gesture class ``c > 0`` when ``p(c | I_t, x)`` (eq. 3.1) beats background and
   every other class (ties go to background) (:mod:`~hmocap_ros.gestures.grid_votes`). A pixel
   whose background lead after some trees is more than ``vote_reach`` x the trees left stops
   there and votes background (a design choice for speed, not in the thesis: most of the grid
   is wall and floor, decided by the first trees).
2. The vote image of each class is turned into a density ``p(c | I_t)`` by a Parzen estimator
   with a Gaussian kernel (``parzen_sigma_px``): the blurred 0/1 vote image, i.e. the kernel-
   weighted fraction of grid pixels around ``x`` that vote for ``c`` (a pseudo-probability in
   [0, 1], independent of the stride).
3. Temporal smoothing (eq. 3.4): ``p'(c | I_t) = alpha p(c | I_t) + (1 - alpha) p'(c | I_{t-1})``,
   one map per class kept across frames; the state starts at zero (so a gesture must be
   seen on more than one frame to reach full strength) and restarts when the image size
   changes, the stamps go back in time or jump by more than ``max_gap_s``.
4. The location ``g_c`` is the maximum of ``p'``, refined to sub-grid precision (the centre of
   its plateau when a flat vote region makes several cells equal, else the centroid of its 3x3
   neighbourhood); its depth is the median depth of the grid pixels around it that voted for ``c``.
5. Volume test (eq. 3.5): ``V = sum_{x in S} p'(c | I_t(x))`` over the disk ``S`` centred at
   ``g_c`` of radius ``volume_radius_px_m / depth`` pixels (shrinking with depth, so the test
   covers the same part of the body at any distance). ``volume`` is ``V / |S|``, the mean
   density over the disk, in [0, 1] and depth-invariant; ``score`` is ``p'(g_c)``. A class is
   detected when ``score >= min_score`` and ``volume >= min_volume``.
6. One place shows one gesture: a detection within ``suppression_radius_px_m / depth`` pixels
   of a higher-scoring detection of another class is dropped (not in the thesis, whose votes
   are already exclusive per pixel; here the spill-over of near-miss shapes is suppressed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from hmocap_ros.gestures.depth_features import depth_to_metres
from hmocap_ros.gestures.grid_votes import forest_grid_votes, pad_for_forest
from hmocap_ros.gestures.params import DetectorParams
from hmocap_ros.gestures.trees import Forest

__all__ = ["Detection", "GestureDetector", "gesture_thresholds", "node_detections", "parzen_density", "refine_maximum",
           "smooth_density", "suppress_other_classes"]


@dataclass(frozen=True)
class Detection:
    """One localized gesture: class, pixel (column u, row v), depth [m], score and volume (sec. 3.2.4)."""

    class_id: int
    name: str
    u: float
    v: float
    depth_m: float
    score: float
    volume: float
    stamp_ns: int


def parzen_density(votes: np.ndarray, sigma_cells: float) -> np.ndarray:
    """Gaussian Parzen estimate of (gh, gw, K) 0/1 vote images, zero outside the image."""
    if sigma_cells <= 0 or votes.size == 0:
        return votes.copy()
    k = int(2 * np.ceil(3 * sigma_cells) + 1)
    kernel = cv2.getGaussianKernel(k, sigma_cells).astype(np.float32)
    out = np.empty_like(votes)
    for c in range(votes.shape[2]):  # per channel: OpenCV filters at most 4 channels at once
        out[:, :, c] = cv2.sepFilter2D(votes[:, :, c], -1, kernel, kernel, borderType=cv2.BORDER_CONSTANT)
    return out


def smooth_density(previous: np.ndarray | None, current: np.ndarray, alpha: float) -> np.ndarray:
    """Eq. 3.4: ``alpha * current + (1 - alpha) * previous`` (``previous`` None = zeros)."""
    if previous is None:
        return np.float32(alpha) * current
    return np.float32(alpha) * current + np.float32(1.0 - alpha) * previous


def _window(shape, gy: int, gx: int, reach: int) -> tuple[int, int, int, int]:
    """Row and column bounds of the (2 reach + 1)^2 window at ``(gy, gx)``, clipped to ``shape``."""
    return max(gy - reach, 0), min(gy + reach + 1, shape[0]), max(gx - reach, 0), min(gx + reach + 1, shape[1])


def refine_maximum(dens: np.ndarray, gy: int, gx: int, reach: int) -> tuple[float, float]:
    """Sub-cell location of the maximum at ``(gy, gx)``: the centre of its plateau (cells within
    ``reach`` equal to the maximum, as a flat vote region blurred by a truncated kernel gives),
    else the density-weighted centroid of its 3x3 neighbourhood."""
    top = dens[gy, gx]
    y0, y1, x0, x1 = _window(dens.shape, gy, gx, reach)
    plateau = dens[y0:y1, x0:x1] >= top - np.float32(1e-6) * max(float(top), 1.0)
    if np.count_nonzero(plateau) > 1:
        ys, xs = np.nonzero(plateau)
        return float(ys.mean() + y0), float(xs.mean() + x0)
    y0, y1, x0, x1 = _window(dens.shape, gy, gx, 1)
    w = dens[y0:y1, x0:x1].astype(np.float64)
    ys, xs = np.mgrid[y0:y1, x0:x1]
    return float((w * ys).sum() / w.sum()), float((w * xs).sum() / w.sum())


def gesture_thresholds(params: DetectorParams, taught: dict | None = None) -> dict:
    """(score, volume) thresholds per gesture name: ``min_score`` and ``min_volume``, or for a
    gesture with a taught threshold ``th`` (sec. 3.4.1) ``th`` and ``th x min_volume / min_score``:
    the volume test (eq. 3.5) keeps its ratio to the score test, so a taught forest, whose votes
    cover less of the gesture than the shipped forest's, is held to the same shape of maximum."""
    ratio = params.min_volume / params.min_score if params.min_score > 0 else 0.0
    return {str(name): (float(th), float(th) * ratio) for name, th in (taught or {}).items()}


def node_detections(candidates: list, params: DetectorParams, thresholds: dict | None = None) -> list:
    """What the ``gesture_detection`` node reports from a frame's candidates (one localized
    maximum per class, :attr:`GestureDetector.candidates`, found at lower thresholds): those
    above the lowest thresholds in use, one per place (:func:`suppress_other_classes`, ``params``
    scaled to the camera), then each gesture at its own thresholds (:func:`gesture_thresholds`:
    a taught one from ``thresholds[name]``, else ``min_score`` and ``min_volume``)."""
    own = gesture_thresholds(params, thresholds)
    default = (params.min_score, params.min_volume)
    floor_score = min([default[0]] + [t[0] for t in own.values()])
    floor_volume = min([default[1]] + [t[1] for t in own.values()])
    kept = suppress_other_classes([d for d in candidates if d.score >= floor_score and d.volume >= floor_volume],
                                  params.suppression_radius_px_m)
    return [d for d in kept if d.score >= own.get(d.name, default)[0] and d.volume >= own.get(d.name, default)[1]]


def suppress_other_classes(detections: list, radius_px_m: float) -> list:
    """Best score first; drops a detection within ``radius_px_m / depth`` pixels of a better one
    of another class (the votes of one hand shape spill over to similar classes nearby)."""
    kept: list = []
    for det in sorted(detections, key=lambda d: -d.score):
        if all(math.hypot(det.u - k.u, det.v - k.v) >= radius_px_m / k.depth_m for k in kept):
            kept.append(det)
    return kept


class GestureDetector:
    """Gesture localization on a stream of depth frames of one camera (thesis sec. 3.2.4).

    ``update(depth, stamp_ns)`` takes a raw depth image (unit and invalid value per
    ``params``) and returns the detections of that frame (``candidates``: the same before the
    suppression of step 6, for :func:`node_detections`); between calls it keeps the
    temporally smoothed densities (eq. 3.4). ``density`` (gh, gw, C-1) is that state and
    :meth:`probability_image` the full-resolution debug map.

    Camera: the forest's tests are pixel*metre offsets for the focal length it was trained at,
    and the pixel sizes of ``params`` are for ``params.reference_focal_px``; both are rescaled
    to the camera's focal length ``focal_px`` (:meth:`set_focal`, e.g. from CameraInfo). While
    it is unknown (None) the camera is taken to be the training camera at this image width
    (focal scaled by width / training width). ``active_params`` are the scaled parameters in use.
    """

    forest: Forest

    def __init__(self, forest: Forest, params: DetectorParams | None = None, focal_px: float | None = None):
        self.params = params if params is not None else DetectorParams()
        self.focal_px = None if focal_px is None else float(focal_px)
        self.active_params = self.params
        self.offset_scale = 1.0
        self._configured: tuple | None = None
        self.set_forest(forest)

    def set_forest(self, forest: Forest) -> None:
        """Use ``forest`` from the next frame on (an online forest that grew); keeps the state
        when the classes are the same."""
        if self.params.max_depth_m >= forest.features.background_depth_m:
            raise ValueError("DetectorParams.max_depth_m must be below the forest's background_depth_m")
        if forest.n_classes > 127:
            raise ValueError("at most 127 classes (the vote map is int8)")
        same = hasattr(self, "forest") and self.forest.class_names == forest.class_names
        self.forest = forest
        self._configured = None
        if not same:
            self.reset()

    def set_focal(self, focal_px: float | None) -> None:
        """The camera's focal length in pixels (fx of its CameraInfo), None = unknown."""
        if focal_px is not None and not (np.isfinite(focal_px) and focal_px > 0):
            raise ValueError(f"focal length must be a positive number, got {focal_px}")
        self.focal_px = None if focal_px is None else float(focal_px)

    def camera_focal(self, width: int) -> float | None:
        """The focal length used for an image ``width`` pixels wide (see the class docstring)."""
        if self.focal_px is not None:
            return self.focal_px
        trained, trained_width = self.forest.training_focal_px, self.forest.training_width
        if trained and trained_width:
            return trained * width / trained_width
        return trained

    def _configure(self, width: int) -> None:
        focal = self.camera_focal(width)
        key = (focal, id(self.forest))
        if self._configured == key:
            return
        scaled, self.offset_scale = self.forest.for_focal(focal) if focal is not None else (self.forest, 1.0)
        self.active_params = self.params.for_focal(focal)
        self._flat = scaled.flat()
        if self._configured is not None and self._configured[0] != focal:
            self.reset()  # another camera: the old densities mean nothing here
        self._configured = key

    def reset(self) -> None:
        """Forget the temporal state (eq. 3.4 restarts from zero)."""
        self.density: np.ndarray | None = None
        self.class_map: np.ndarray | None = None
        self.grid_depth: np.ndarray | None = None
        self._shape: tuple | None = None
        self._last_stamp: int | None = None
        self._padded: np.ndarray | None = None
        self.candidates: list = []

    @property
    def grid_offset(self) -> int:
        return self.active_params.stride // 2

    def update(self, depth: np.ndarray, stamp_ns: int) -> list[Detection]:
        """Detections in one depth frame (raw units, see ``DetectorParams``), best score first."""
        stamp_ns = int(stamp_ns)
        background = self.forest.features.background_depth_m
        depth_m = depth_to_metres(depth, self.params.depth_format, background)
        self._configure(depth_m.shape[1])
        p = self.active_params
        if (self._shape != depth_m.shape or self._last_stamp is None or stamp_ns < self._last_stamp
                or stamp_ns - self._last_stamp > p.max_gap_s * 1e9):
            self.density = None
        self._shape = depth_m.shape
        self._last_stamp = stamp_ns

        self._padded = pad_for_forest(depth_m, self._flat, self._padded)
        self.class_map, self.grid_depth = forest_grid_votes(self._flat, self._padded, p.stride, p.vote_reach)
        n_gestures = self.forest.n_classes - 1
        votes = (self.class_map[:, :, None] == np.arange(1, n_gestures + 1, dtype=np.int8)).astype(np.float32)
        current = parzen_density(votes, p.parzen_sigma_px / p.stride)
        self.density = smooth_density(self.density, current, p.alpha)
        self.candidates = []
        if self.density.size == 0:  # an image smaller than the grid offset
            return []

        detections = []
        for k in range(n_gestures):
            det = self._localize(k + 1, stamp_ns)
            if det is not None:
                detections.append(det)
        self.candidates = detections
        return suppress_other_classes(detections, p.suppression_radius_px_m)

    def _localize(self, class_id: int, stamp_ns: int) -> Detection | None:
        p = self.active_params
        assert self.density is not None  # update() has just computed it
        dens = self.density[:, :, class_id - 1]
        flat_max = int(np.argmax(dens))
        gy, gx = divmod(flat_max, dens.shape[1])
        score = float(dens[gy, gx])
        if score <= 0.0 or score < p.min_score:
            return None
        depth_m = self._depth_at(class_id, gy, gx)
        if depth_m is None:
            return None
        r = p.volume_radius_px_m / depth_m / p.stride  # disk radius in grid cells
        cy, cx = refine_maximum(dens, gy, gx, max(1, int(np.ceil(r))))
        # Eq. 3.5 over the disk of radius volume_radius / depth pixels (at least the centre cell).
        gy, gx = int(round(cy)), int(round(cx))
        y0, y1, x0, x1 = _window(dens.shape, gy, gx, int(np.floor(r)))
        ys, xs = np.ogrid[y0:y1, x0:x1]
        disk = (ys - gy) ** 2 + (xs - gx) ** 2 <= r * r
        volume = float(dens[y0:y1, x0:x1][disk].mean())
        if volume < p.min_volume:
            return None
        off, s = self.grid_offset, p.stride
        return Detection(class_id, self.forest.class_names[class_id], off + cx * s, off + cy * s, depth_m,
                         score, volume, stamp_ns)

    def _depth_at(self, class_id: int, gy: int, gx: int) -> float | None:
        """Median depth of the grid pixels within 2 cells of the maximum that voted for the class,
        else of the valid ones; None when there are none."""
        y0, y1, x0, x1 = max(gy - 2, 0), gy + 3, max(gx - 2, 0), gx + 3
        assert self.class_map is not None and self.grid_depth is not None  # update() has just voted
        cls = self.class_map[y0:y1, x0:x1]
        dep = self.grid_depth[y0:y1, x0:x1]
        for sel in (cls == class_id, cls >= 0):
            if np.any(sel):
                return float(np.median(dep[sel]))
        return None

    def probability_image(self, class_id: int | None = None) -> np.ndarray:
        """Debug map (H, W) float32 in [0, 1]: the smoothed density p' of ``class_id`` (default:
        the maximum over the gesture classes) resampled to the image size; zeros before any frame."""
        if self.density is None or self._shape is None:
            return np.zeros(self._shape or (1, 1), np.float32)
        dens = self.density.max(axis=2) if class_id is None else self.density[:, :, class_id - 1]
        s, h, w = self.active_params.stride, *self._shape
        big = cv2.resize(dens, (dens.shape[1] * s, dens.shape[0] * s), interpolation=cv2.INTER_LINEAR)
        out = np.zeros((h, w), np.float32)
        out[: min(h, big.shape[0]), : min(w, big.shape[1])] = big[:h, :w]
        return out
