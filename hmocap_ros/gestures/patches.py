"""Patch (training sample) collection from annotated depth frames (thesis sec. 3.2.3, "Patch collection").

A sample is a reference pixel of a frame with a class label; its "patch" is whatever the tests
probe around it, so only the frame stack and pixel indices are stored, never pixel copies.

Per gesture frame (label ``(c, u, v)``, ``c > 0``): up to ``N+`` positives of class ``c`` drawn
without replacement in the box of half side ``box_half_size_px_m / d`` pixels centred on the
annotated point (``d`` its depth), keeping only box pixels within ``positive_depth_tolerance_m``
of ``d`` (the background visible through the box is not the gesture), and ``N-`` negatives
(class 0) drawn from the valid pixels outside the box. Per negative frame (``c = 0``): ``N-``
negatives from all valid pixels. Class balance is not made here but per tree, when the trainer
draws its bag (:mod:`hmocap_ros.gestures.forest`).

A near-miss frame (label ``(0, u, v)`` with ``(u, v)`` in the image: background, annotated with
the reference point of the gesture it almost is) is a negative frame whose hardest negatives
are known: besides the ``N-`` anywhere, ``n_near_miss`` negatives are drawn in the box around
the point exactly where a gesture frame's positives would be (the hand, within the depth
tolerance) and ``n_negative_near`` in the near square around the box (the rest of the hand and
the arm). Uniform negatives almost never land on that hand (a few hundred of its pixels among
300,000), so without them a hand one finger away from a gesture votes for it (the located hard
negatives of thesis sec. 3.3.2, with the location given by the annotation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hmocap_ros.gestures.depth_features import check_stack, stack_metres
from hmocap_ros.gestures.grid_votes import forest_grid_votes, grid_shape, pad_for_forest
from hmocap_ros.gestures.params import FeatureParams, PatchParams
from hmocap_ros.gestures.trees import Forest

__all__ = ["SampleSet", "collect_samples", "frame_labels", "hand_negatives", "mine_hard_negatives"]


@dataclass(eq=False)
class SampleSet:
    """Training samples: pixel ``(x[i], y[i])`` (column, row) of ``frames[frame[i]]`` with class ``label[i]``.

    ``frames`` (F, H, W) float32 metres as made by ``depth_to_metres``, or uint16 millimetres
    (``depth_to_millimetres``) (shared, not copied, by :meth:`subset`).
    """

    frames: np.ndarray
    frame: np.ndarray
    x: np.ndarray
    y: np.ndarray
    label: np.ndarray
    n_classes: int
    located: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.label.shape[0])

    @property
    def located_mask(self) -> np.ndarray:
        """(S,) bool: the located near-miss negatives (on or around a near miss's hand)."""
        return self.located if self.located is not None else np.zeros(len(self), np.bool_)

    def class_counts(self) -> np.ndarray:
        return np.bincount(self.label, minlength=self.n_classes)

    def subset(self, index) -> "SampleSet":
        index = np.asarray(index)
        return SampleSet(self.frames, self.frame[index], self.x[index], self.y[index], self.label[index],
                         self.n_classes, None if self.located is None else self.located[index])

    def extended(self, other: "SampleSet") -> "SampleSet":
        """These samples followed by ``other``'s (same frame stack)."""
        if other.frames is not self.frames or other.n_classes != self.n_classes:
            raise ValueError("can only extend with samples of the same frames and classes")
        located = (None if self.located is None and other.located is None
                   else np.concatenate([self.located_mask, other.located_mask]))
        return SampleSet(self.frames, np.concatenate([self.frame, other.frame]), np.concatenate([self.x, other.x]),
                         np.concatenate([self.y, other.y]), np.concatenate([self.label, other.label]),
                         self.n_classes, located)


def frame_labels(labels, n_frames: int) -> np.ndarray:
    """Labels as an (F, 3) int array ``(class, u, v)``; ``None`` rows (or class 0) are negative frames."""
    rows = [(0, -1, -1) if lab is None else tuple(lab)[:3] for lab in labels]
    arr = np.asarray(rows, dtype=np.float64).reshape(-1, 3)
    if arr.shape[0] != n_frames:
        raise ValueError(f"{arr.shape[0]} labels for {n_frames} frames")
    if not np.all(np.isfinite(arr)) or np.any(arr[:, 0] < 0):
        raise ValueError("labels must be finite (class, u, v) with class >= 0")
    return np.rint(arr).astype(np.int64)


def _annotated_depth(depth_m: np.ndarray, valid: np.ndarray, u: int, v: int) -> float | None:
    """Depth of the annotated point: the pixel itself, else the median of valid pixels within 3 px."""
    h, w = depth_m.shape
    if not (0 <= u < w and 0 <= v < h):
        return None
    if valid[v, u]:
        return float(depth_m[v, u])
    win = depth_m[max(v - 3, 0):v + 4, max(u - 3, 0):u + 4][valid[max(v - 3, 0):v + 4, max(u - 3, 0):u + 4]]
    return float(np.median(win)) if win.size else None


def _choose(rng: np.random.Generator, flat_index: np.ndarray, n: int) -> np.ndarray:
    if flat_index.size <= n:
        return flat_index
    return rng.choice(flat_index, size=n, replace=False)


def hand_negatives(depth_m: np.ndarray, u: int, v: int, params: PatchParams, background: float,
                   rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Columns and rows of up to ``params.n_near_miss`` negatives of one frame (float32 metres,
    invalid = ``background``) in the box around ``(u, v)`` on the surface there (within
    ``positive_depth_tolerance_m`` of its depth): where a gesture frame's positives would be,
    on a frame that is not the gesture (a near miss shown in the trainer's box). None when
    ``(u, v)`` has no depth."""
    h, w = depth_m.shape
    valid = depth_m < np.float32(background)
    d0 = _annotated_depth(depth_m, valid, u, v)
    if d0 is None or params.n_near_miss == 0:
        return np.zeros(0, np.int32), np.zeros(0, np.int32)
    half = params.box_half_size_px_m / d0
    y0, y1 = max(int(np.ceil(v - half)), 0), min(int(np.floor(v + half)) + 1, h)
    x0, x1 = max(int(np.ceil(u - half)), 0), min(int(np.floor(u + half)) + 1, w)
    win = depth_m[y0:y1, x0:x1]
    hand = valid[y0:y1, x0:x1]
    if params.positive_depth_tolerance_m > 0:
        hand &= np.abs(win - np.float32(d0)) <= np.float32(params.positive_depth_tolerance_m)
    pick = _choose(rng, np.flatnonzero(hand), params.n_near_miss)
    return (pick % (x1 - x0) + x0).astype(np.int32), (pick // (x1 - x0) + y0).astype(np.int32)


def collect_samples(frames_m: np.ndarray, labels, params: PatchParams, features: FeatureParams,
                    rng: np.random.Generator, n_classes: int | None = None) -> SampleSet:
    """Samples of every frame of ``frames_m`` (F, H, W) float32 metres or uint16 millimetres
    (``depth_features.depth_to_millimetres``), labels ``(class, u, v)`` per frame.

    A gesture frame whose annotated point lies outside the image or has no valid depth within
    3 px gives no samples at all (without the point's depth there is no box to sample around,
    nor to keep negatives out of).
    """
    frames_m = check_stack(frames_m)
    if frames_m.ndim != 3:
        raise ValueError("frames_m must be (F, H, W)")
    lab = frame_labels(labels, frames_m.shape[0])
    n_classes = int(n_classes if n_classes is not None else max(int(lab[:, 0].max(initial=0)) + 1, 2))
    if lab[:, 0].max(initial=0) >= n_classes:
        raise ValueError(f"a label's class is >= n_classes = {n_classes}")
    h, w = frames_m.shape[1:]
    bg = np.float32(features.background_depth_m)
    parts: list[tuple] = []  # (frame, flat pixel indices, class[, located])
    for f in range(frames_m.shape[0]):
        depth = stack_metres(frames_m[f], bg)
        valid = depth < bg
        cls, u, v = (int(a) for a in lab[f])
        d0 = _annotated_depth(depth, valid, u, v)
        if cls == 0:
            parts.append((f, _choose(rng, np.flatnonzero(valid), params.n_negative), 0))
            if d0 is None or not (params.n_near_miss or params.n_negative_near):
                continue
        elif d0 is None:
            continue
        half = params.box_half_size_px_m / d0
        ys, xs = np.ogrid[:h, :w]
        in_box = (np.abs(xs - u) <= half) & (np.abs(ys - v) <= half)
        hand = valid & in_box
        if params.positive_depth_tolerance_m > 0:
            hand &= np.abs(depth - np.float32(d0)) <= np.float32(params.positive_depth_tolerance_m)
        if cls == 0:
            parts.append((f, _choose(rng, np.flatnonzero(hand), params.n_near_miss), 0, True))
        else:
            parts.append((f, _choose(rng, np.flatnonzero(hand), params.n_positive), cls))
        ex = half * params.negative_exclusion_scale
        outside = valid & ~((np.abs(xs - u) <= ex) & (np.abs(ys - v) <= ex))
        if cls > 0:
            parts.append((f, _choose(rng, np.flatnonzero(outside), params.n_negative), 0))
        if params.n_negative_near:
            near = params.near_half_size_px_m / d0
            around = outside & (np.abs(xs - u) <= near) & (np.abs(ys - v) <= near)
            parts.append((f, _choose(rng, np.flatnonzero(around), params.n_negative_near), 0, cls == 0))
    if parts:
        frame = np.concatenate([np.full(p[1].size, p[0], np.int32) for p in parts])
        flat = np.concatenate([p[1] for p in parts]).astype(np.int64)
        label = np.concatenate([np.full(p[1].size, p[2], np.int32) for p in parts])
        located = np.concatenate([np.full(p[1].size, len(p) > 3 and p[3], np.bool_) for p in parts])
    else:
        frame, flat, label = np.zeros(0, np.int32), np.zeros(0, np.int64), np.zeros(0, np.int32)
        located = np.zeros(0, np.bool_)
    return SampleSet(frames_m, frame, (flat % w).astype(np.int32), (flat // w).astype(np.int32), label, n_classes,
                     located if located.any() else None)


def mine_hard_negatives(forest: Forest, frames_m: np.ndarray, labels, params: PatchParams,
                        rng: np.random.Generator, per_frame: int, stride: int,
                        exclusion_scale: float = 2.0) -> SampleSet:
    """Hard negatives of a trained forest on its own training frames (the on-the-fly hard
    negative mining of thesis sec. 3.3.2, run offline over the whole training set).

    The forest votes on every ``stride``-th pixel of each frame, exactly as the detector does
    (:func:`~hmocap_ros.gestures.grid_votes.forest_grid_votes`, sec. 3.2.4); a pixel that votes for
    a gesture is a false positive unless it lies within ``exclusion_scale`` positive boxes of the
    frame's annotated gesture (whose pixels are, or border on, positives). Up to ``per_frame``
    of them per frame, drawn at random, become background samples. These are the shapes the
    uniform negatives of patch collection rarely hit: other people's hands, near-miss poses,
    the moments between gestures, clutter that looks like a hand. On a near-miss frame (label
    ``(0, u, v)``) the false positives within ``exclusion_scale`` near squares
    (``near_half_size_px_m / d``) of the near miss's point are drawn first: those are where
    the forest mistakes the near miss for its gesture, the rest fill what is left.
    """
    frames_m = check_stack(frames_m)
    lab = frame_labels(labels, frames_m.shape[0])
    flat = forest.flat()
    h, w = frames_m.shape[1:]
    _, _, offset = grid_shape(h, w, stride)
    bg = np.float32(forest.features.background_depth_m)
    padded = None
    parts: list[tuple] = []  # (frame, flat pixel indices, located)
    for f in range(frames_m.shape[0]):
        depth = stack_metres(frames_m[f], bg)
        padded = pad_for_forest(depth, flat, padded)
        class_map, _ = forest_grid_votes(flat, padded, stride)
        gy, gx = np.nonzero(class_map > 0)
        px, py = offset + gx * stride, offset + gy * stride
        cls, u, v = (int(a) for a in lab[f])
        d0 = _annotated_depth(depth, depth < bg, u, v) if px.size else None
        if cls > 0 and px.size:
            if d0 is None:
                continue
            ex = exclusion_scale * params.box_half_size_px_m / d0
            keep = (np.abs(px - u) > ex) | (np.abs(py - v) > ex)
            px, py = px[keep], py[keep]
        elif d0 is not None:
            ex = exclusion_scale * params.near_half_size_px_m / d0
            at = (np.abs(px - u) <= ex) & (np.abs(py - v) <= ex)
            first = _choose(rng, py[at] * w + px[at], per_frame)
            rest = _choose(rng, py[~at] * w + px[~at], per_frame - first.size)
            parts.append((f, first, True))
            parts.append((f, rest, False))
            continue
        parts.append((f, _choose(rng, py * w + px, per_frame), False))
    flat_index = np.concatenate([p[1] for p in parts]).astype(np.int64) if parts else np.zeros(0, np.int64)
    frame = np.concatenate([np.full(p[1].size, p[0], np.int32) for p in parts]) if parts else np.zeros(0, np.int32)
    located = np.concatenate([np.full(p[1].size, p[2], np.bool_) for p in parts]) if parts else np.zeros(0, np.bool_)
    return SampleSet(frames_m, frame, (flat_index % w).astype(np.int32), (flat_index // w).astype(np.int32),
                     np.zeros(flat_index.size, np.int32), forest.n_classes, located if located.any() else None)
