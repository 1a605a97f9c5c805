"""The room's fixed frames, as an app needs them: a small tree of static transforms, no rclpy.

The room publishes its frames once, latched: ``camera_rig_publisher`` puts ``world`` (+Z up)
-> ``room`` (+Y up) -> every camera's optical frame on ``/tf_static``, a depth camera that is
not in the rig is placed by a static transform of its own (docs/real_sensors.md), and the
``camera_rig`` message carries the rig's cameras in the room frame. :class:`StaticFrames`
keeps every such transform by child frame (the newest wins) and composes them, so a point
measured in any of these frames is expressed in any other of the same tree: nothing about the
axes is assumed, the rotation ``room -> world`` is the one published.
"""

from __future__ import annotations

import numpy as np

from hmocap_ros.io.tf import FrameTransform, from_transform_stamped

__all__ = ["StaticFrames", "rig_frame_transforms"]


class StaticFrames:
    """Static transforms by child frame, composed on demand (``lookup``)."""

    def __init__(self) -> None:
        self.parents: dict[str, FrameTransform] = {}
        self._cache: dict[tuple[str, str], np.ndarray | None] = {}

    def add(self, transform: FrameTransform) -> None:
        """Add (or replace, for its child frame) one transform."""
        self.parents[transform.child] = transform
        self._cache.clear()

    def add_message(self, msg) -> list[str]:
        """Add every transform of a ``tf2_msgs/TFMessage``; the one-line errors of those that
        are not transforms (an empty frame name, a quaternion that is not a unit one)."""
        errors = []
        for stamped in msg.transforms:
            try:
                self.add(from_transform_stamped(stamped))
            except ValueError as err:
                errors.append(str(err))
        return errors

    def __contains__(self, frame: str) -> bool:
        return frame in self.parents or any(t.parent == frame for t in self.parents.values())

    def _to_root(self, frame: str) -> tuple[str, np.ndarray]:
        """The root of ``frame``'s tree and the 4x4 transform from ``frame`` to it."""
        matrix = np.eye(4)
        seen = {frame}
        while frame in self.parents:
            transform = self.parents[frame]
            matrix = transform.matrix @ matrix
            frame = transform.parent
            if frame in seen:  # a loop of transforms: no root
                break
            seen.add(frame)
        return frame, matrix

    def lookup(self, target: str, source: str) -> np.ndarray | None:
        """4x4 matrix taking ``source`` coordinates to ``target`` coordinates, None when the two
        frames are not in one tree (or either is unknown)."""
        key = (target, source)
        if key not in self._cache:
            if target == source:
                self._cache[key] = np.eye(4)
            elif source not in self or target not in self:
                self._cache[key] = None
            else:
                root_s, s = self._to_root(source)
                root_t, t = self._to_root(target)
                self._cache[key] = np.linalg.inv(t) @ s if root_s == root_t else None
        return self._cache[key]

    def transform_points(self, points, target: str, source: str) -> np.ndarray | None:
        """Points (..., 3) in ``source`` expressed in ``target``; None when there is no transform."""
        matrix = self.lookup(target, source)
        if matrix is None:
            return None
        p = np.asarray(points, dtype=np.float64)
        return p @ matrix[:3, :3].T + matrix[:3, 3]


def rig_frame_transforms(msg) -> list[FrameTransform]:
    """The cameras of a ``hmocap_interfaces/CameraRig`` message as transforms from the rig's
    frame (``header.frame_id``) to each camera's optical frame (its CameraInfo's frame_id).
    ValueError when the message has no frame or its poses are not transforms."""
    room = str(msg.header.frame_id)
    if not room:
        raise ValueError("camera_rig without header.frame_id")
    out = []
    for info, pose in zip(msg.camera_info, msg.camera_poses):
        p, q = pose.position, pose.orientation
        out.append(FrameTransform(room, str(info.header.frame_id), (p.x, p.y, p.z), (q.x, q.y, q.z, q.w)))
    return out
