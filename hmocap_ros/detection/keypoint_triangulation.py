"""Labelled 3D keypoints from the landmarks of several calibrated views, robust to wrong views.

Each view's network (:mod:`.keypoint_network`) sees the person alone and can be wrong: a hand
raised near the face, a limb hidden by the body, a person seen from behind with the sides
swapped. The views are weighed, checked against each other and against the silhouette, and
a keypoint is triangulated from the views that agree:

1. **Per-view points** (:func:`view_keypoints`): each label of :data:`KEYPOINT_LABELS`, and the
   nose and ears that orient the head, is the mean of its landmarks' pixels
   (:data:`COMPOSITION`), weighted by the smallest visibility times presence of those landmarks,
   times the view's pose presence score. A point farther than ``mask_tolerance_px`` from the view's
   foreground has its weight multiplied by ``outside_mask_weight``; one whose weight is below
   ``min_visibility`` is not used, and a view whose pose presence is below ``min_pose_score``
   is not used at all. The pixels are then undistorted once: the DLT and the reprojection
   errors below work in the ideal (distortion-free) images.
2. **Left/right per view** (:func:`resolve_swaps`): for the arm and the leg labels separately,
   every assignment of "as labelled" or "sides swapped" to the available views (the first one
   fixed: swapping all views only renames the sides) is scored by the consensus of step 3,
   summed over the group's labels, less ``swap_margin`` times the weight it renames; the best
   one is kept. Which of it and its mirror (every view flipped) names the sides right is
   decided by the previous skeleton when given (the one nearer to it), else by the views'
   vote (the one that renames less weight). The ears follow the arms.
3. **Consensus per point** (:func:`robust_points`), RANSAC over view pairs (4 to 6 views give
   6 to 15 pairs, all tried): every pair's DLT point is scored MSAC-like over all views,
   ``sum_v w_v max(0, 1 - (e_v / tau)^2)`` with ``e_v`` the reprojection error in pixels and
   ``tau = max_reprojection_px``; the views that agree with the best pair's point
   (``e_v < tau``, in front of the camera) are triangulated together, twice, and the final
   point is the DLT of the views that agree with it: only those of weight
   ``confident_visibility`` or more when there are ``min_views`` of them. Triangulation is
   :func:`hmocap_ros.geometry.triangulate`.
4. **Body points** (design choices where the thesis, sec. 2.5, leaves the detector open; each
   matches the end-effector or joint of the tracker's body model, measured on simulated
   recordings): ``hand`` is the mean of the index and pinky landmarks (the knuckles: the
   tracker's hand end-effector is the midpoint of wrist and hand tip); ``foot`` is the foot
   index landmark (the tracker's foot end-effector is the toe); ``head`` is the head's centre,
   the ears' midpoint moved by :data:`HEAD_OFFSET` in the head's frame (forward: towards the
   nose across the ears' axis; up: perpendicular to both, pointing up in the room), where the
   tracker's head end-effector (midpoint of head joint and head top) lies; the hips are moved
   apart by :data:`HIP_WIDENING` each (BlazePose's hip landmarks lie inside the model's hip
   joints). The other joints are their landmarks.

Confidence (``Keypoints3D.scores``): ``support * consensus`` with ``support = 1 - prod_v (1 -
c_v)`` over the views used, ``c_v = w_v (1 - (e_v / tau)^2)`` (two clear views agreeing to a
pixel give about 0.99), and ``consensus = sum_used w_v / sum_usable w_v`` (the share of the
usable views' weight that agrees: two agreeing views against two other confident views halve
it). Keypoints below ``min_score`` are not reported.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from itertools import combinations, product
from typing import Sequence

import numpy as np

from hmocap_ros.detection.keypoint_network import NUM_LANDMARKS, ViewLandmarks
from hmocap_ros.geometry import ROOM_UP, project_points, reprojection_errors, triangulate

__all__ = ["KEYPOINT_LABELS", "COMPOSITION", "MIRROR", "TRIANGULATED_POINTS", "Keypoints3D", "view_keypoints",
           "robust_points", "resolve_swaps", "triangulate_views", "near_foreground"]

#: Labels of the 3D keypoints (the subject's left and right), the message terms.
KEYPOINT_LABELS = (
    "head", "left_hand", "right_hand", "left_foot", "right_foot",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
    "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
)
#: Network landmarks (indices of ``keypoint_network.LANDMARK_NAMES``) averaged in each view
#: into the point triangulated for a label (``head`` is then moved to the head's centre).
COMPOSITION = {
    "head": (7, 8), "left_hand": (17, 19), "right_hand": (18, 20),
    "left_foot": (31,), "right_foot": (32,), "left_shoulder": (11,), "right_shoulder": (12,),
    "left_elbow": (13,), "right_elbow": (14,), "left_wrist": (15,), "right_wrist": (16,),
    "left_hip": (23,), "right_hip": (24,), "left_knee": (25,), "right_knee": (26,),
    "left_ankle": (27,), "right_ankle": (28,),
}
#: The head's centre from the ears' midpoint, metres along the head's forward axis (towards
#: the nose, across the ears' axis) and its up axis: where the body model's head end-effector
#: (midpoint of head joint and head top) lies from BlazePose's ears.
HEAD_OFFSET = (-0.078, 0.040)
#: Metres each hip point moves outwards along the hips' axis: BlazePose's hip landmarks lie
#: inside the body model's hip joints.
HIP_WIDENING = 0.03
#: a view whose landmarks agree with the triangulated points on fewer than this share of the
#: points it has is reported as left out (a view of another person, a wrong crop)
LEFT_OUT_SHARE = 0.25
#: points triangulated besides the labels, to orient the head
_AUXILIARY = {"nose": (0,), "left_ear": (7,), "right_ear": (8,)}
#: the labels of the points :func:`view_keypoints` and :func:`robust_points` work on: the
#: reported labels, then the auxiliary ones
TRIANGULATED_POINTS = KEYPOINT_LABELS + tuple(_AUXILIARY)
_COMPONENTS = {**COMPOSITION, **_AUXILIARY}


def _mirror(label: str) -> str:
    if label.startswith("left_"):
        return "right_" + label[5:]
    if label.startswith("right_"):
        return "left_" + label[6:]
    return label


#: Index of each point's other side (itself for ``head`` and ``nose``), over the labels and the
#: auxiliary points.
MIRROR = np.array([TRIANGULATED_POINTS.index(_mirror(label)) for label in TRIANGULATED_POINTS])
_ARMS = np.array([KEYPOINT_LABELS.index(f"{s}_{p}") for p in ("hand", "shoulder", "elbow", "wrist")
                  for s in ("left", "right")])
_LEGS = np.array([KEYPOINT_LABELS.index(f"{s}_{p}") for p in ("foot", "hip", "knee", "ankle")
                  for s in ("left", "right")])
_ARMS_AND_EARS = np.concatenate(
    [_ARMS, [TRIANGULATED_POINTS.index("left_ear"), TRIANGULATED_POINTS.index("right_ear")]])
_MATRIX = np.zeros((len(TRIANGULATED_POINTS), NUM_LANDMARKS))
for _k, _label in enumerate(TRIANGULATED_POINTS):
    _MATRIX[_k, list(_COMPONENTS[_label])] = 1.0 / len(_COMPONENTS[_label])
_USES = _MATRIX > 0


def _head_centre(points: np.ndarray) -> np.ndarray:
    """The head's centre from the triangulated ears' midpoint, ears and nose (:data:`HEAD_OFFSET`
    in the head's frame: up is the sign of forward x ears' axis that points up in the room);
    without the nose or an ear, the up offset along the room's up axis."""
    up = np.asarray(ROOM_UP)
    head, nose = points[TRIANGULATED_POINTS.index("head")], points[TRIANGULATED_POINTS.index("nose")]
    across = points[TRIANGULATED_POINTS.index("left_ear")] - points[TRIANGULATED_POINTS.index("right_ear")]
    forward = nose - head
    if np.all(np.isfinite(across) & np.isfinite(forward)) and np.linalg.norm(across) > 1e-3:
        across = across / np.linalg.norm(across)
        forward = forward - (forward @ across) * across
        if np.linalg.norm(forward) > 1e-3:
            forward = forward / np.linalg.norm(forward)
            head_up = np.cross(forward, across)
            head_up = head_up if head_up @ up >= 0 else -head_up
            return head + HEAD_OFFSET[0] * forward + HEAD_OFFSET[1] * head_up
    return head + HEAD_OFFSET[1] * up


