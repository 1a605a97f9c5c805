"""3D extremities (hands, head) from multi-view detections on the body surface (thesis sec. 2.5.1).

Per frame set:

1. **Surface** (``surface_points``): the visual hull is carved in a box around the previous
   pose (``carve`` of ``visual_hull.py`` at ``voxel``); its surface voxels (an empty 6-neighbour)
   are the oriented points ``Q``, with normals from the gradient of the smoothed occupancy.
   (The thesis estimates surface points and normals jointly after Salvador et al. [102]; a
   carved hull and its occupancy gradient give the same kind of oriented point set.)
2. **Visibility** (eq. 2.16, ``visibility``): ``eta_c(q) = -z_c . n_q`` where ``q`` passes a
   z-buffer test in camera ``c``, else 0, normalised so that ``sum_c eta_c(q) = 1``. ``z_c``
   is the viewing ray through ``q`` (the optical axis of a pinhole camera is the ray of its
   centre pixel only). The z-buffer is kept at a cell of about one projected voxel, so the
   carved shell has no holes that let its back show through.
3. **Probability surface** (eq. 2.17): ``Prob(q) = sum_c eta_c(q) T(proj_c(q))`` with ``T`` the
   per-pixel detector map of each view (``segmentation.skin``; maps of any resolution).
4. **Filtering** (eq. 2.18): ``Q' = {q : Prob(q) >= Gamma}``, clustered by distance tolerance
   ``theta_tol`` (connected components of a kd-tree radius graph, as in Rusu's Euclidean
   clustering [100]) and kept when their size lies in ``[theta_min, theta_max]``.
5. **Candidate location**: the thesis takes cluster centroids. A skin cluster is a hand *and*
   a bare forearm when sleeves are short, whose centroid lies mid-forearm; we take the mean of
   the cluster points within ``tip_radius`` of its point farthest from the body's centre (the
   end of the limb). For a hand alone or a face it is close to the centroid.
6. **Classification** (eq. 2.19, ``classify``): candidates are assigned to the end-effectors
   of the previous pose (left hand, right hand, head) by repeatedly taking the closest pair
   within the maximum distances ``Upsilon`` (35 cm hands, 25 cm head), the thesis' greedy
   solution.
6b. **Re-acquisition** (``reacquire``, beyond the thesis): a hand left unassigned by eq. 2.19
   (the tracked arm is lost, farther than Upsilon from its hand) takes the closest remaining
   candidate within arm's reach of its shoulder (the reference pose's arm length + 5 cm) that
   is not near the predicted head (30 cm) and lies nearer its own shoulder than the other
   shoulder (so that the other hand is not taken), so a lost arm can be drawn back by IK
   particles.
7. **Feet** (``geodesic_extrema``, beyond the thesis' skin detector, which cannot see shoes;
   the thesis lists feet among the extremities it localises): the extremities of the carved
   hull itself, the points geodesically farthest from the body's centre (after Baak et al.'s
   accumulative geodesic extrema: the farthest voxel becomes a source too, ``n_extrema``
   times), each taken as the mean of the hull within ``tip_radius`` of it, and classified
   to the feet of the previous pose like the skin candidates (Upsilon 35 cm).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from hmocap_ros.camera_model import Projection, project_points
from hmocap_ros.rig import camera_arrays
from hmocap_ros.tracking.visual_hull import carve

__all__ = ["END_EFFECTORS", "ExtremityParams", "Extremities", "ExtremityDetector",
           "detection_cost",
           "classify", "surface_points", "visibility", "extremity_probability",
           "cluster_candidates"]

#: End-effectors the detections are classified into (thesis: hands and head).
END_EFFECTORS = ("l_hand", "r_hand", "head", "l_foot", "r_foot")
#: the end-effectors the skin detector serves; the others come from the hull's extrema
SKIN_EFFECTORS = (0, 1, 2)
FOOT_EFFECTORS = (3, 4)


@dataclass(frozen=True)
class ExtremityParams:
    """Settings of :class:`ExtremityDetector` (thesis symbols in brackets)."""

    voxel: float = 0.03          #: carving grid (m)
    margin: float = 0.35         #: box around the previous pose's joints (m)
    mask_scale: float = 0.5      #: resolution of the masks used for carving
    max_misses: int = 0          #: views a surface voxel may fall outside the silhouette in
    threshold: float = 0.35      #: [Gamma] eq. 2.18
    cluster_tol: float = 0.05    #: [theta_tol] (m)
    cluster_min: int = 3         #: [theta_min] points
    cluster_max: int = 600       #: [theta_max] points
    tip_radius: float = 0.08     #: candidate = mean of the cluster within this of its far end (m)
    max_distance: tuple = (0.35, 0.35, 0.25, 0.35, 0.35)  #: [Upsilon] per END_EFFECTORS (m)
    depth_tolerance: float = 2.0  #: z-buffer tolerance in voxels
    feet: bool = True            #: locate the feet as geodesic extrema of the hull
    reacquire: bool = False      #: second pass for unassigned hands (module docstring, 6b)
    head_exclusion: float = 0.30  #: m, re-acquisition ignores candidates this near the head
    n_extrema: int = 6           #: geodesic extrema searched (head, hands, feet and a spare)


@dataclass(frozen=True, eq=False)
class Extremities:
    """One frame set's detections.

    candidates: (E, 3) skin candidate locations; assigned: (5, 3) per :data:`END_EFFECTORS`
    the candidate assigned to it (NaN rows: none); extrema: (X, 3) the hull's geodesic
    extrema; surface / probability: the oriented points and eq. 2.17 (for plots and tests).
    """

    candidates: np.ndarray
    assigned: np.ndarray
    surface: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    probability: np.ndarray = field(default_factory=lambda: np.zeros(0))
    extrema: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def found(self) -> np.ndarray:
        """(5,) bool: which end-effectors got a detection."""
        return np.isfinite(self.assigned).all(axis=1)

    @property
    def detections(self) -> np.ndarray:
        """(U, 3) the set C_t of eq. 2.20: the assigned hands and feet (not the head, see
        ``ik_proposals``)."""
        use = self.found.copy()
        use[2] = False
        return self.assigned[use]


def detection_cost(assigned: np.ndarray, effectors: np.ndarray) -> np.ndarray:
    """Eq. 2.20 for a batch of poses: (N,) mean over the detections C_t of the distance to the
    nearest model end-effector.

    assigned: (5, 3) detections per :data:`END_EFFECTORS` (NaN: none; the head is left out, see
    ``ik_proposals``); effectors: (N, 5, 3) the poses' end-effectors. "Nearest" ranges over the
    end-effectors of the detection's own detector (a skin blob is a hand or the head, a hull
    extremum a foot), so a hand seen where a wrong particle has a foot is not explained by it.
    """
    cost = np.zeros(effectors.shape[0])
    count = 0
    for kind in (SKIN_EFFECTORS, FOOT_EFFECTORS):
        rows = [i for i in kind if i != 2 and np.isfinite(assigned[i]).all()]
        if not rows:
            continue
        d = np.linalg.norm(assigned[rows][None, :, None] - effectors[:, None, list(kind)], axis=3)
        cost += d.min(axis=2).sum(axis=1)
        count += len(rows)
    return cost / max(count, 1)


def surface_points(occupancy: np.ndarray, origin: np.ndarray, voxel: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Oriented surface points of a boolean voxel grid: (points (S, 3), unit normals (S, 3)).

    occupancy: (X, Y, Z) bool, voxel ``(i, j, k)`` centred at ``origin + voxel * (i, j, k)``.
    A surface voxel is occupied with an empty (or out-of-grid) 6-neighbour; its normal is
    minus the gradient of the occupancy smoothed with a Gaussian of one voxel.
    """
    occ = np.asarray(occupancy, dtype=bool)
    if not occ.any():
        return np.zeros((0, 3)), np.zeros((0, 3))
    inner = ndimage.binary_erosion(occ, structure=ndimage.generate_binary_structure(3, 1),
                                   border_value=0)
    surf = occ & ~inner
    smooth = ndimage.gaussian_filter(occ.astype(np.float32), 1.0, mode="constant")
    grads = np.gradient(smooth)
    idx = np.argwhere(surf)
    g = np.stack([grads[a][surf] for a in range(3)], axis=1).astype(np.float64)
    n = -g
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(norm > 1e-9, n / np.maximum(norm, 1e-12), 0.0)
    return origin + voxel * idx, n


