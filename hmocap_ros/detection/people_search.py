"""Several people in the views: whose crop is whose, and the people no body follows yet (no rclpy).

The keypoint stage (:mod:`.keypoint_detector`) with ``max_people`` > 1 runs the landmark
network once per person and view. Three decisions make the crops each person's own:

1. **Depth order** (:func:`occluded_bodies`): where two bodies overlap in a view, the network
   sees the nearer person (the farther one is behind them), so the farther body's crop in that
   view is left out when the nearer body's box covers more than ``occluded_share`` of the
   farther body's box. A body's box is the box about its tracked skeleton's keypoints
   projected into the view (tighter than the crop, whose square holds the body's circle);
   depth is the depth of its hips' centre in that camera: the order comes from the tracked
   bodies, never from who looks larger.
2. **Identity** (:func:`landmarks_owner`): a body's landmarks are kept only when their hips'
   centre (auxiliary landmark 33) lies nearer to that body's projected hips than to any other
   body's; otherwise the network followed the other person out of the crop, the landmarks are
   dropped and the view's track with them.
3. **New people** (:func:`new_people`): the pose detector's detections in each view (after its
   non-maximum suppression) that are no tracked body's (:func:`is_tracked`: their hips' centre
   near a body's projected hips) are matched across views: two
   detections of two views are the same person when the DLT points of their hips' centre and
   their scale point (the detector's keypoints 0 and 1) reproject within ``tolerance_px`` in
   both views and the hips' centre lies in the room's height range. Groups are grown greedily
   from the best agreeing pair (lowest summed reprojection error), each view giving at most one
   detection to each person. A person needs two views that agree: one view never starts a
   body.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from typing import Sequence

import numpy as np

from hmocap_ros.detection.pose_detector import PoseDetection
from hmocap_ros.geometry import ROOM_UP, project_points, reprojection_errors, triangulate

__all__ = ["HIPS_HEIGHT_RANGE_M", "NewPerson", "landmark_hips", "landmarks_owner",
           "is_tracked", "new_people", "occluded_bodies", "pixels_box"]

#: the heights above the floor (metres) where a person's hips' centre can lie: a person lying
#: on the floor down to one jumping
HIPS_HEIGHT_RANGE_M = (0.0, 1.6)
#: the hips' centre landmark of the landmark network (auxiliary point 33)
_HIPS_LANDMARK = 33


def _intersection(a: np.ndarray, b: np.ndarray) -> float:
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return float(max(w, 0.0) * max(h, 0.0))


def _area(box: np.ndarray) -> float:
    return float(max(box[2] - box[0], 0.0) * max(box[3] - box[1], 0.0))


def pixels_box(pixels: dict) -> np.ndarray | None:
    """The box ``(4,)`` (x0, y0, x1, y1) about a body's projected keypoints (label -> (2,)
    pixel), None without any."""
    if not pixels:
        return None
    points = np.array(list(pixels.values()), dtype=np.float64)
    return np.concatenate([points.min(axis=0), points.max(axis=0)])


def occluded_bodies(boxes: Sequence[np.ndarray | None], depths: Sequence[float],
                    occluded_share: float) -> list[bool]:
    """Per body, whether its crop in one view is left out (module docstring, 1): ``boxes``
    per body (None: not in the view), ``depths`` the depth (metres) of each body's hips in the
    camera (NaN: unknown, then it occludes nobody and is occluded by nobody)."""
    out = [False] * len(boxes)
    for a, b in combinations(range(len(boxes)), 2):
        box_a, box_b = boxes[a], boxes[b]
        if box_a is None or box_b is None or not np.isfinite([depths[a], depths[b]]).all():
            continue
        near, far = (a, b) if depths[a] <= depths[b] else (b, a)
        box_far = boxes[far]
        assert box_far is not None
        if _intersection(box_a, box_b) > occluded_share * _area(box_far):
            out[far] = True
    return out


def landmarks_owner(hips_px: np.ndarray, projected_hips: np.ndarray) -> int:
    """Index of the body whose projected hips' centre (``projected_hips (B, 2)``, NaN where a
    body has none in the view) lies nearest to the landmarks' hips' centre ``hips_px (2,)``;
    -1 when no body has one (module docstring, 2)."""
    d = np.linalg.norm(np.asarray(projected_hips, float) - np.asarray(hips_px, float), axis=1)
    if not np.isfinite(d).any():
        return -1
    return int(np.nanargmin(d))


def landmark_hips(xy: np.ndarray) -> np.ndarray:
    """The hips' centre pixel ``(2,)`` of a view's landmarks ``(39, 2)``."""
    return np.asarray(xy, float)[_HIPS_LANDMARK]


#: a detection is a tracked body's when its hips' centre lies within this share of its own
#: scale (the distance from its hips' centre to its scale point) of the body's projected hips
TRACKED_SHARE = 0.5


def is_tracked(detection: PoseDetection, projected_hips: np.ndarray) -> bool:
    """Whether a detection is a tracked body's: its hips' centre within :data:`TRACKED_SHARE`
    of its scale of a body's projected hips' centre (``projected_hips (B, 2)``, NaN where a
    body has none in the view)."""
    hips = np.asarray(detection.keypoints[0], float)
    scale = float(np.linalg.norm(np.asarray(detection.keypoints[1], float) - hips))
    d = np.linalg.norm(np.asarray(projected_hips, float).reshape(-1, 2) - hips, axis=1)
    return bool(np.any(d[np.isfinite(d)] < TRACKED_SHARE * scale))


@dataclass(frozen=True)
class NewPerson:
    """A person no body follows, seen by two views or more: per view index, its detection;
    ``hips``: the room position (3,) of its hips' centre; ``error_px``: the mean
    reprojection error of the detections' two keypoints."""

    detections: dict
    hips: np.ndarray
    error_px: float