def _body_points(points: np.ndarray) -> np.ndarray:
    """The labels' positions ``(K, 3)`` from the triangulated points: the head moved to its
    centre, the hips widened (:data:`HIP_WIDENING`)."""
    out = points[:len(KEYPOINT_LABELS)].copy()
    if np.all(np.isfinite(out[0])):
        out[0] = _head_centre(points)
    left, right = KEYPOINT_LABELS.index("left_hip"), KEYPOINT_LABELS.index("right_hip")
    across = out[left] - out[right]
    width = np.linalg.norm(across)
    if np.isfinite(width) and width > 1e-3:
        out[left] += HIP_WIDENING * across / width
        out[right] -= HIP_WIDENING * across / width
    return out


@dataclass(frozen=True, eq=False)
class Keypoints3D:
    """Labelled 3D keypoints of one frame set (the labels that could be triangulated).

    labels: subset of :data:`KEYPOINT_LABELS`, in its order; positions: (K, 3) room frame,
    metres; scores: (K,) confidence in [0, 1] (module docstring); views_used: (K,) the number
    of views the point was triangulated from; views_left_out: the views (camera indices) whose
    landmarks disagree with the other views on nearly every point (:data:`LEFT_OUT_SHARE`),
    left out of this frame set.
    """

    labels: tuple[str, ...]
    positions: np.ndarray
    scores: np.ndarray
    views_used: np.ndarray
    views_left_out: tuple = ()

    def as_dict(self) -> dict[str, np.ndarray]:
        """``{label: (3,) position}``, the form :func:`triangulate_views` takes as ``previous``."""
        return {label: self.positions[k] for k, label in enumerate(self.labels)}

    @classmethod
    def empty(cls) -> "Keypoints3D":
        return cls((), np.zeros((0, 3)), np.zeros(0), np.zeros(0, dtype=int))


