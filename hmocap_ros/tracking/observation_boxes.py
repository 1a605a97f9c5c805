"""Approximate partitioning of observations by variable bounding boxes (thesis sec. 2.4.1).

For the hierarchical layer ``l`` (a block of DoFs), the hidden variables ``Omega_{t,l,v}`` of
eq. 2.15 are 1 inside one 2D box per view and 0 elsewhere. Following the thesis' three steps:

1. the pose of the parent layers, already filtered: the mean of the particle set that layer
   ``l`` is about to weigh. That set is the output of layer ``l - 1``'s layered resampling
   (alg. 4) and of the kernel that diffused block ``l`` (see :mod:`.body_layers`), so its
   unweighted mean is the thesis' weighted mean ``sum_i pi_{l-1}^i x_{l-1}^i`` of the
   filtered parents, with block ``l`` at its prediction. From it, the 3D position of the
   layer's joint ``mu_{Y_l}``;
2. a 3D box centred there "with fixed sizes proportional to the estimated anthropometric
   sizes of parts involved": for a limb layer the box is centred at the joint the block
   rotates (hip, shoulder, elbow; :data:`LAYER_ANCHORS`) and its half-size is the length of
   the chain it moves (thigh + shin + foot, upper arm + forearm + hand, forearm + hand) of
   the estimated body shape, times ``reach`` (:func:`reach_box`): the box holds every
   position the limb can take, so a limb the previous frame lost (an arm left hidden against
   the torso while the real one rose) still sees its true pixels. The torso layer moves the
   whole body; its box is that of the torso and head vertices (:data:`LAYER_PARTS`) of the
   mean pose, widened by ``spread`` standard deviations of their positions over the particles
   (the root's motion) (:func:`part_boxes_3d`); every box gets ``margin`` metres more;
3. per view, the 2D box enclosing the 8 projected corners (plus one pixel).

The cost inside the boxes is ``sum_v XOR_v(Omega) / |Omega_v|`` (eq. 2.15); the final
whole-body re-weighting layer uses the whole images (eq. 2.8).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from hmocap_ros.geometry.distortion import coefficients8, monotonic_radius2
from hmocap_ros.geometry.projection import project_one_view

__all__ = ["BOX_MARGIN", "BOX_REACH", "BOX_SPREAD", "LAYER_ANCHORS", "LAYER_PARTS",
           "box_corners", "chain_lengths", "layer_boxes", "layer_vertex_indices",
           "part_boxes_3d", "reach_box"]

#: The boxes of the tracker's layers (eq. 2.15 leaves their size open): a limb layer's box
#: reaches BOX_REACH times the length of the chain it moves around the joint it rotates, so
#: that any pose the layer's particles try stays inside; the torso's spans BOX_SPREAD standard
#: deviations of the particles' part positions around the mean part; both with a BOX_MARGIN
#: (m) for the silhouettes' blur at the working resolution.
BOX_REACH, BOX_SPREAD, BOX_MARGIN = 1.05, 2.0, 0.05

LAYER_PARTS = {
    "torso": ("pelvis", "spine", "chest", "neck", "head", "l_clavicle", "r_clavicle"),
    "l_leg": ("l_hip", "l_knee", "l_ankle"),
    "r_leg": ("r_hip", "r_knee", "r_ankle"),
    "l_shoulder": ("l_shoulder", "l_elbow", "l_wrist"),
    "r_shoulder": ("r_shoulder", "r_elbow", "r_wrist"),
    "l_elbow": ("l_elbow", "l_wrist"),
    "r_elbow": ("r_elbow", "r_wrist"),
}


#: Limb layers: (the joint the block rotates, the chain of joints / end sites it moves).
LAYER_ANCHORS = {
    "l_leg": ("l_hip", ("l_knee", "l_ankle", "l_toe")),
    "r_leg": ("r_hip", ("r_knee", "r_ankle", "r_toe")),
    "l_shoulder": ("l_shoulder", ("l_elbow", "l_wrist", "l_hand_tip")),
    "r_shoulder": ("r_shoulder", ("r_elbow", "r_wrist", "r_hand_tip")),
    "l_elbow": ("l_elbow", ("l_wrist", "l_hand_tip")),
    "r_elbow": ("r_elbow", ("r_wrist", "r_hand_tip")),
}


def chain_lengths(model, rest) -> dict:
    """Length (m) of the chain each limb layer moves, on a shaped rest skeleton ``rest``
    (``ShapedRest`` of one shape): ``{block: length}``."""
    joints = np.asarray(rest.joints)
    ends = np.asarray(rest.end_sites)
    names = list(map(str, model.joint_names))
    end_names = list(map(str, model.end_site_names))

    def point(name):
        return joints[names.index(name)] if name in names else ends[end_names.index(name)]

    out = {}
    for block, (anchor, chain) in LAYER_ANCHORS.items():
        pts = [point(anchor)] + [point(n) for n in chain]
        out[block] = float(sum(np.linalg.norm(b - a) for a, b in zip(pts[:-1], pts[1:])))
    return out


def reach_box(anchor: np.ndarray, length: float, reach: float = 1.05,
              margin: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """3D box ``(lo, hi)`` centred at ``anchor`` with half-size ``reach * length + margin``."""
    half = reach * length + margin
    return anchor - half, anchor + half


def layer_vertex_indices(model, blocks) -> np.ndarray:
    """Indices of the mesh vertices whose body part belongs to any of ``blocks``."""
    joints = [model.joint_index(j) for b in blocks for j in LAYER_PARTS[b]]
    return np.flatnonzero(np.isin(np.asarray(model.vertex_part), joints))


def part_boxes_3d(verts: np.ndarray, index: np.ndarray, spread: float = 2.0,
                  margin: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """3D box ``(lo (3,), hi (3,))`` of the part vertices ``index`` of a particle set.

    verts: posed vertices (N, V, 3) of the particles about to be weighed. The box spans the
    particle-mean part vertices, each widened by ``spread`` standard deviations over the
    particles, plus ``margin`` metres on every side.
    """
    part = np.asarray(verts[:, index], dtype=np.float64)  # (N, P, 3)
    mean = part.mean(axis=0)
    std = part.std(axis=0) if part.shape[0] > 1 else np.zeros_like(mean)
    lo = (mean - spread * std).min(axis=0) - margin
    hi = (mean + spread * std).max(axis=0) + margin
    return lo, hi


def box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The 8 corners (8, 3) of an axis-aligned box."""
    sel = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    return np.where(sel == 0, lo, hi)


