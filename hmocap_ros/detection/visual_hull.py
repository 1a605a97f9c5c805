"""Visual hull of the person by voxel carving (thesis sec. 2.3.4, after Laurentini [75]).

The tracker starts from the visual hull: "the initial position is computed from the visual
hull centroid (generated with the available silhouettes), and the model is scaled to fit the
visual hull height". A voxel of a grid over the room is kept when its centre projects onto
foreground in every view that sees it (at most ``max_misses`` misses allowed) and at least
``min_views`` views see it. The person is a 26-connected component: of those at least 30% of
the largest one's size, the one the rig sees best (the highest mean number of views seeing its
voxels; then the largest). With a second person in the room, the tracker thus takes the one in
full view of the cameras, not whoever is nearest a camera or half out of its field. A
``region`` of the floor (x/z box) restricts the choice to people whose centroid stands in it;
``exclude`` (where the people other trackers follow stand) leaves those people out.
The grid is coarse over the whole room, then fine inside that component's box.

Bridging (``bridge_misses``, beyond the thesis): the components are taken over a carving that
lets a voxel miss the foreground in ``bridge_misses`` more views (still on foreground in
``min_views``), and each keeps only its voxels of the strict carving. A band of the body that
the segmentation loses in one view (a shirt the colour of the wall behind it) otherwise cuts
the hull in two, and the largest part, legs and hips, gives the start-up a height far short of
the person's.

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

from hmocap_ros.geometry.projection import project_batch

__all__ = ["Hull", "carve", "coarse_people", "room_bounds", "visual_hull"]


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

    def top_within(self, centre_xz, radius: float) -> float | None:
        """Top of the hull's voxels standing within ``radius`` metres of ``centre_xz`` (x, z)
        on the floor: the height of one column, e.g. over a body's head, which a raised hand
        beside it does not top; None when the column holds no voxel."""
        d = self.points[:, [0, 2]] - np.asarray(centre_xz, dtype=np.float64)
        inside = np.einsum("ij,ij->i", d, d) <= radius * radius
        if not inside.any():
            return None
        return float(self.points[inside, 1].max() + 0.5 * self.voxel_size)

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
          points: np.ndarray, min_views: int = 2, max_misses: int = 0,
          return_seen: bool = False, return_misses: bool = False):
    """Occupancy (P,) bool of world points ``(P, 3)`` against foreground masks ``(M, H, W)``.

    A point is occupied when at least ``min_views`` views see it (it projects inside the
    image) and it projects onto background in at most ``max_misses`` of them. With
    ``return_seen``: ``(occupancy, views seeing each point (P,))``; with ``return_misses``:
    ``(occupancy, views seeing it, views seeing it on background (P,))``.
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
    occ = (n_seen >= min_views) & (misses <= max_misses)
    if return_misses:
        return occ, n_seen, misses
    return (occ, n_seen) if return_seen else occ


def bridged(occ: np.ndarray, n_seen: np.ndarray, misses: np.ndarray, min_views: int,
            max_misses: int, bridge_misses: int) -> np.ndarray:
    """The carving that groups hull voxels into people: ``occ`` plus the voxels that miss
    the foreground in up to ``bridge_misses`` more views and are still on foreground in at
    least ``min_views`` views. A band of the person lost in one view (a shirt the colour of
    the wall behind it) then no longer cuts the hull in two; the hull keeps ``occ``'s voxels."""
    if bridge_misses <= 0:
        return occ
    return occ | ((misses <= max_misses + bridge_misses) & (n_seen - misses >= min_views))


