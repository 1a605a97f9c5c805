"""Visual hull of the person by voxel carving (thesis sec. 2.3.4, after Laurentini [75]).

The tracker starts from the visual hull: "the initial position is computed from the visual
hull centroid (generated with the available silhouettes), and the model is scaled to fit the
visual hull height". A voxel of a grid over the room is kept when its centre projects onto
foreground in every view that sees it (at most ``max_misses`` misses allowed) and at least
``min_views`` views see it. The largest 26-connected component is the person; the grid is
coarse over the whole room, then fine inside that component's box.

Outputs (:class:`Hull`): centroid, top height (the feet stand on the floor, y = 0), volume,
and a heading guess from the principal horizontal axis of the upper-body voxels (the shoulder
line is the widest horizontal direction of a standing person): the person faces one of the
two normals of that axis, ``heading`` or ``heading + pi`` (angle about +Y from +Z towards +X,
the convention of ``root_yaw``); ``elongation`` (major / minor spread) says how much to
trust it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import ndimage

from hmocap_ros.render import project_batch

__all__ = ["Hull", "carve", "room_bounds", "visual_hull"]


@dataclass(frozen=True, eq=False)
class Hull:
    """The carved person: voxel centres ``points (K, 3)`` of the kept component and summaries."""

    points: np.ndarray
    voxel_size: float
    centroid: np.ndarray
    top: float
    bottom: float
    volume: float
    heading: float
    elongation: float

    @property
    def height(self) -> float:
        """Standing height estimate: top of the hull above the floor (y = 0)."""
        return self.top


def room_bounds(cameras: Sequence, floor: float = 0.0, ceiling: float | None = None,
                margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned room box ``(lo (3,), hi (3,))`` spanned by the camera centres.

    x and z span the cameras' positions (cameras hang near the walls), y spans the floor to
    the highest camera (or ``ceiling``); ``margin`` shrinks the horizontal extent.
    """
    pos = np.stack([np.asarray(c.position, dtype=np.float64) for c in cameras])
    lo = pos.min(axis=0)
    hi = pos.max(axis=0)
    lo[1], hi[1] = floor, (pos[:, 1].max() if ceiling is None else ceiling)
    if len(cameras) < 3 or np.any(hi[[0, 2]] - lo[[0, 2]] < 1.0):
        # Cameras on one side of the room: fall back to a 3 m reach around them.
        c = 0.5 * (lo + hi)
        lo[[0, 2]] = np.minimum(lo[[0, 2]], c[[0, 2]] - 3.0)
        hi[[0, 2]] = np.maximum(hi[[0, 2]], c[[0, 2]] + 3.0)
    lo[[0, 2]] += margin
    hi[[0, 2]] -= margin
    return lo, hi


def _grid(lo: np.ndarray, hi: np.ndarray, voxel: float) -> tuple[np.ndarray, tuple]:
    n = np.maximum(np.ceil((hi - lo) / voxel).astype(int), 1)
    axes = [lo[k] + (np.arange(n[k]) + 0.5) * voxel for k in range(3)]
    xs, ys, zs = np.meshgrid(*axes, indexing="ij")
    return np.stack([xs.ravel(), ys.ravel(), zs.ravel()], axis=1), tuple(n)


def carve(masks: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray, D: np.ndarray,
          points: np.ndarray, min_views: int = 2, max_misses: int = 0) -> np.ndarray:
    """Occupancy (P,) bool of world points ``(P, 3)`` against foreground masks ``(M, H, W)``.

    A point is occupied when at least ``min_views`` views see it (it projects inside the
    image) and it projects onto background in at most ``max_misses`` of them.
    """
    n_views, height, width = masks.shape
    uv, _ = project_batch(points[None], K, R, t, D)
    uv = uv[0]  # (M, P, 2)
    col = np.floor(uv[..., 0] + 0.5)
    row = np.floor(uv[..., 1] + 0.5)
    seen = np.isfinite(col) & (col >= 0) & (col < width) & (row >= 0) & (row < height)
    ci = np.where(seen, col, 0).astype(np.intp)
    ri = np.where(seen, row, 0).astype(np.intp)
    fg = np.zeros(seen.shape, dtype=bool)
    for m in range(n_views):
        fg[m] = masks[m][ri[m], ci[m]] != 0
    fg &= seen
    n_seen = seen.sum(axis=0)
    misses = n_seen - fg.sum(axis=0)
    return (n_seen >= min_views) & (misses <= max_misses)


def _largest_component(occ: np.ndarray) -> np.ndarray | None:
    labels, n = ndimage.label(occ, structure=np.ones((3, 3, 3), dtype=bool))
    if n == 0:
        return None
    sizes = np.bincount(labels.ravel())[1:]
    return labels == (1 + int(np.argmax(sizes)))


def visual_hull(masks: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray, D: np.ndarray,
                bounds: tuple[np.ndarray, np.ndarray], *, coarse_voxel: float = 0.08,
                fine_voxel: float = 0.03, min_views: int = 2, max_misses: int = 0,
                min_volume: float = 0.01) -> Hull | None:
    """Carve the person's visual hull; None when nothing of at least ``min_volume`` m^3 is found.

    masks: (M, H, W) foreground (non-zero) at the resolution of the cameras ``K, R, t, D``
    (e.g. an :class:`~hmocap_ros.tracking.body_fitness.Observation`). bounds: the room box
    (:func:`room_bounds`).
    """
    if masks.shape[0] < min_views:
        return None
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    points, shape = _grid(lo, hi, coarse_voxel)
    occ = carve(masks, K, R, t, D, points, min_views, max_misses).reshape(shape)
    comp = _largest_component(occ)
    if comp is None or comp.sum() * coarse_voxel ** 3 < min_volume:
        return None
    idx = np.argwhere(comp)
    flo = lo + idx.min(axis=0) * coarse_voxel - coarse_voxel
    fhi = lo + (idx.max(axis=0) + 1) * coarse_voxel + coarse_voxel
    flo[1] = max(flo[1], lo[1])
    points, shape = _grid(flo, fhi, fine_voxel)
    occ = carve(masks, K, R, t, D, points, min_views, max_misses).reshape(shape)
    comp = _largest_component(occ)
    if comp is None:
        return None
    pts = points.reshape(shape + (3,))[comp]
    volume = len(pts) * fine_voxel ** 3
    if volume < min_volume:
        return None
    top = float(pts[:, 1].max() + 0.5 * fine_voxel)
    bottom = float(pts[:, 1].min() - 0.5 * fine_voxel)
    heading, elongation = _heading(pts, bottom, top)
    return Hull(points=pts, voxel_size=fine_voxel, centroid=pts.mean(axis=0), top=top,
                bottom=bottom, volume=volume, heading=heading, elongation=elongation)


def _heading(pts: np.ndarray, bottom: float, top: float) -> tuple[float, float]:
    """Facing direction (mod pi) normal to the widest horizontal axis of the chest band."""
    h = top - bottom
    band = pts[(pts[:, 1] > bottom + 0.55 * h) & (pts[:, 1] < bottom + 0.85 * h)]
    if len(band) < 5:
        band = pts
    xz = band[:, [0, 2]] - band[:, [0, 2]].mean(axis=0)
    evals, evecs = np.linalg.eigh(xz.T @ xz / len(xz))
    major = evecs[:, 1]  # (x, z) of the shoulder line
    facing = np.array([-major[1], major[0]])  # a horizontal normal of it
    heading = float(np.arctan2(facing[0], facing[1]))
    elongation = float(np.sqrt(evals[1] / max(evals[0], 1e-12)))
    return heading, elongation
