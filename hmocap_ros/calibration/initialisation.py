"""First estimates for the bundle adjustment: intrinsics, board pose per view, camera poses.

1. Intrinsics per camera are given (camera_info) or estimated with ``cv2.calibrateCamera``
   (Zhang's method) on up to 40 of the camera's board views, spread over the session.
2. Each view (a camera seeing a board pose) gives the board's pose in that camera by
   ``cv2.solvePnP`` (IPPE for planar targets, then Levenberg-Marquardt).
3. Cameras are chained along a maximum spanning tree of the graph whose edge weights are the
   numbers of board poses two cameras share, rooted at the camera with the most views; each
   edge's relative pose is the robust mean over its shared views (chordal rotation mean and
   median translation after dropping views whose rotation disagrees by more than 3 medians).
4. Each board pose is placed in the reference camera's frame through the camera that sees
   the most of its corners.
"""

from __future__ import annotations

import cv2
import numpy as np

from hmocap_ros.calibration.observations import Observations
from hmocap_ros.geometry.rotations import compose, invert, mean_rotation, rotation_angle_deg

__all__ = ["estimate_intrinsics", "view_poses", "chain_cameras", "initial_board_poses"]


def estimate_intrinsics(corner_points: np.ndarray, views: list, size: tuple[int, int],
                        max_views: int = 40) -> tuple[np.ndarray, np.ndarray, float]:
    """``(K, D (5,), rms px)`` of one camera from its views ``[(ids, pixels), ...]`` of the
    board; ``size`` = (width, height). Needs at least 4 views of 8 corners."""
    usable = [v for v in views if len(v[0]) >= 8]
    if len(usable) < 4:
        raise ValueError(f"{len(usable)} views with 8 corners or more; estimating intrinsics needs 4")
    pick = np.unique(np.linspace(0, len(usable) - 1, min(max_views, len(usable))).round().astype(int))
    obj = [corner_points[usable[i][0]].astype(np.float32) for i in pick]
    img = [usable[i][1].astype(np.float32).reshape(-1, 1, 2) for i in pick]
    w, h = size
    f0 = 0.8 * w
    K0 = np.array([[f0, 0, (w - 1) / 2], [0, f0, (h - 1) / 2], [0, 0, 1]])
    rms, K, D, _, _ = cv2.calibrateCamera(obj, img, (w, h), K0, np.zeros(5),
                                          flags=cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_K3)
    return K, D.ravel()[:5], float(rms)


def view_poses(obs: Observations, corner_points: np.ndarray, K: np.ndarray, D: np.ndarray) -> dict:
    """``{(camera, pose): (R, t)}`` board -> camera for every view with 6 corners or more."""
    poses = {}
    for (c, p), rows in obs.views().items():
        if len(rows) < 6:
            continue
        obj = corner_points[obs.corner[rows]].astype(np.float64)
        img = obs.pixels[rows].astype(np.float64)
        ok, rvec, tvec = cv2.solvePnP(obj, img, K[c], D[c], flags=cv2.SOLVEPNP_IPPE)
        if not ok:
            continue
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, K[c], D[c], rvec, tvec)
        poses[(c, p)] = (cv2.Rodrigues(rvec)[0], tvec.ravel())
    return poses


def _relative(pairs: list) -> tuple[np.ndarray, np.ndarray]:
    """Robust mean of relative poses ``[(R, t), ...]``."""
    R = np.stack([r for r, _ in pairs])
    t = np.stack([t for _, t in pairs])
    mean = mean_rotation(R)
    angle = rotation_angle_deg(R, mean[None])
    keep = angle <= max(3.0 * np.median(angle), 0.5)
    return mean_rotation(R[keep]), np.median(t[keep], axis=0)


def chain_cameras(poses: dict, n_cameras: int) -> tuple[list, int, list]:
    """World -> camera ``(R, t)`` per camera in the reference camera's frame (None for a camera
    the tree does not reach), the reference camera and the tree's edges
    ``(parent, child, shared views)``."""
    seen = [{p for (c, p) in poses if c == k} for k in range(n_cameras)]
    ref = int(np.argmax([len(s) for s in seen]))
    cams: list = [None] * n_cameras
    cams[ref] = (np.eye(3), np.zeros(3))
    edges = []
    while True:
        best = None
        for a in range(n_cameras):
            if cams[a] is None:
                continue
            for b in range(n_cameras):
                if cams[b] is None:
                    shared = len(seen[a] & seen[b])
                    if shared and (best is None or shared > best[2]):
                        best = (a, b, shared)
        if best is None:
            break
        a, b, shared = best
        rel = []
        for p in sorted(seen[a] & seen[b]):
            Ra, ta = poses[(a, p)]
            Rb, tb = poses[(b, p)]
            rel.append(compose(Rb, tb, *invert(Ra, ta)))  # camera a -> camera b
        R_ba, t_ba = _relative(rel)
        cams[b] = compose(R_ba, t_ba, *cams[a])
        edges.append(best)
    return cams, ref, edges


def initial_board_poses(poses: dict, cams: list, obs: Observations) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Board -> reference frame ``R (P, 3, 3), t (P, 3)`` and whether each pose was placed."""
    counts = obs.views()
    R = np.repeat(np.eye(3)[None], obs.n_poses, axis=0)
    t = np.zeros((obs.n_poses, 3))
    placed = np.zeros(obs.n_poses, bool)
    best = np.zeros(obs.n_poses, int)
    for (c, p), (Rv, tv) in poses.items():
        if cams[c] is None or len(counts[(c, p)]) <= best[p]:
            continue
        best[p] = len(counts[(c, p)])
        R[p], t[p] = compose(*invert(*cams[c]), Rv, tv)
        placed[p] = True
    return R, t, placed
