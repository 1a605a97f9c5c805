"""The landmark network on a few views per frame set, the other views' landmarks carried forward.

The network is the largest share of a frame set's work (docs/tracking.md, "Keypoints on some
views per set", has its cost per view). With ``views_per_set`` (and ``pose_rate_hz``) the
:class:`~.keypoint_detector.KeypointDetector` runs it on the views whose landmarks are oldest
and carries every other view's latest landmarks to the new frame set's stamp:

- **Which views** (:func:`views_to_run`): every view without landmarks (the first frame set,
  a view that lost the person: its crop needs the network or the pose detector), then the
  views with the oldest landmarks until ``k`` run (ties go to the lower camera index), so each
  view is refreshed every ``ceil(V / k)`` frame sets.
- **Motion compensation** (:func:`carried_landmarks`): a view's landmarks computed at stamp
  ``s`` are moved, landmark by landmark, by the image motion of the body part they belong to
  (:data:`LANDMARK_PART`) between ``s`` and the new stamp ``t``: ``x_t = x_s + pi(X(t)) -
  pi(X(s))``, with ``pi`` the view's projection and ``X`` the tracked skeleton's part
  (:class:`SkeletonHistory`: the skeletons the tracker fed back, linearly interpolated between
  their stamps and extrapolated at constant velocity beyond the newest, for at most
  :data:`MAX_EXTRAPOLATION_S`). Without a skeleton the landmarks are carried unmoved.
- **At least two views per set** (:data:`MIN_VIEWS_PER_SET`): with one fresh view against
  three carried ones the fit follows the carried landmarks, which follow the fit, and the
  velocity feeds the tracker's frame-to-frame noise back into its own keypoints (docs/tracking.md,
  "Keypoints on some views per set", has the figures).
- **Fusion**: the carried landmarks go into the same robust triangulation as the fresh ones,
  with their own confidences (a design choice); the consensus (RANSAC over view pairs) leaves
  out a carried view that disagrees with the fresh ones, as it does a wrong view.
- **Age**: landmarks older than ``max_carry_ms`` are not carried (the view counts as missing
  until its turn comes).
- **How many views** (:func:`views_for_rate`): ``views_per_set`` at least; with
  ``pose_rate_hz > 0``, more when the measured cost leaves room: the largest ``k`` with
  ``other + k * per_view <= 1 / pose_rate_hz``, ``per_view`` the landmark network's mean
  seconds per view and ``other`` the rest of the frame set's work (the detector's own, plus
  what the caller reports of the other stages in its thread), both exponential moving averages
  (:class:`CostMeter`). Its choice depends on the machine's speed, so runs that must repeat bit
  for bit (``hmocap track``) set ``pose_rate_hz`` to 0.
"""
from __future__ import annotations

import dataclasses
import math
from collections import deque
from typing import Sequence

import numpy as np

from hmocap_ros.detection.keypoint_network import NUM_LANDMARKS, ViewLandmarks
from hmocap_ros.geometry import project_points

__all__ = ["LANDMARK_PART", "MAX_EXTRAPOLATION_S", "MIN_VIEWS_PER_SET", "CostMeter", "SkeletonHistory",
           "carried_landmarks", "views_for_rate", "views_to_run"]

#: the skeleton part (a label of :func:`~.extremity_pipeline.skeleton_labels`) whose motion
#: carries each of the network's landmarks; ``hips`` is the hips' midpoint (the auxiliary
#: points 33-38 align the crop about the hips' centre)
LANDMARK_PART: tuple[str, ...] = (
    ("head",) * 11                                           # 0-10: face
    + ("left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
       "left_wrist", "right_wrist")                          # 11-16
    + ("left_wrist", "right_wrist") * 3                      # 17-22: pinky, index, thumb
    + ("left_hip", "right_hip", "left_knee", "right_knee",
       "left_ankle", "right_ankle")                          # 23-28
    + ("left_ankle", "right_ankle") * 2                      # 29-32: heel, foot index
    + ("hips",) * (NUM_LANDMARKS - 33)                       # 33-38: auxiliary
)
#: the farthest a skeleton is extrapolated beyond the newest one fed back (seconds)
MAX_EXTRAPOLATION_S = 0.2
#: the fewest views whose network runs on a frame set that has that many candidates
MIN_VIEWS_PER_SET = 2
#: skeletons kept by :class:`SkeletonHistory`
_HISTORY = 16


