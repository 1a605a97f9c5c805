"""Skin extremities: hands and head in 3D from multi-view skin maps on the body surface (sec. 2.5.1).

Per frame set:

1. **Surface** (``surface_points``): the visual hull is carved in a box (around the last
   skeleton, or around the coarse hull of the foreground when there is none) at ``voxel``; its
   surface voxels (an empty 6-neighbour) are the oriented points ``Q``, with normals from the
   gradient of the smoothed occupancy. (The thesis estimates surface points and normals jointly
   after Salvador et al. [102]; a carved hull and its occupancy gradient give the same kind of
   oriented point set.)
2. **Visibility** (eq. 2.16, ``visibility``): ``eta_c(q) = -z_c . n_q`` where ``q`` passes a
   z-buffer test in camera ``c``, else 0, normalised so that ``sum_c eta_c(q) = 1``. ``z_c``
   is the viewing ray through ``q`` (the optical axis of a pinhole camera is the ray of its
   centre pixel only). The z-buffer is kept at a cell of about one projected voxel, so the
   carved shell has no holes that let its back show through.
3. **Probability surface** (eq. 2.17): ``Prob(q) = sum_c eta_c(q) T(proj_c(q))`` with ``T`` the
   per-pixel skin map of each view (``detection.skin``; maps of any resolution).
4. **Filtering** (eq. 2.18): ``Q' = {q : Prob(q) >= Gamma}``, clustered by distance tolerance
   ``theta_tol`` (connected components of a kd-tree radius graph, as in Rusu's Euclidean
   clustering [100]) and kept when their size lies in ``[theta_min, theta_max]``.
5. **Candidate location**: the thesis takes cluster centroids. A skin cluster is a hand *and*
   a bare forearm when sleeves are short, whose centroid lies mid-forearm; we take the mean of
   the cluster points within ``tip_radius`` of its point farthest from the body's centre (the
   end of the limb). For a hand alone or a face it is close to the centroid. Its score is the
   cluster's summed probability (eq. 2.18), its normal the cluster's mean normal.

The classification of the candidates into hands and head (eq. 2.19) belongs to whoever knows the
body: the tracker assigns them to its predicted pose (:mod:`hmocap_ros.tracking.detection_assignment`);
the node labels them for display against the last skeleton.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from hmocap_ros.detection.visual_hull import carve, coarse_people, room_bounds
from hmocap_ros.geometry import Projection, project_points
from hmocap_ros.geometry.rig import camera_arrays
from hmocap_ros.params import param

__all__ = ["SkinExtremityParams", "SkinCandidates", "SkinExtremityDetector", "surface_points",
           "visibility", "extremity_probability", "cluster_candidates"]


@dataclass(frozen=True)
class SkinExtremityParams:
    """Settings of :class:`SkinExtremityDetector` (thesis symbols in brackets)."""

    voxel: float = param(0.03, "Carving grid of the surface points (m).")
    margin: float = param(0.35, "Carving box: margin (m) around the last skeleton's joints.")
    mask_scale: float = param(0.5, "Resolution of the masks used for carving, as a fraction "
                                   "of the image size.")
    threshold: float = param(0.35, "[Gamma] eq. 2.18: least extremity probability of a "
                                   "surface point kept.")
    cluster_tol: float = param(0.05, "[theta_tol] clustering distance (m).")
    cluster_min: int = param(3, "[theta_min] least points of a cluster.")
    cluster_max: int = param(600, "[theta_max] most points of a cluster.")
    tip_radius: float = param(0.08, "A candidate is the mean of its cluster within this "
                                    "distance (m) of the cluster's far end.")
    depth_tolerance: float = param(2.0, "z-buffer tolerance of eq. 2.16, in voxels.")
    coarse_voxel: float = param(0.08, "Without a skeleton: voxel (m) of the coarse hull of "
                                      "the room that finds the person's box.")


@dataclass(frozen=True, eq=False)
class SkinCandidates:
    """One frame set's skin candidates: positions, normals (E, 3), scores (E,) (eq. 2.18's
    summed probability) and the oriented surface points with their probability (eq. 2.17)."""

    positions: np.ndarray
    normals: np.ndarray
    scores: np.ndarray
    surface: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    probability: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @staticmethod
    def empty() -> "SkinCandidates":
        return SkinCandidates(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))


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
    :func:`~hmocap_ros.geometry.project_points` in ``cameras``, if already computed.
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


def cluster_candidates(points: np.ndarray, normals: np.ndarray, prob: np.ndarray,
                       centre: np.ndarray, params: SkinExtremityParams
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 2.18 and clustering: candidate locations (E, 3), mean normals (E, 3) and summed
    probabilities (E,) (module docstring, 4-5)."""
    keep = prob >= params.threshold
    pts, nrm, pr = points[keep], normals[keep], prob[keep]
    none = np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    if len(pts) < params.cluster_min:
        return none
    pairs = cKDTree(pts).query_pairs(params.cluster_tol, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                       shape=(len(pts), len(pts)))
    n, labels = connected_components(graph, directed=False)
    sizes = np.bincount(labels, minlength=n)
    out, out_n, out_s = [], [], []
    for k in np.flatnonzero((sizes >= params.cluster_min) & (sizes <= params.cluster_max)):
        members = labels == k
        cl = pts[members]
        far = cl[np.argmax(np.linalg.norm(cl - centre, axis=1))]
        tip = cl[np.linalg.norm(cl - far, axis=1) <= params.tip_radius]
        out.append(tip.mean(axis=0))
        mean_n = nrm[members].mean(axis=0)
        out_n.append(mean_n / max(float(np.linalg.norm(mean_n)), 1e-9))
        out_s.append(float(pr[members].sum()))
    if not out:
        return none
    return np.array(out), np.array(out_n), np.array(out_s)