def near_foreground(mask: np.ndarray, pixels: np.ndarray, width: int, height: int,
                     tolerance_px: float) -> np.ndarray:
    """(K,) bool: a foreground pixel of ``mask`` (uint8, any resolution: scaled to the image)
    lies within ``tolerance_px`` (full-image pixels, Chebyshev distance) of each pixel
    ``(K, 2)``: a window of the mask is gathered around every pixel."""
    mh, mw = mask.shape[:2]
    sx, sy = mw / width, mh / height
    radius = int(np.ceil(tolerance_px * max(sx, sy)))
    col = np.rint(sx * (pixels[:, 0] + 0.5) - 0.5)
    row = np.rint(sy * (pixels[:, 1] + 0.5) - 0.5)
    finite = np.isfinite(col) & np.isfinite(row)
    offsets = np.arange(-radius, radius + 1)
    cols = np.where(finite, col, -radius - 1)[:, None] + offsets  # (K, w)
    rows = np.where(finite, row, -radius - 1)[:, None] + offsets
    ci = np.clip(cols, 0, mw - 1).astype(np.intp)
    ri = np.clip(rows, 0, mh - 1).astype(np.intp)
    window = mask[ri[:, :, None], ci[:, None, :]] > 0  # (K, w, w)
    window &= ((rows >= 0) & (rows < mh))[:, :, None] & ((cols >= 0) & (cols < mw))[:, None, :]
    return finite & window.any(axis=(1, 2))


def _ideal(camera):
    """The camera without lens distortion (its pixels: :meth:`undistort_pixels`)."""
    return dataclasses.replace(camera, D=np.zeros(5), distortion_model="plumb_bob")


def view_keypoints(cameras, views: Sequence[ViewLandmarks | None],
                   masks: Sequence[np.ndarray | None] | None,
                   params) -> tuple[np.ndarray, np.ndarray]:
    """Per-view pixels ``(V, P, 2)`` (NaN: no view) and weights ``(V, P)`` (0: unused) of the
    labels and the auxiliary points (nose, ears), step 1 of the module docstring."""
    n_views, n_labels = len(cameras), len(TRIANGULATED_POINTS)
    pixels = np.full((n_views, n_labels, 2), np.nan)
    weights = np.zeros((n_views, n_labels))
    for v, (camera, view) in enumerate(zip(cameras, views)):
        if view is None or view.score < params.min_pose_score:
            continue
        pixels[v] = _MATRIX @ view.xy
        confidence = view.visibility * view.presence
        weights[v] = np.where(_USES, confidence[None, :], np.inf).min(axis=1) * view.score
        mask = None if masks is None else masks[v]
        if mask is not None:
            near = near_foreground(mask, pixels[v], camera.width, camera.height,
                                    params.mask_tolerance_px)
            weights[v] = np.where(near, weights[v], weights[v] * params.outside_mask_weight)
    weights[(weights < params.min_visibility) | ~np.isfinite(pixels).all(axis=-1)] = 0.0
    return pixels, weights


def _msac(cameras, points, pixels, weights, tau):
    """Reprojection errors ``(V, N)`` (inf where unusable or behind the camera) and the MSAC
    score ``(N,)`` of points ``(N, 3)``."""
    finite = np.isfinite(points).all(axis=1)
    errors = reprojection_errors(cameras, points, pixels)
    depth = project_points(cameras, np.where(finite[:, None], points, 0.0)).depth
    errors = np.where((weights > 0) & (depth > 0) & np.isfinite(errors), errors, np.inf)
    score = (weights * np.clip(1.0 - (errors / tau) ** 2, 0.0, None)).sum(axis=0)
    return errors, np.where(finite, score, -np.inf)