def visibility(points: np.ndarray, normals: np.ndarray, cameras: Sequence, voxel: float,
               depth_tolerance: float = 2.0, views: np.ndarray | None = None,
               proj: Projection | None = None) -> np.ndarray:
    """Eq. 2.16, normalised over the cameras: eta (M, S), each column sums to 1 (or is 0).

    A point is visible in a camera when it is in its image and no other surface point lies in
    front of it (z-buffer with cells of about one projected voxel; ``depth_tolerance`` voxels
    of slack). ``views`` (M,) bool leaves cameras out (missing views). ``proj``: the points'
    :func:`~hmocap_ros.camera_model.project_points` in ``cameras``, if already computed.
    """
    M, S = len(cameras), len(points)
    if S == 0:
        return np.zeros((M, 0))
    proj = project_points(cameras, points) if proj is None else proj
    eta = np.zeros((M, S))
    for c, cam in enumerate(cameras):
        if views is not None and not views[c]:
            continue
        vis = proj.visible[c]
        if not vis.any():
            continue
        depth = proj.depth[c]
        cell = max(1.0, cam.fx * voxel / float(np.median(depth[vis])))
        uv = np.floor(proj.pixels[c] / cell).astype(np.int64)
        w = int(np.ceil(cam.width / cell)) + 1
        flat = np.where(vis, uv[:, 1] * w + uv[:, 0], -1)
        zbuf = np.full(int(np.ceil(cam.height / cell) + 1) * w, np.inf)
        np.minimum.at(zbuf, flat[vis], depth[vis])
        front = vis & (depth <= zbuf[np.maximum(flat, 0)] + depth_tolerance * voxel)
        ray = points - cam.position
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        eta[c] = np.where(front, np.maximum(0.0, -np.einsum("ij,ij->i", ray, normals)), 0.0)
    total = eta.sum(axis=0, keepdims=True)
    return np.where(total > 0, eta / np.where(total > 0, total, 1.0), 0.0)