class SkinExtremityDetector:
    """Skin candidates in 3D from foreground masks and per-view skin maps (sec. 2.5.1).

    cameras: the rig at the masks' full resolution. ``detect(masks, maps, joints)``.
    """

    def __init__(self, cameras: Sequence, params: SkinExtremityParams | None = None):
        self.cameras = tuple(cameras)
        self.params = params or SkinExtremityParams()
        p = self.params
        self._small = tuple(c.scaled(p.mask_scale) for c in self.cameras)
        self._K, self._R, self._t, self._D = camera_arrays(self._small)
        self._room = room_bounds(self.cameras, margin=0.0)

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

    def _box(self, small: np.ndarray, views: np.ndarray, joints: np.ndarray | None):
        """The carving box: around ``joints`` with the margin, or around the largest
        component of the room's coarse hull (None: nobody there)."""
        p = self.params
        if joints is not None and np.isfinite(joints).all():
            lo, hi = joints.min(axis=0) - p.margin, joints.max(axis=0) + p.margin
        else:
            people = coarse_people(small[views], self._K[views], self._R[views],
                                   self._t[views], self._D[views], self._room,
                                   coarse_voxel=p.coarse_voxel, min_views=min(2, len(views)))
            if not people:
                return None
            centre = max(people, key=lambda c: c[0])[2]
            half = np.array([0.8, 0.0, 0.8])
            lo, hi = centre - half, centre + half
            lo[1], hi[1] = 0.0, 2.3
        lo = np.array(lo, dtype=np.float64)
        lo[1] = max(lo[1], 0.0)
        return lo, np.asarray(hi, dtype=np.float64)

    def detect(self, masks: Sequence[np.ndarray | None], maps: Sequence[np.ndarray | None],
               joints: np.ndarray | None = None) -> SkinCandidates:
        """Candidates of one frame set.

        masks: per camera (H, W) foreground at the cameras' resolution or None; maps: per
        camera skin map (any resolution) or None; joints: (J, 3) the last skeleton (the
        carving box and the bodies' centre), or None.
        """
        p = self.params
        small, ok = self._small_masks(masks)
        have_map = np.array([m is not None for m in maps]) & ok
        if ok.sum() < 2 or not have_map.any():
            return SkinCandidates.empty()
        views = np.flatnonzero(ok)
        box = self._box(small, views, joints)
        if box is None:
            return SkinCandidates.empty()
        lo, hi = box
        axes = [np.arange(a, b + p.voxel, p.voxel) for a, b in zip(lo, hi)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
        shape = grid.shape[:3]
        occ = carve(small[views], self._K[views], self._R[views], self._t[views],
                    self._D[views], grid.reshape(-1, 3), min_views=min(2, len(views)),
                    max_misses=0).reshape(shape)
        occ = _largest_component(occ)
        if occ is None:
            return SkinCandidates.empty()
        pts, normals = surface_points(occ, lo, p.voxel)
        proj = project_points(self.cameras, pts)
        eta = visibility(pts, normals, self.cameras, p.voxel, p.depth_tolerance, ok, proj)
        prob = extremity_probability(pts, eta, self.cameras,
                                     [m if h else None for m, h in zip(maps, have_map)], proj)
        centre = (joints.mean(axis=0) if joints is not None and np.isfinite(joints).all()
                  else pts.mean(axis=0))
        cand, cand_n, scores = cluster_candidates(pts, normals, prob, centre, p)
        return SkinCandidates(cand, cand_n, scores, pts, prob)


def _largest_component(occ: np.ndarray) -> np.ndarray | None:
    labels, n = ndimage.label(occ, structure=np.ones((3, 3, 3), bool))
    if n == 0:
        return None
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    return labels == int(np.argmax(sizes))
