"""The whole calibration from corner observations: initialisation, bundle adjustment and
the room frame, as one call (:func:`calibrate_rig`) that ``hmocap calibrate`` and the tests use."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from hmocap_ros.calibration.bundle_adjustment import BundleResult, bundle_adjust
from hmocap_ros.calibration.initialisation import chain_cameras, initial_board_poses, view_poses
from hmocap_ros.calibration.observations import Observations
from hmocap_ros.calibration.room_frame import room_from_camera, room_from_floor_board
from hmocap_ros.geometry.rotations import compose, invert

__all__ = ["CalibrationError", "RigSolution", "calibrate_rig"]


class CalibrationError(ValueError):
    """The session cannot give a rig; the message says why in one line."""


@dataclass(frozen=True, eq=False)
class RigSolution:
    """Cameras kept (indices into the session's cameras), their world (room) -> camera
    ``R (k, 3, 3), t (k, 3)``, intrinsics ``K (k, 3, 3), D (k, 5)``, board poses in the room,
    the bundle adjustment, the tree edges and the cameras left out with the reason."""

    cameras: list
    R: np.ndarray
    t: np.ndarray
    K: np.ndarray
    D: np.ndarray
    R_board: np.ndarray
    t_board: np.ndarray
    bundle: BundleResult
    edges: list
    left_out: dict


def calibrate_rig(obs: Observations, corner_points: np.ndarray, K: np.ndarray, D: np.ndarray,
                  names: list, floor_pose: int | None = None, room_camera: int | None = None,
                  refine_intrinsics: bool = False,
                  log: Callable[[str], None] = lambda line: None) -> RigSolution:
    """Camera poses in the room from the observations (module docstring); ``floor_pose`` is
    the board pose lying on the floor, one pose for all the images of it so that every
    camera's corners in every one of them constrain it (room frame from it), else
    ``room_camera`` gives the room frame."""
    D = np.pad(np.asarray(D, float), ((0, 0), (0, 5)))[:, :5]
    poses = view_poses(obs, corner_points, K, D)
    cams, ref, edges = chain_cameras(poses, obs.n_cameras)
    for a, b, shared in edges:
        log(f"  {names[b]} placed from {names[a]} ({shared} shared board poses)")
    left_out = {c: ("no board pose shared with the other cameras" if any(k[0] == c for k in poses)
                    else "never sees the board") for c in range(obs.n_cameras) if cams[c] is None}
    kept = [c for c in range(obs.n_cameras) if cams[c] is not None]
    if len(kept) < 2:
        raise CalibrationError(f"only {len(kept)} camera(s) can be placed "
                               f"({', '.join(names[c] for c in kept) or 'none'}); a rig needs 2")
    R_board, t_board, placed = initial_board_poses(poses, cams, obs)
    keep = np.isin(obs.camera, kept) & placed[obs.pose]
    remap_cam = np.full(obs.n_cameras, -1)
    remap_cam[kept] = np.arange(len(kept))
    used_poses = np.flatnonzero(placed)
    remap_pose = np.full(obs.n_poses, -1)
    remap_pose[used_poses] = np.arange(len(used_poses))
    sub = obs.subset(keep)
    sub = Observations(remap_cam[sub.camera], remap_pose[sub.pose], sub.corner, sub.pixels,
                       len(kept), len(used_poses))
    R0 = np.stack([cams[c][0] for c in kept])
    t0 = np.stack([cams[c][1] for c in kept])
    log(f"bundle adjustment: {len(kept)} cameras, {len(used_poses)} board poses, "
        f"{len(sub.camera)} corners")
    bundle = bundle_adjust(sub, corner_points, int(remap_cam[ref]), R0, t0, R_board[used_poses],
                           t_board[used_poses], K[kept], D[kept], refine_intrinsics=refine_intrinsics)
    rms = np.sqrt(np.mean(np.sum(bundle.residuals ** 2, axis=1)))
    log(f"  RMS {rms:.3f} px, {bundle.n_dropped} corners dropped as outliers")
    if floor_pose is not None:
        if not placed[floor_pose]:
            raise CalibrationError("no placed camera sees the board lying on the floor; "
                                   "choose a camera for the room frame (--room-frame CAMERA)")
        f = int(remap_pose[floor_pose])
        R_room, t_room = room_from_floor_board(bundle.R_board[f], bundle.t_board[f])
    else:
        if room_camera is None or room_camera not in kept:
            raise CalibrationError("the room frame needs the board on the floor or a placed camera")
        k = int(remap_cam[room_camera])
        R_room, t_room = room_from_camera(bundle.R_cam[k], bundle.t_cam[k])
    R_world = invert(R_room, t_room)  # room -> world
    R, t = compose(bundle.R_cam, bundle.t_cam, *R_world)
    Rb, tb = compose(R_room, t_room, bundle.R_board, bundle.t_board)
    return RigSolution(kept, R, t, bundle.K, bundle.D, Rb, tb, bundle, edges, left_out)