def extremity_probability(points: np.ndarray, eta: np.ndarray, cameras: Sequence,
                          maps: Sequence[np.ndarray | None],
                          proj: Projection | None = None) -> np.ndarray:
    """Eq. 2.17: Prob(q) = sum_c eta_c(q) T_c(proj_c(q)); maps uint8 (255 = 1) or float.

    A camera without a map (None) contributes nothing (its eta share is lost, not moved to
    the others: a view that cannot say "hand" does not make the others more certain).
    ``proj`` as in :func:`visibility`.
    """
    prob = np.zeros(len(points))
    if len(points) == 0:
        return prob
    proj = project_points(cameras, points) if proj is None else proj
    for c, (cam, tmap) in enumerate(zip(cameras, maps)):
        if tmap is None:
            continue
        t = np.asarray(tmap)
        sx, sy = t.shape[1] / cam.width, t.shape[0] / cam.height
        u = np.clip(np.floor((proj.pixels[c, :, 0] + 0.5) * sx), 0, t.shape[1] - 1)
        v = np.clip(np.floor((proj.pixels[c, :, 1] + 0.5) * sy), 0, t.shape[0] - 1)
        u = np.where(np.isfinite(u), u, 0).astype(np.intp)
        v = np.where(np.isfinite(v), v, 0).astype(np.intp)
        val = t[v, u].astype(np.float64)
        if t.dtype == np.uint8:
            val /= 255.0
        prob += np.where(proj.visible[c], eta[c] * val, 0.0)
    return prob


def cluster_candidates(points: np.ndarray, prob: np.ndarray, centre: np.ndarray,
                       params: ExtremityParams) -> np.ndarray:
    """Eq. 2.18 and clustering: candidate locations (E, 3) (see the module docstring, 4-5)."""
    keep = prob >= params.threshold
    pts = points[keep]
    if len(pts) < params.cluster_min:
        return np.zeros((0, 3))
    pairs = cKDTree(pts).query_pairs(params.cluster_tol, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                       shape=(len(pts), len(pts)))
    n, labels = connected_components(graph, directed=False)
    sizes = np.bincount(labels, minlength=n)
    out = []
    for k in np.flatnonzero((sizes >= params.cluster_min) & (sizes <= params.cluster_max)):
        cl = pts[labels == k]
        far = cl[np.argmax(np.linalg.norm(cl - centre, axis=1))]
        tip = cl[np.linalg.norm(cl - far, axis=1) <= params.tip_radius]
        out.append(tip.mean(axis=0))
    return np.array(out).reshape(-1, 3)