def _components(occ: np.ndarray, n_seen: np.ndarray | None = None,
                centres: np.ndarray | None = None, link: np.ndarray | None = None):
    """26-connected components of ``occ``: ``(labels, n, sizes (n,), seen (n,) or None,
    centroids (n, 3) or None)``; ``seen`` is the mean of ``n_seen`` over each component's
    voxels, ``centroids`` the mean of the voxel ``centres`` (``occ.shape + (3,)``).
    ``link`` (a superset of ``occ``, :func:`bridged`): the components are ``link``'s, and
    labels, sizes, ``seen`` and centroids count only their ``occ`` voxels; a component of
    ``link`` without any voxel of ``occ`` (a ghost of the looser carving) is nobody and left
    out."""
    labels, n = ndimage.label(occ if link is None else link,
                              structure=np.ones((3, 3, 3), dtype=bool))
    if link is not None:
        labels = np.where(occ, labels, 0)
        present = np.bincount(labels.ravel(), minlength=n + 1)[1:] > 0
        if not present.all():
            renumber = np.zeros(n + 1, dtype=labels.dtype)
            n = int(present.sum())
            renumber[1:][present] = np.arange(1, n + 1)
            labels = renumber[labels]
    flat = labels.ravel()
    sizes = np.bincount(flat, minlength=n + 1)[1:]
    seen = c = None
    if n_seen is not None:
        seen = (np.bincount(flat, weights=n_seen.ravel().astype(np.float64), minlength=n + 1)[1:]
                / np.maximum(sizes, 1))
    if centres is not None:
        c = np.stack([np.bincount(flat, weights=centres[..., k].ravel(), minlength=n + 1)[1:]
                      for k in range(3)], axis=1) / np.maximum(sizes, 1)[:, None]
    return labels, n, sizes, seen, c


