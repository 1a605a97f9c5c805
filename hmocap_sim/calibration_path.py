"""Where the board is during a simulated calibration session: on the floor, then carried.

For the first ``floor_seconds`` the board lies flat on the floor with its origin at the room
origin, its x axis along room +x and its printed face up (board y along room +z, board z =
-Y): the pose that defines the room frame (:mod:`hmocap_ros.calibration.room_frame`). Then a
person carries it through the volume the cameras see on a smooth random path (cubic splines
through random key positions every two seconds), turning it about the vertical so that it
faces every camera in turn, tilted up towards the cameras by 10-45 degrees, with a random roll.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from hmocap_ros.calibration.room_frame import FLOOR_ROTATION

__all__ = ["FLOOR_ROTATION", "board_poses", "board_rotation"]

_CENTRE_LOW = np.array([-1.1, 0.7, -0.9])  # box of the carried board's centre (room, metres)
_CENTRE_HIGH = np.array([1.1, 1.8, 0.9])
_KEY_SECONDS = 2.0
_TURN_SECONDS = 12.0  # one turn about the vertical, at most


def board_rotation(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(N, 3, 3) board -> room rotations whose printed face (board -z) points at azimuth ``yaw``
    (from +x towards +z) and elevation ``pitch``, rolled by ``roll`` about that direction."""
    face = np.stack([np.cos(pitch) * np.cos(yaw), np.sin(pitch), np.cos(pitch) * np.sin(yaw)], -1)
    z = -face
    x = np.cross(np.array([0.0, 1.0, 0.0]), z)
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    y = np.cross(z, x)
    c, s = np.cos(roll)[:, None], np.sin(roll)[:, None]
    x, y = c * x + s * y, -s * x + c * y
    return np.stack([x, y, z], axis=-1)


def board_poses(t: np.ndarray, floor_seconds: float, board_size: tuple[float, float],
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Board -> room rotations (N, 3, 3) and translations (N, 3) (the board origin) at times
    ``t`` (seconds from the start); ``board_size`` is the board's (x, y) extent in metres."""
    t = np.asarray(t, np.float64)
    n = len(t)
    R = np.repeat(FLOOR_ROTATION[None], n, axis=0)
    origin = np.zeros((n, 3))
    carried = t >= floor_seconds
    if not carried.any():
        return R, origin
    tc = t[carried] - floor_seconds
    span = max(tc[-1], _KEY_SECONDS)
    keys = np.arange(0.0, span + 2 * _KEY_SECONDS, _KEY_SECONDS)
    centres = rng.uniform(_CENTRE_LOW, _CENTRE_HIGH, (len(keys), 3))
    centre = CubicSpline(keys, centres, bc_type="natural")(tc)
    wobble = CubicSpline(keys, rng.uniform(-1.0, 1.0, (len(keys), 3)), bc_type="natural")(tc)
    turn = 2.0 * np.pi / min(_TURN_SECONDS, max(span, 1.0))
    yaw = rng.uniform(0.0, 2.0 * np.pi) + turn * tc + 0.35 * wobble[:, 0]
    pitch = np.radians(27.5 + 17.5 * np.clip(wobble[:, 1], -1.0, 1.0))
    roll = np.radians(25.0) * wobble[:, 2]
    Rc = board_rotation(yaw, pitch, roll)
    w, h = board_size
    R[carried] = Rc
    origin[carried] = centre - 0.5 * w * Rc[:, :, 0] - 0.5 * h * Rc[:, :, 1]
    return R, origin