def geodesic_extrema(occupancy: np.ndarray, origin: np.ndarray, voxel: float,
                     centre: np.ndarray, n: int, tip_radius: float) -> np.ndarray:
    """Accumulative geodesic extrema of a voxel body: (<= n, 3) tip locations.

    Geodesic distance over 26-connected occupied voxels (edge length the step's length) from
    the voxel nearest ``centre``; the farthest voxel is an extremum and becomes a source too,
    ``n`` times (an extremum at distance 0 ends the search). Each extremum is reported as the
    mean of the occupied voxels within ``tip_radius`` (Euclidean) of it.
    """
    from scipy.sparse.csgraph import dijkstra

    idx = np.argwhere(occupancy)
    if len(idx) < 2:
        return np.zeros((0, 3))
    shape = np.array(occupancy.shape)
    lut = -np.ones(occupancy.shape, np.int64)
    lut[tuple(idx.T)] = np.arange(len(idx))
    rows, cols, lens = [], [], []
    for off in np.argwhere(np.ones((3, 3, 3), bool)) - 1:
        if tuple(off) <= (0, 0, 0):
            continue  # each undirected edge once
        nb = idx + off
        ok = np.all((nb >= 0) & (nb < shape), axis=1)
        j = np.full(len(idx), -1)
        j[ok] = lut[tuple(nb[ok].T)]
        has = j >= 0
        rows.append(np.flatnonzero(has))
        cols.append(j[has])
        lens.append(np.full(has.sum(), voxel * float(np.linalg.norm(off))))
    graph = coo_matrix((np.concatenate(lens), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(len(idx), len(idx))).tocsr()
    pts = origin + voxel * idx
    sources = [int(np.argmin(np.linalg.norm(pts - centre, axis=1)))]
    out = []
    for _ in range(n):
        d = dijkstra(graph, directed=False, indices=sources, min_only=True)
        d[~np.isfinite(d)] = -1.0
        far = int(np.argmax(d))
        if d[far] <= 0:
            break
        tip = pts[np.linalg.norm(pts - pts[far], axis=1) <= tip_radius]
        out.append(tip.mean(axis=0))
        sources.append(far)
    return np.array(out).reshape(-1, 3)


def _greedy_pairs(d: np.ndarray) -> list[tuple[int, int]]:
    """The thesis' greedy solution of an assignment (eq. 2.19): repeatedly the closest finite
    (row, column) pair of ``d`` (modified), each row and column used once."""
    pairs = []
    while np.isfinite(d).any():
        i, e = np.unravel_index(np.argmin(d), d.shape)
        pairs.append((int(i), int(e)))
        d[i, :] = np.inf
        d[:, e] = np.inf
    return pairs


def reacquire_hands(candidates: np.ndarray, assigned: np.ndarray, shoulders: np.ndarray,
                    reach: np.ndarray, head: np.ndarray, head_exclusion: float) -> np.ndarray:
    """Second pass for hands eq. 2.19 left unassigned: (2, 3) hands (see the module's 6b).

    assigned: (3, 3) left hand, right hand, head after eq. 2.19 (NaN: none). Candidates
    already used, within ``head_exclusion`` of the predicted ``head``, or not nearer the hand's
    own shoulder than the other one, are not taken; the closest (candidate, shoulder) pair
    within that arm's ``reach`` goes first.
    """
    hands = np.array(assigned[:2], dtype=np.float64)
    if len(candidates) == 0 or np.isfinite(hands).all():
        return hands
    used = np.zeros(len(candidates), bool)
    for row in assigned:
        if np.isfinite(row).all():
            used |= np.all(np.isclose(candidates, row), axis=1)
    if np.isfinite(head).all():
        used |= np.linalg.norm(candidates - head, axis=1) <= head_exclusion
    d = np.linalg.norm(shoulders[:, None] - candidates[None], axis=2)  # (2, E)
    d[d >= d[::-1]] = np.inf  # each hand keeps to its own side
    d[:, used] = np.inf
    d[d > np.asarray(reach, dtype=np.float64)[:, None]] = np.inf
    d[np.isfinite(hands).all(axis=1)] = np.inf
    for i, e in _greedy_pairs(d):
        hands[i] = candidates[e]
    return hands


def classify(candidates: np.ndarray, targets: np.ndarray, max_distance: Sequence[float]
             ) -> np.ndarray:
    """Eq. 2.19 by the thesis' greedy rule: (I, 3) assigned candidate per target (NaN: none).

    Repeatedly assigns the closest (target, candidate) pair whose distance is within the
    target's maximum ``Upsilon_i``; each candidate and target is used once.
    """
    targets = np.asarray(targets, dtype=np.float64)
    out = np.full(targets.shape, np.nan)
    if len(candidates) == 0:
        return out
    d = np.linalg.norm(targets[:, None] - candidates[None], axis=2)
    d[d > np.asarray(max_distance, dtype=np.float64)[:, None]] = np.inf
    d[~np.isfinite(targets).all(axis=1)] = np.inf
    for i, e in _greedy_pairs(d):
        out[i] = candidates[e]
    return out


class ExtremityDetector:
    """Hands and head in 3D from foreground masks and per-view detector maps (sec. 2.5.1).

    cameras: the rig at the masks' full resolution. ``detect(masks, maps, joints, targets)``.
    """

    def __init__(self, cameras: Sequence, params: ExtremityParams | None = None):
        self.cameras = tuple(cameras)
        self.params = params or ExtremityParams()
        p = self.params
        self._small = tuple(c.scaled(p.mask_scale) for c in self.cameras)
        self._K, self._R, self._t, self._D = camera_arrays(self._small)

    def _small_masks(self, masks: Sequence[np.ndarray | None]) -> tuple[np.ndarray, np.ndarray]:
        import cv2

        out, ok = [], []
        for cam, m in zip(self._small, masks):
            if m is None:
                out.append(np.zeros((cam.height, cam.width), np.uint8))
                ok.append(False)
                continue
            small = cv2.resize((np.asarray(m) > 0).astype(np.uint8) * 255,
                               (cam.width, cam.height), interpolation=cv2.INTER_AREA)
            out.append((small >= 128).astype(np.uint8))
            ok.append(True)
        return np.stack(out), np.array(ok)

    def detect(self, masks: Sequence[np.ndarray | None], maps: Sequence[np.ndarray | None],
               joints: np.ndarray, targets: np.ndarray, centre: np.ndarray | None = None,
               shoulders: np.ndarray | None = None, reach: np.ndarray | None = None
               ) -> Extremities:
        """Detections of one frame set.

        masks: per camera (H, W) foreground at the cameras' resolution or None; maps: per
        camera detector map (any resolution) or None; joints: (J, 3) the previous pose's joints
        (the carving box); targets: (5, 3) its end-effectors (:data:`END_EFFECTORS`);
        centre: the body's centre for the candidates' far ends (default: mean of ``joints``).
        shoulders (2, 3) and reach (2,): left/right shoulder and arm length of the reference
        pose, for re-acquisition (``params.reacquire``).
        """
        p = self.params
        small, ok = self._small_masks(masks)
        have_map = np.array([m is not None for m in maps]) & ok
        empty = Extremities(np.zeros((0, 3)), np.full((len(END_EFFECTORS), 3), np.nan))
        if ok.sum() < 2 or not (have_map.any() or p.feet):
            return empty
        lo = joints.min(axis=0) - p.margin
        hi = joints.max(axis=0) + p.margin
        lo[1] = max(lo[1], 0.0)
        axes = [np.arange(a, b + p.voxel, p.voxel) for a, b in zip(lo, hi)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
        shape = grid.shape[:3]
        views = np.flatnonzero(ok)
        occ = carve(small[views], self._K[views], self._R[views], self._t[views],
                    self._D[views], grid.reshape(-1, 3), min_views=min(2, len(views)),
                    max_misses=p.max_misses).reshape(shape)
        occ = _largest_component(occ)
        if occ is None:
            return empty
        pts, normals = surface_points(occ, lo, p.voxel)
        proj = project_points(self.cameras, pts)
        eta = visibility(pts, normals, self.cameras, p.voxel, p.depth_tolerance, ok, proj)
        prob = extremity_probability(pts, eta, self.cameras,
                                     [m if h else None for m, h in zip(maps, have_map)], proj)
        c = joints.mean(axis=0) if centre is None else centre
        cand = cluster_candidates(pts, prob, c, p)
        targets = np.asarray(targets, dtype=np.float64)
        upsilon = np.asarray(p.max_distance, dtype=np.float64)
        assigned = np.full((len(END_EFFECTORS), 3), np.nan)
        skin, feet = list(SKIN_EFFECTORS), list(FOOT_EFFECTORS)
        assigned[skin] = classify(cand, targets[skin], upsilon[skin])
        if p.reacquire and shoulders is not None and reach is not None:
            assigned[:2] = reacquire_hands(cand, assigned[:3], shoulders, reach,
                                           targets[2], p.head_exclusion)
        extrema = np.zeros((0, 3))
        if p.feet:
            extrema = geodesic_extrema(occ, lo, p.voxel, c, p.n_extrema, p.tip_radius)
            assigned[feet] = classify(extrema, targets[feet], upsilon[feet])
        return Extremities(cand, assigned, pts, prob, extrema)


def _largest_component(occ: np.ndarray) -> np.ndarray | None:
    labels, n = ndimage.label(occ, structure=np.ones((3, 3, 3), bool))
    if n == 0:
        return None
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    return labels == int(np.argmax(sizes))
