"""The room frame (metres, +Y up, floor y = 0) of a calibrated rig, from the board lying on
the floor or from a chosen camera.

Board on the floor, printed face up: its plane is the floor (y = 0), its origin (the outer
corner next to the first square) is the room origin, its x axis is room +x and its y axis room
+z; the board's z axis (away from the printed face) is then room -Y:
``x_room = FLOOR_ROTATION @ x_board``.

A chosen camera: its centre is the origin, its image right is +x, its image up is +Y (a
camera mounted level) and +z points backwards out of the lens.
"""

from __future__ import annotations

import numpy as np

from hmocap_ros.geometry.rotations import compose, invert

__all__ = ["FLOOR_ROTATION", "CAMERA_TO_ROOM", "room_from_floor_board", "room_from_camera"]

#: Board -> room rotation of the board lying on the floor with its printed face up.
FLOOR_ROTATION = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
#: Optical frame (x right, y down, z forward) -> room axes for a chosen camera.
CAMERA_TO_ROOM = np.diag([1.0, -1.0, -1.0])


def room_from_floor_board(R_board: np.ndarray, t_board: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` of ``x_room = R x + t`` from the frame where the floor board has pose
    ``x = R_board x_board + t_board``."""
    R_inv, t_inv = invert(R_board, t_board)
    return compose(FLOOR_ROTATION, np.zeros(3), R_inv, t_inv)


def room_from_camera(R_cam: np.ndarray, t_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(R, t)`` of ``x_room = R x + t`` from the frame where the camera's world->camera
    transform is ``(R_cam, t_cam)``."""
    return compose(CAMERA_TO_ROOM, np.zeros(3), R_cam, t_cam)
