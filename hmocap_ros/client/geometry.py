"""Geometry an interaction app asks of the room's bodies and gestures, without rclpy.

Everything is in one fixed frame with +Z up (the client's ``world``, REP 103): metres, the
floor at z = 0. Places are a point or an axis-aligned box (:class:`PointPlace`,
:class:`BoxPlace`; a box given by its floor rectangle alone spans every height).

- :func:`nearest_hand`: which body made a gesture, the body whose hand joint is nearest to the
  gesture's 3D point, within a distance;
- :func:`joint_above`: whether a joint is higher than another (a raised hand: the wrist above
  the head);
- :func:`pointing_ray` and :func:`pointing_angle`: a hand points along the ray from the elbow
  through the wrist; it points at a place when the angle between that ray and the direction to
  the nearest point of the place is small (0 when the ray passes through a box).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from hmocap_ros.client.bodies import HAND_JOINTS, Body

__all__ = ["BoxPlace", "PointPlace", "joint_above", "nearest_hand", "pointing_angle", "pointing_at", "pointing_ray"]

#: (m) an elbow-wrist segment shorter than this gives no direction
MIN_FOREARM = 0.05
#: (m) how far above and below a floor rectangle reaches for :func:`pointing_angle`
_FAR = 1e4


@dataclass(frozen=True, eq=False)
class PointPlace:
    """A place that is a point (3,) of the fixed frame."""

    point: np.ndarray

    def __post_init__(self):
        p = np.asarray(self.point, dtype=np.float64)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"a point must be 3 finite numbers [x, y, z], got {np.asarray(self.point).tolist()}")
        object.__setattr__(self, "point", p)

    def nearest(self, points) -> np.ndarray:
        """The point of the place nearest to each of ``points`` (..., 3)."""
        return np.broadcast_to(self.point, np.shape(points)).copy()

    def distance(self, points) -> np.ndarray:
        """Distance (m) of ``points`` (..., 3) from the place."""
        return np.linalg.norm(np.asarray(points, dtype=np.float64) - self.point, axis=-1)

    def contains(self, points, margin: float = 0.0) -> np.ndarray:
        """Whether ``points`` (..., 3) lie within ``margin`` of the point."""
        return self.distance(points) <= margin

    @property
    def centre(self) -> np.ndarray:
        return self.point


@dataclass(frozen=True, eq=False)
class BoxPlace:
    """An axis-aligned box of the fixed frame, ``low`` (3,) to ``high`` (3,); a floor rectangle
    has ``low[2] = -inf`` and ``high[2] = +inf``."""

    low: np.ndarray
    high: np.ndarray

    def __post_init__(self):
        lo = np.asarray(self.low, dtype=np.float64)
        hi = np.asarray(self.high, dtype=np.float64)
        if lo.shape not in ((2,), (3,)) or hi.shape != lo.shape:
            raise ValueError(f"a box needs min and max of 2 numbers [x, y] (a floor rectangle) or 3 [x, y, z], "
                             f"got {np.asarray(self.low).tolist()} and {np.asarray(self.high).tolist()}")
        if lo.shape == (2,):
            lo, hi = np.append(lo, -np.inf), np.append(hi, np.inf)
        if np.any(np.isnan(lo)) or np.any(np.isnan(hi)) or not np.all(np.isfinite(lo[:2])) \
                or not np.all(np.isfinite(hi[:2])) or np.any(lo >= hi):
            raise ValueError(f"a box needs finite min < max on every axis, got min {lo.tolist()} max {hi.tolist()}")
        object.__setattr__(self, "low", lo)
        object.__setattr__(self, "high", hi)

    def nearest(self, points) -> np.ndarray:
        """The point of the box nearest to each of ``points`` (..., 3) (the point itself inside)."""
        return np.clip(np.asarray(points, dtype=np.float64), self.low, self.high)

    def distance(self, points) -> np.ndarray:
        """Distance (m) of ``points`` (..., 3) from the box, 0 inside."""
        p = np.asarray(points, dtype=np.float64)
        return np.linalg.norm(p - self.nearest(p), axis=-1)

    def contains(self, points, margin: float = 0.0) -> np.ndarray:
        """Whether ``points`` (..., 3) lie in the box grown by ``margin`` on every side
        (shrunk by a negative one)."""
        p = np.asarray(points, dtype=np.float64)
        return np.all((p >= self.low - margin) & (p <= self.high + margin), axis=-1)

    @property
    def centre(self) -> np.ndarray:
        """The box's centre (a floor rectangle's at z = 0)."""
        mid = (self.low + self.high) / 2
        return np.where(np.isfinite(mid), mid, 0.0)


def nearest_hand(bodies: Iterable[Body] | Mapping[str, Body], point,
                 max_distance: float) -> tuple[Body, str, float] | None:
    """``(body, side, distance)`` of the hand joint nearest to ``point`` (3,) over ``bodies`` (Body
    objects, or a mapping of ids to them such as ``Room.bodies``; ``side`` is ``"left"`` or
    ``"right"``), None when no hand is within ``max_distance`` m."""
    best = None
    target = np.asarray(point, dtype=np.float64)
    for body in (bodies.values() if isinstance(bodies, Mapping) else bodies):
        for side, (hand, _elbow) in HAND_JOINTS.items():
            p = body.joint(hand)
            if p is None:
                continue
            d = float(np.linalg.norm(p - target))
            if d <= max_distance and (best is None or d < best[2]):
                best = (body, side, d)
    return best


def joint_above(body: Body, joint: str, other: str, margin: float = 0.0) -> bool | None:
    """Whether ``joint`` is more than ``margin`` m higher (+Z) than ``other``; None when the
    body misses either."""
    a, b = body.joint(joint), body.joint(other)
    if a is None or b is None:
        return None
    return bool(a[2] - b[2] > margin)


def pointing_ray(body: Body, side: str) -> tuple[np.ndarray, np.ndarray] | None:
    """``(origin, unit direction)`` of the ray from the elbow through the wrist of ``side``
    (``"left"`` or ``"right"``), starting at the wrist; None when the body misses either
    joint or the forearm is shorter than :data:`MIN_FOREARM`."""
    hand, elbow = HAND_JOINTS[side]
    w, e = body.joint(hand), body.joint(elbow)
    if w is None or e is None:
        return None
    d = w - e
    length = float(np.linalg.norm(d))
    return (w, d / length) if length >= MIN_FOREARM else None


def pointing_angle(origin, direction, place) -> float:
    """Angle (degrees) between the ray ``origin + t direction`` (t >= 0) and the direction from
    ``origin`` to the point of ``place`` that is nearest to it in angle: 0 when the ray passes
    through a box (or starts in it), 180 when the place lies straight behind.

    For a box the nearest direction lies on its outline as seen from ``origin``, so on one of
    its 12 edges: on the edge ``a + s e`` (``s`` in [0, 1], relative to the origin) the cosine
    ``d . p / |p|`` is extreme where ``(d.e)(p.p) = (d.p)(p.e)``, which is linear in ``s``;
    each edge is checked at that ``s`` and its ends. A floor rectangle's open heights count as
    :data:`_FAR` m above and below the origin."""
    o = np.asarray(origin, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    if isinstance(place, PointPlace):
        return _angle(d, place.point - o)
    low = np.where(np.isfinite(place.low), place.low, o - _FAR)
    high = np.where(np.isfinite(place.high), place.high, o + _FAR)
    if _ray_hits_box(o, d, low, high):
        return 0.0
    corners = np.stack(np.meshgrid(*zip(low, high), indexing="ij"), axis=-1).reshape(8, 3) - o
    ends = np.array([(i, i | bit) for i in range(8) for bit in (1, 2, 4) if not i & bit])  # the 12 edges
    a, e = corners[ends[:, 0]], corners[ends[:, 1]] - corners[ends[:, 0]]
    da, de = a @ d, e @ d
    aa, ae, ee = (a * a).sum(1), (a * e).sum(1), (e * e).sum(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.clip(np.nan_to_num((da * ae - de * aa) / (de * ae - da * ee), nan=0.0), 0.0, 1.0)
    points = a[:, None, :] + np.stack([np.zeros_like(s), np.ones_like(s), s], 1)[..., None] * e[:, None, :]
    cosines = (points @ d) / np.maximum(np.linalg.norm(points, axis=-1), 1e-12)
    return float(np.degrees(np.arccos(np.clip(cosines.max(), -1.0, 1.0))))


def _angle(d: np.ndarray, v: np.ndarray) -> float:
    norm = float(np.linalg.norm(v))
    if norm == 0.0:
        return 0.0
    return float(np.degrees(np.arccos(np.clip(np.dot(v, d) / norm, -1.0, 1.0))))


def _ray_hits_box(o: np.ndarray, d: np.ndarray, low: np.ndarray, high: np.ndarray) -> bool:
    """Whether the ray ``o + t d``, t >= 0, meets the box (slab test)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (low - o) / d, (high - o) / d
    parallel = d == 0
    if np.any(parallel & ((o < low) | (o > high))):
        return False
    near = np.where(parallel, -np.inf, np.minimum(t1, t2)).max()
    far = np.where(parallel, np.inf, np.maximum(t1, t2)).min()
    return bool(far >= max(near, 0.0))

def pointing_at(body: Body, place, max_angle: float = 15.0) -> str | None:
    """The side (``"left"`` or ``"right"``) whose forearm points at ``place`` within
    ``max_angle`` degrees (:func:`pointing_angle`), the better of the two when both do; None
    when neither does or the body misses the joints."""
    best = None
    for side in HAND_JOINTS:
        ray = pointing_ray(body, side)
        if ray is None:
            continue
        angle = pointing_angle(*ray, place)
        if angle <= max_angle and (best is None or angle < best[1]):
            best = (side, angle)
    return None if best is None else best[0]