@lru_cache(maxsize=64)
def _valid_r2(dist: tuple) -> float:
    return monotonic_radius2(coefficients8(np.array(dist, dtype=np.float64)))


def layer_boxes(lo: np.ndarray, hi: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray,
                D: np.ndarray, width: int, height: int, pad_px: float = 1.0) -> np.ndarray:
    """2D boxes (M, 4) ``[x0, y0, x1, y1)`` enclosing the projected 3D box in each view.

    A box whose corners cannot all be projected (a corner behind a camera) is the whole
    image, so the layer never loses that view's evidence by accident.
    """
    corners = box_corners(lo, hi)
    d8 = np.zeros((len(K), 8))
    d8[:, :np.shape(D)[1]] = D
    uv = np.empty((len(K), 8, 2), dtype=np.float32)
    z = np.empty(8, dtype=np.float32)
    for m in range(len(K)):  # 8 points: a serial call beats waking the thread pool
        project_one_view(corners, np.asarray(K[m], np.float64), np.asarray(R[m], np.float64),
                     np.asarray(t[m], np.float64), d8[m], 1e-3, _valid_r2(tuple(d8[m])), uv[m], z)
    uv = uv.astype(np.float64)  # (M, 8, 2)
    boxes = np.empty((uv.shape[0], 4))
    ok = np.isfinite(uv).all(axis=(1, 2))
    boxes[:, 0] = np.where(ok, np.nanmin(uv[..., 0], axis=1, initial=np.inf) - pad_px, 0)
    boxes[:, 1] = np.where(ok, np.nanmin(uv[..., 1], axis=1, initial=np.inf) - pad_px, 0)
    boxes[:, 2] = np.where(ok, np.nanmax(uv[..., 0], axis=1, initial=-np.inf) + 1 + pad_px, width)
    boxes[:, 3] = np.where(ok, np.nanmax(uv[..., 1], axis=1, initial=-np.inf) + 1 + pad_px, height)
    boxes[:, 0::2] = np.clip(boxes[:, 0::2], 0, width)
    boxes[:, 1::2] = np.clip(boxes[:, 1::2], 0, height)
    return boxes