class SkeletonHistory:
    """The tracked skeletons fed back (label -> (3,) room position, by stamp), and the
    skeleton at any stamp: linear interpolation between two kept ones, constant velocity
    beyond the newest (at most :data:`MAX_EXTRAPOLATION_S`), the oldest before it."""

    def __init__(self) -> None:
        self._items: deque[tuple[int, dict]] = deque(maxlen=_HISTORY)

    def __len__(self) -> int:
        return len(self._items)

    def clear(self) -> None:
        self._items.clear()

    def add(self, stamp_ns: int, skeleton: dict) -> None:
        """Keep a skeleton (one already kept at that stamp or a later one is not added
        again; an earlier stamp than the newest clears the history: the stream started
        over)."""
        if not skeleton:
            return
        if self._items and stamp_ns < self._items[0][0]:
            self._items.clear()
        elif self._items and stamp_ns <= self._items[-1][0]:
            return
        parts = {k: np.asarray(v, float) for k, v in skeleton.items()}
        if "left_hip" in parts and "right_hip" in parts:
            parts["hips"] = 0.5 * (parts["left_hip"] + parts["right_hip"])
        self._items.append((int(stamp_ns), parts))

    def at(self, stamp_ns: int) -> dict | None:
        """The skeleton at a stamp (class docstring), None when none is kept."""
        if not self._items:
            return None
        stamps = [s for s, _ in self._items]
        if stamp_ns <= stamps[0]:
            return self._items[0][1]
        if len(stamps) == 1:
            return self._items[-1][1]
        i = int(np.searchsorted(stamps, stamp_ns))
        if i >= len(stamps):  # beyond the newest: the last two's velocity
            i = len(stamps) - 1
            ahead = min((stamp_ns - stamps[-1]) * 1e-9, MAX_EXTRAPOLATION_S)
            stamp_ns = stamps[-1] + int(ahead * 1e9)
        (s0, a), (s1, b) = self._items[i - 1], self._items[i]
        w = (stamp_ns - s0) / max(s1 - s0, 1)
        return {k: a[k] + w * (b[k] - a[k]) for k in a.keys() & b.keys()}


def views_to_run(ages_ns: Sequence[int | None], candidates: Sequence[int], k: int) -> list[int]:
    """The candidate views without landmarks, and of the others the oldest until
    ``max(k, MIN_VIEWS_PER_SET)`` views run (``ages_ns[v]``: the stamp of view ``v``'s
    landmarks, None: none; ties to the lower index)."""
    k = max(int(k), MIN_VIEWS_PER_SET)
    without = [v for v in candidates if ages_ns[v] is None]
    others = sorted((v for v in candidates if ages_ns[v] is not None), key=lambda v: (ages_ns[v], v))
    return sorted(without + others[:max(k - len(without), 0)])


def carried_landmarks(camera, view: ViewLandmarks, then: dict | None,
                      now: dict | None) -> ViewLandmarks:
    """A view's landmarks moved from one stamp to another by the image motion of their body
    parts (module docstring): ``then`` and ``now`` are the skeleton at the two stamps (None:
    unmoved). A landmark whose part is in neither, or projects behind the camera, stays."""
    if then is None or now is None:
        return view
    parts = sorted(then.keys() & now.keys())
    if not parts:
        return view
    both = np.stack([np.stack([then[p] for p in parts]), np.stack([now[p] for p in parts])])
    proj = project_points([camera], both, distort=True)
    pixels = proj.pixels[0]  # (2, P, 2)
    ok = np.isfinite(pixels).all(axis=-1).all(axis=0) & (proj.depth[0] > 0).all(axis=0)
    motion = {p: pixels[1, j] - pixels[0, j] for j, p in enumerate(parts) if ok[j]}
    shift = np.array([motion.get(part, (0.0, 0.0)) for part in LANDMARK_PART])
    return dataclasses.replace(view, xy=view.xy + shift)


def views_for_rate(rate_hz: float, per_view_s: float, other_s: float, n_views: int) -> int:
    """The most views (at least :data:`MIN_VIEWS_PER_SET`, at most ``n_views``) whose landmark
    networks fit a frame set's time at ``rate_hz`` beside ``other_s`` of other work (module docstring)."""
    if n_views < 1:
        return 0
    if per_view_s <= 0:
        return n_views
    k = math.floor((1.0 / rate_hz - other_s) / per_view_s)
    return int(min(max(k, MIN_VIEWS_PER_SET), n_views))


class CostMeter:
    """Exponential moving averages of the landmark network's seconds per view and of the
    frame set's other seconds (module docstring); ``weight``: the newest measure's share."""

    def __init__(self, weight: float = 0.2) -> None:
        self.weight = weight
        self.per_view_s = 0.0
        self.other_s = 0.0
        self._seen = False

    def add(self, network_s: float, views: int, other_s: float) -> None:
        if views > 0:
            per_view = network_s / views
            w = self.weight if self._seen else 1.0
            self.per_view_s += w * (per_view - self.per_view_s)
            self.other_s += w * (other_s - self.other_s)
            self._seen = True