def _coarse_occupancy(masks, K, R, t, D, bounds, coarse_voxel, min_views, max_misses,
                      bridge_misses=0):
    """The coarse room grid carved: ``(occupancy, its bridged carving (:func:`bridged`),
    views seeing each voxel, voxel centres)`` shaped as the grid (the last with a trailing 3)."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    points, shape = _grid(lo, hi, coarse_voxel)
    occ, n_seen, misses = carve(masks, K, R, t, D, points, min_views, max_misses,
                                return_misses=True)
    link = bridged(occ, n_seen, misses, min_views, max_misses, bridge_misses)
    return (occ.reshape(shape), link.reshape(shape), n_seen.reshape(shape),
            points.reshape(shape + (3,)))


def coarse_people(masks: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray,
                  D: np.ndarray, bounds: tuple[np.ndarray, np.ndarray], *,
                  coarse_voxel: float = 0.08, min_views: int = 2, max_misses: int = 0,
                  min_fraction: float = 0.3,
                  bridge_misses: int = 0) -> list[tuple[int, float, np.ndarray]]:
    """The candidates :func:`visual_hull` chooses from: per component of the coarse hull of at
    least ``min_fraction`` of the largest one's size, ``(voxels, mean views seeing them,
    centroid (3,))`` (for diagnostics: whom the tracker could start on, and why)."""
    occ, link, n_seen, centres = _coarse_occupancy(masks, K, R, t, D, bounds, coarse_voxel,
                                                   min_views, max_misses, bridge_misses)
    _, n, sizes, seen, c = _components(occ, n_seen, centres, link=link)
    if n == 0:
        return []
    return [(int(sizes[k]), float(seen[k]), c[k]) for k in range(n)
            if sizes[k] >= min_fraction * sizes.max()]


def _person_component(occ: np.ndarray, n_seen: np.ndarray | None = None,
                      min_fraction: float = 0.3, centres: np.ndarray | None = None,
                      near: np.ndarray | None = None,
                      near_radius: float = 1.0,
                      region: Sequence[float] | None = None,
                      exclude: np.ndarray | None = None,
                      exclude_radius: float = 0.5,
                      link: np.ndarray | None = None) -> np.ndarray | None:
    """The component to track: of the connected components at least ``min_fraction`` of the
    largest one's size, the one the views see best (highest mean number of views seeing its
    voxels), then the largest. With two people in the room, the rig tracks the one it
    observes best rather than whoever is closest to a camera or half out of its view.
    ``near`` (3,) with ``centres`` (the voxel centres, ``occ.shape + (3,)``): the component
    whose centroid lies nearest that point, if within ``near_radius`` metres (the person the
    tracker just lost), else as above. ``region`` ``(x_min, z_min, x_max, z_max)`` with
    ``centres``: only components whose centroid lies in that floor box count (None when there
    is none). ``exclude`` (K, 3) with ``centres``: components whose centroid lies within
    ``exclude_radius`` metres of one of these points on the floor are no candidates (people
    other trackers already follow; None when nobody else is there). ``link``: group the
    voxels of ``occ`` by the components of this superset (:func:`bridged`)."""
    located = near is not None or region is not None or exclude is not None
    labels, n, sizes, seen, c = _components(occ, n_seen, centres if located else None, link)
    if n == 0:
        return None
    allowed = np.ones(n, dtype=bool)
    if region is not None and c is not None:
        x0, z0, x1, z1 = (float(v) for v in region)
        allowed &= (c[:, 0] >= x0) & (c[:, 0] <= x1) & (c[:, 2] >= z0) & (c[:, 2] <= z1)
    if exclude is not None and len(exclude) and c is not None:
        taken = np.asarray(exclude, dtype=np.float64).reshape(-1, 3)[:, [0, 2]]
        gap = np.linalg.norm(c[:, None, [0, 2]] - taken[None], axis=2).min(axis=1)
        allowed &= gap > exclude_radius
    if not allowed.any():
        return None
    sizes = np.where(allowed, sizes, 0)
    big = sizes >= min_fraction * sizes.max()
    if near is not None and c is not None:
        dist = np.linalg.norm(c[:, [0, 2]] - np.asarray(near)[[0, 2]], axis=1)
        dist[~big] = np.inf
        if dist.min() <= near_radius:
            return labels == (1 + int(np.argmin(dist)))
    if seen is None or n == 1:
        return labels == (1 + int(np.argmax(sizes)))
    best = max(np.flatnonzero(big), key=lambda k: (round(float(seen[k]), 1), int(sizes[k])))
    return labels == (1 + int(best))


def visual_hull(masks: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray, D: np.ndarray,
                bounds: tuple[np.ndarray, np.ndarray], *, coarse_voxel: float = 0.08,
                fine_voxel: float = 0.03, min_views: int = 2, max_misses: int = 0,
                min_volume: float = 0.01, near: np.ndarray | None = None,
                region: Sequence[float] | None = None, exclude: np.ndarray | None = None,
                exclude_radius: float = 0.5, bridge_misses: int = 0) -> Hull | None:
    """Carve the person's visual hull; None when nothing of at least ``min_volume`` m^3 is found.

    masks: (M, H, W) foreground (non-zero) at the resolution of the cameras ``K, R, t, D``
    (e.g. an :class:`~hmocap_ros.tracking.body_fitness.Observation`). bounds: the room box
    (:func:`room_bounds`). near: where the person was last seen (restarts prefer the person
    there, see :func:`_person_component`). region: ``(x_min, z_min, x_max, z_max)``, the
    floor box a person's centroid must stand in (None: anywhere in the room). exclude:
    (K, 3) points where people other trackers follow stand; nobody within
    ``exclude_radius`` metres of one on the floor is chosen. bridge_misses: group the
    voxels into people over a carving that lets a voxel miss the foreground in this many
    more views (:func:`bridged`); the hull's voxels stay those of ``max_misses``.
    """
    if masks.shape[0] < min_views:
        return None
    lo = np.asarray(bounds[0], dtype=np.float64)
    occ, link, n_seen, centres = _coarse_occupancy(masks, K, R, t, D, bounds, coarse_voxel,
                                                   min_views, max_misses, bridge_misses)
    comp = _person_component(occ, n_seen, centres=centres, near=near, region=region,
                             exclude=exclude, exclude_radius=exclude_radius, link=link)
    if comp is None or comp.sum() * coarse_voxel ** 3 < min_volume:
        return None
    idx = np.argwhere(comp)
    flo = lo + idx.min(axis=0) * coarse_voxel - coarse_voxel
    fhi = lo + (idx.max(axis=0) + 1) * coarse_voxel + coarse_voxel
    flo[1] = max(flo[1], lo[1])
    points, shape = _grid(flo, fhi, fine_voxel)
    occ, n_seen, misses = carve(masks, K, R, t, D, points, min_views, max_misses,
                                return_misses=True)
    link = bridged(occ, n_seen, misses, min_views, max_misses, bridge_misses).reshape(shape)
    # Inside the chosen person's box: the largest part.
    comp = _person_component(occ.reshape(shape), link=link)
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
