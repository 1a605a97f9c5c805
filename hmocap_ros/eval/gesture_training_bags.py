"""The trainable frames of annotated gesture bags (thesis sec. 3.2.3).

Reads the layout of ``hmocap sim gestures`` (:func:`~hmocap_ros.eval.gesture_eval.read_gesture_bags`)
into one compact uint16 millimetre stack for training a gesture forest.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from hmocap_ros.eval.gesture_eval import GestureBag, read_gesture_bags
from hmocap_ros.gestures.depth_features import depth_to_millimetres
from hmocap_ros.gestures.params import TrainParams

__all__ = ["read_training_bags"]


def read_training_bags(paths: Sequence[str | Path], params: TrainParams | None = None) -> tuple[GestureBag, int]:
    """The trainable frames of annotated bags as compact uint16 millimetres, 0 = invalid
    (``params.depth``; :func:`~hmocap_ros.gestures.depth_features.depth_to_millimetres`):
    background frames and gesture frames whose reference point is visible, in bag order. Each
    frame is converted as it is read and the others are dropped in place, so memory holds one
    copy of the frames at 0.6 MB per 640x480 frame. A near-miss frame's label is ``(0, u, v)``,
    the missed gesture's reference pixel (background with a place). Returns the frames and the
    number of frames left out."""
    params = params if params is not None else TrainParams()
    fmt, background = params.depth, params.features.background_depth_m
    data = read_gesture_bags(paths, frame_fn=lambda raw: depth_to_millimetres(raw, fmt, background))
    keep = np.flatnonzero(data.trainable)
    frames = data.depth
    for j, i in enumerate(keep):  # per frame, not per pixel: compaction without a second stack
        if i != j:
            frames[j] = frames[i]
    near = data.near_misses or [None] * len(data.labels)
    labels = [data.labels[i] if data.labels[i] is not None or near[i] is None else (0, near[i][1], near[i][2])
              for i in keep]
    return GestureBag(frames[:keep.size], data.stamps_ns[keep], labels, data.visible[keep], data.focal_px,
                      data.class_names, data.sources, [near[i] for i in keep]), len(data.labels) - keep.size