def _best_pairs(cameras, pixels, weights, tau):
    """The best view-pair hypothesis of each point: ``(points (N, 3), score (N,))``."""
    n_views, n = weights.shape
    pairs = list(combinations(range(n_views), 2))
    if not pairs or n == 0:
        return np.full((n, 3), np.nan), np.full(n, -np.inf)
    use = np.zeros((n_views, len(pairs), n), dtype=bool)
    for p, (a, b) in enumerate(pairs):
        use[[a, b], p] = weights[[a, b]] > 0
    tiled = np.broadcast_to(pixels[:, None], (n_views, len(pairs), n, 2)).reshape(n_views, -1, 2)
    points = triangulate(cameras, tiled, use.reshape(n_views, -1))
    _, score = _msac(cameras, points, tiled,
                     np.broadcast_to(weights[:, None], use.shape).reshape(n_views, -1), tau)
    score = score.reshape(len(pairs), n)
    best = np.argmax(score, axis=0)
    points = points.reshape(len(pairs), n, 3)[best, np.arange(n)]
    return points, score[best, np.arange(n)]


def robust_points(cameras, pixels: np.ndarray, weights: np.ndarray, tau: float,
                  min_views: int = 2, confident: float = 0.0):
    """Step 3 of the module docstring for N points: pixels ``(V, N, 2)``, weights ``(V, N)``.

    Of the agreeing views, only those with weight >= ``confident`` are triangulated when there
    are ``min_views`` of them (a landmark the network marks hidden is often right, but less
    precise). Returns ``(points (N, 3) NaN where fewer than min_views agree, used (V, N) bool,
    errors (V, N) px)``.
    """
    need = max(2, min_views)

    def chosen(errors):
        agree = errors < tau
        strong = agree & (weights >= confident)
        return np.where(strong.sum(axis=0) >= need, strong, agree)

    points, _ = _best_pairs(cameras, pixels, weights, tau)
    for _ in range(2):
        errors, _ = _msac(cameras, points, pixels, weights, tau)
        points = triangulate(cameras, pixels, chosen(errors), need)
    errors, _ = _msac(cameras, points, pixels, weights, tau)
    used = chosen(errors) & np.isfinite(points).all(axis=1)[None, :]
    points[used.sum(axis=0) < need] = np.nan
    return points, used, errors


def _group_swaps(cameras, pixels, weights, group, available, tau, previous, margin):
    """Per-view swap flags ``(V,)`` of one label group (step 2)."""
    n_views = len(cameras)
    free = available[1:]
    combos = np.zeros((2 ** len(free), n_views), dtype=bool)
    combos[:, free] = np.array(list(product((False, True), repeat=len(free))), dtype=bool)
    swapped = combos[:, :, None]  # (C, V, 1)
    pix = np.where(swapped[..., None], pixels[:, MIRROR][None], pixels[None])[:, :, group]
    wts = np.where(swapped, weights[:, MIRROR][None], weights[None])[:, :, group]
    n_c, n_g = len(combos), len(group)
    points, score = _best_pairs(cameras, pix.transpose(1, 0, 2, 3).reshape(n_views, -1, 2),
                                wts.transpose(1, 0, 2).reshape(n_views, -1), tau)
    total = np.where(np.isfinite(score), score, 0.0).reshape(n_c, n_g).sum(axis=1)
    vote = weights[:, group].sum(axis=1)  # (V,) each view's weight in the group
    swapped_weight = combos @ vote
    total -= margin * np.minimum(swapped_weight, vote[available].sum() - swapped_weight)
    best = int(np.argmax(total))
    flags = combos[best]
    mirror_flags = flags.copy()
    mirror_flags[available] = ~flags[available]
    mine = points.reshape(n_c, n_g, 3)[best]
    position = {int(g): i for i, g in enumerate(group)}
    other = mine[[position[int(m)] for m in MIRROR[group]]]  # the mirror's points: sides renamed
    known = [k for k, label in enumerate(np.array(KEYPOINT_LABELS)[group])
             if previous and label in previous and np.all(np.isfinite(previous[label]))]
    if known:
        target = np.array([previous[KEYPOINT_LABELS[group[k]]] for k in known], dtype=np.float64)
        d_flags = np.nansum(np.linalg.norm(mine[known] - target, axis=1))
        d_mirror = np.nansum(np.linalg.norm(other[known] - target, axis=1))
        return mirror_flags if d_mirror < d_flags else flags
    return mirror_flags if vote[mirror_flags].sum() < vote[flags].sum() else flags


