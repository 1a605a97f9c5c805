"""What an app gets from the room: a tracked :class:`Body` and a detected :class:`Gesture`.

No rclpy here: both are plain frozen dataclasses with numpy arrays, expressed in the client's
fixed frame (``world`` by default: metres, +Z up, the floor at z = 0; REP 103), and
:func:`skeleton_points` / :func:`gesture_fields` read the messages they come from (an rclpy
message or a rosbags dataclass: anything with the fields), raising :class:`BadMessage` with
one line of text for what an app cannot use.

A body's joints are the 19 of ``hmocap_interfaces/Skeleton`` (``pelvis``, ``spine``, ``chest``,
``neck``, ``head``, ``l_clavicle``, ``l_shoulder``, ``l_elbow``, ``l_wrist`` and the right
side's, ``l_hip``, ``l_knee``, ``l_ankle`` and the right side's); a joint without a finite
position is missing, and everything that needs it answers None.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BadMessage", "Body", "Gesture", "HAND_JOINTS", "ROOT_JOINT", "gesture_fields", "skeleton_points"]

#: The joint that says where a body is (the root of the tracking skeleton).
ROOT_JOINT = "pelvis"
#: Each side's hand joint (the skeleton's last joint of the arm) and the elbow a pointing ray
#: starts from.
HAND_JOINTS = {"left": ("l_wrist", "l_elbow"), "right": ("r_wrist", "r_elbow")}


class BadMessage(ValueError):
    """A message an app cannot use; the text is the one log line that says why."""


@dataclass(frozen=True, eq=False)
class Body:
    """One tracked person at one stamp.

    id: the REP-155 body id (``b0``, ``b1``, ...); stamp_ns: the stamp of the camera frames the
    pose comes from (integer nanoseconds); frame_id: the frame of ``positions`` (the client's
    fixed frame); joint_names: one per row of ``positions`` (J, 3), metres, NaN where a joint is
    missing; confidence: (J,) in [0, 1] or None when the tracker gave none; fit_error: the
    tracker's final silhouette cost (thesis eq. 2.8, lower is better; NaN when unknown).
    """

    id: str
    stamp_ns: int
    frame_id: str
    joint_names: tuple[str, ...]
    positions: np.ndarray
    confidence: np.ndarray | None = None
    fit_error: float = float("nan")

    def joint(self, name: str) -> np.ndarray | None:
        """The position (3,) of joint ``name``, None when the body has no such joint or it is missing."""
        try:
            p = self.positions[self.joint_names.index(name)]
        except ValueError:
            return None
        return p.copy() if np.all(np.isfinite(p)) else None

    @property
    def position(self) -> np.ndarray | None:
        """Where the body is: its root joint (``pelvis``), else the mean of the joints it has;
        None when it has none."""
        root = self.joint(ROOT_JOINT)
        if root is not None:
            return root
        valid = np.all(np.isfinite(self.positions), axis=1)
        return self.positions[valid].mean(axis=0) if np.any(valid) else None

    @property
    def missing_joints(self) -> tuple[str, ...]:
        """The joints without a finite position."""
        bad = ~np.all(np.isfinite(self.positions), axis=1)
        return tuple(name for name, b in zip(self.joint_names, bad) if b)


@dataclass(frozen=True, eq=False)
class Gesture:
    """One gesture of one depth frame (``hmocap_interfaces/Gesture``).

    name, class_id, score (the Parzen density at the maximum, thesis eq. 3.4), volume (eq. 3.5),
    u, v: as in the message; stamp_ns: the depth image's stamp; source_frame: the frame its
    3D point was measured in (the depth camera's optical frame); point: that point in the
    client's fixed frame (3,), or None when the detector had no 3D point (no camera_info) or the
    depth camera's pose in the room is not known (no transform on ``/tf_static``).
    """

    name: str
    class_id: int
    score: float
    volume: float
    u: float
    v: float
    stamp_ns: int
    source_frame: str
    point: np.ndarray | None


def skeleton_points(msg) -> tuple[str, tuple[str, ...], np.ndarray, np.ndarray | None]:
    """``(body_id, joint_names, positions (J, 3), confidence (J,) or None)`` of a Skeleton
    message, positions in its ``header.frame_id``. BadMessage for a message without a body id
    or with as many positions as joint names; a confidence of another length than the joints
    is dropped (None): the positions are still good."""
    body_id = str(msg.body_id)
    names = tuple(str(n) for n in msg.joint_names)
    if not body_id:
        raise BadMessage("skeleton without a body_id: message ignored")
    if len(msg.positions) != len(names):
        raise BadMessage(f"skeleton of {body_id}: {len(msg.positions)} positions for {len(names)} joint names: "
                         "message ignored")
    positions = np.array([(p.x, p.y, p.z) for p in msg.positions], dtype=np.float64).reshape(-1, 3)
    confidence = np.asarray(msg.confidence, dtype=np.float64)
    return body_id, names, positions, (confidence if len(confidence) == len(names) else None)


def gesture_fields(gesture) -> tuple[np.ndarray | None, dict]:
    """The 3D point (3,) of a Gesture message in its array's frame (None when
    ``position_valid`` is false or the point is not finite) and its other fields."""
    p = gesture.position
    point = np.array([p.x, p.y, p.z], dtype=np.float64)
    valid = gesture.position_valid and np.all(np.isfinite(point))
    return (point if valid else None), {"name": str(gesture.name), "class_id": int(gesture.class_id),
                                        "score": float(gesture.score), "volume": float(gesture.volume),
                                        "u": float(gesture.u), "v": float(gesture.v)}