def _points(cameras, views: Sequence[int], dets: Sequence[PoseDetection]):
    """DLT of keypoints 0 and 1 of one detection per view: points (2, 3), errors (V, 2)."""
    cams = [cameras[v] for v in views]
    pixels = np.stack([d.keypoints[:2] for d in dets]).astype(np.float64)  # (V, 2, 2)
    points = triangulate(cams, pixels)
    return points, reprojection_errors(cams, points, pixels)


def _plausible(point: np.ndarray) -> bool:
    height = float(np.dot(point, ROOM_UP))
    return bool(np.isfinite(point).all() and HIPS_HEIGHT_RANGE_M[0] <= height <= HIPS_HEIGHT_RANGE_M[1])


def _in_front(cameras, views: Sequence[int], points: np.ndarray) -> bool:
    depth = project_points([cameras[v] for v in views], points, distort=False).depth
    return bool(np.all(depth > 0))


def new_people(cameras: Sequence, detections: Sequence[Sequence[PoseDetection]],
               tolerance_px: float, max_people: int) -> list[NewPerson]:
    """People seen by two views or more among per-view detections (module docstring, 3), best
    agreeing first, at most ``max_people``."""
    pairs = []
    for va, vb in combinations(range(len(detections)), 2):
        for ia, da in enumerate(detections[va]):
            for ib, db in enumerate(detections[vb]):
                points, errors = _points(cameras, (va, vb), (da, db))
                if (not np.isfinite(errors).all() or errors.max() > tolerance_px
                        or not _plausible(points[0]) or not _in_front(cameras, (va, vb), points)):
                    continue
                pairs.append((float(errors.mean()), va, ia, vb, ib))
    pairs.sort()
    used: set[tuple[int, int]] = set()
    people: list[NewPerson] = []
    for _, va, ia, vb, ib in pairs:
        if len(people) >= max_people:
            break
        if (va, ia) in used or (vb, ib) in used:
            continue
        group = {va: ia, vb: ib}
        for v in range(len(detections)):  # the other views' detections that agree with the pair
            if v in group:
                continue
            best = None
            for i, d in enumerate(detections[v]):
                if (v, i) in used:
                    continue
                views = sorted(group) + [v]
                dets = [detections[u][group[u]] for u in sorted(group)] + [d]
                _, errors = _points(cameras, views, dets)
                if np.isfinite(errors).all() and errors.max() <= tolerance_px:
                    score = float(errors.mean())
                    if best is None or score < best[0]:
                        best = (score, i)
            if best is not None:
                group[v] = best[1]
        views = sorted(group)
        dets = [detections[v][group[v]] for v in views]
        points, errors = _points(cameras, views, dets)
        used.update((v, group[v]) for v in views)
        people.append(NewPerson({v: detections[v][group[v]] for v in views}, points[0],
                                float(np.nanmean(errors))))
    return people