def resolve_swaps(cameras, pixels: np.ndarray, weights: np.ndarray, tau: float,
                  previous: dict[str, np.ndarray] | None = None, margin: float = 0.5):
    """Pixels and weights with each view's sides renamed where step 2 finds them swapped,
    and the swap flags ``(V, 2)`` (arms, legs). The ears follow the arms."""
    available = np.flatnonzero((weights > 0).any(axis=1))
    flags = np.zeros((len(cameras), 2), dtype=bool)
    pixels, weights = pixels.copy(), weights.copy()
    if available.size < 3:  # two views always agree with one of the two assignments
        return pixels, weights, flags
    for g, group in enumerate((_ARMS, _LEGS)):
        flags[:, g] = _group_swaps(cameras, pixels, weights, group, available, tau, previous,
                                   margin)
    for g, group in enumerate((_ARMS_AND_EARS, _LEGS)):
        rows = np.flatnonzero(flags[:, g])
        pixels[rows[:, None], group] = pixels[rows[:, None], MIRROR[group]]
        weights[rows[:, None], group] = weights[rows[:, None], MIRROR[group]]
    return pixels, weights, flags


def triangulate_views(cameras, views: Sequence[ViewLandmarks | None],
                      masks: Sequence[np.ndarray | None] | None = None,
                      previous: dict[str, np.ndarray] | None = None, params=None) -> Keypoints3D:
    """Labelled 3D keypoints of one frame set (module docstring).

    ``cameras``: the rig's cameras; ``views``: per camera its landmarks or None; ``masks``: per
    camera a uint8 foreground mask (any resolution) or None; ``previous``: label -> (3,) room
    position of the last skeleton's keypoints (decides which sides are which);
    ``params``: a :class:`~hmocap_ros.detection.params.KeypointParams` (default:
    its defaults).
    """
    if params is None:
        from hmocap_ros.detection.params import KeypointParams
        params = KeypointParams()
    cameras = list(cameras)
    if len(views) != len(cameras) or (masks is not None and len(masks) != len(cameras)):
        raise ValueError(f"need one view (and mask) per camera: {len(cameras)} cameras, "
                         f"{len(views)} views, {None if masks is None else len(masks)} masks")
    pixels, weights = view_keypoints(cameras, views, masks, params)
    if np.count_nonzero((weights > 0).any(axis=1)) < 2:
        return Keypoints3D.empty()
    # the DLT and the reprojection errors in the undistorted images: undistorted once here
    usable = np.isfinite(pixels).all(axis=-1).all(axis=-1)
    pixels = np.stack([c.undistort_pixels(p) if ok else p
                       for c, p, ok in zip(cameras, pixels, usable)])
    cameras = [_ideal(c) for c in cameras]
    tau = params.max_reprojection_px
    if params.resolve_swaps:
        pixels, weights, _ = resolve_swaps(cameras, pixels, weights, tau, previous,
                                           params.swap_margin)
    points, inliers, errors = robust_points(cameras, pixels, weights, tau, params.min_views,
                                            params.confident_visibility)
    contribution = np.where(inliers, weights * np.clip(1.0 - (errors / tau) ** 2, 0.0, 1.0), 0.0)
    support = 1.0 - np.prod(1.0 - np.clip(contribution, 0.0, 1.0), axis=0)
    total = weights.sum(axis=0)
    agreeing = (weights * inliers).sum(axis=0)
    consensus = np.where(total > 0, agreeing / np.where(total > 0, total, 1.0), 0.0)
    scores = (support * consensus)[:len(KEYPOINT_LABELS)]
    positions = _body_points(points)
    keep = np.isfinite(positions).all(axis=1) & (scores >= params.min_score)
    views_used = inliers.sum(axis=0)[:len(KEYPOINT_LABELS)]
    # a view with landmarks that agree with the triangulated points on almost none of them
    usable = (weights > 0) & np.isfinite(points).all(axis=1)[None, :]
    agreed = (inliers & usable).sum(axis=1)
    left_out = tuple(int(v) for v in np.flatnonzero(
        (usable.sum(axis=1) >= 3) & (agreed < LEFT_OUT_SHARE * usable.sum(axis=1))))
    return Keypoints3D(views_left_out=left_out,
                       labels=tuple(str(n) for n in np.array(KEYPOINT_LABELS)[keep]),
                       positions=positions[keep], scores=scores[keep], views_used=views_used[keep])
