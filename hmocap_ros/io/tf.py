"""Coordinate frames for tf2: rig cameras and rotations as ``geometry_msgs/TransformStamped``.

No rclpy here: :class:`FrameTransform` is a parent -> child transform in plain numbers, built
from a rig camera (:func:`camera_transform`, :func:`rig_transforms`) or from a rotation matrix
and a translation (:func:`frame_transform`); :func:`rotations_to_quaternions` converts a batch
of rotations at once (a tracked body's joint frames, :mod:`hmocap_ros.tracking.body_frames`);
:func:`to_transform_stamped` and
:func:`tf_message` build the messages through a message factory
(``hmocap_ros.io.msg_factory``: ``RclpyFactory`` in a node, ``RosbagsFactory`` for bags).

Conventions (tf2, REP 103 and REP 105)
--------------------------------------
A transform with ``header.frame_id = parent`` and ``child_frame_id = child`` holds the child
frame's pose in the parent frame: ``translation`` is the child's origin in parent
coordinates and ``rotation`` the unit quaternion ``(x, y, z, w)`` that rotates vectors given
in child coordinates into parent coordinates, so ``p_parent = R p_child + t``.

The root of the tree is a fixed frame with +Z up, as REP 103 asks of a world frame
(:data:`DEFAULT_FIXED_FRAME`, ``world``; the role of ``map`` in REP 105), on the floor: RViz's
grid and Foxglove's 3D panel lie on the floor with it. The rig's room frame (``frame_id`` of
the rig file, ``room`` by default) hangs under it at the same origin, in metres with +Y up and
the floor at y = 0 (the convention of the calibration, the simulator and the tracker); the
rotation :data:`Y_UP_TO_Z_UP` takes room vectors into the fixed frame: room +Y is its +Z, room
+X its +X, room +Z its -Y. A camera's ``<name>_optical_frame`` hangs under the room and
follows the REP 103 optical convention: x right, y down, z forward (the viewing direction);
tracked bodies (``body_<id>``) hang under the room too.

Static transforms go on ``/tf_static`` (:data:`TF_STATIC_TOPIC`) as one ``tf2_msgs/TFMessage``
holding every transform of the publisher, reliable and transient-local with a history of one,
as tf2's static broadcaster publishes them: a listener that starts later still gets them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hmocap_ros.geometry.rotations import quaternion_to_matrix

__all__ = [
    "DEFAULT_FIXED_FRAME",
    "FrameTransform",
    "TF_STATIC_TOPIC",
    "TF_TOPIC",
    "TF_MESSAGE_TYPE",
    "Y_UP_TO_Z_UP",
    "camera_transform",
    "frame_transform",
    "from_transform_stamped",
    "rig_transforms",
    "rotation_to_quaternion",
    "rotations_to_quaternions",
    "tf_message",
    "to_transform_stamped",
]

#: Topic of the static transforms (transient local, keep last 1: one message with all of them).
TF_STATIC_TOPIC = "/tf_static"
#: Topic of the transforms that change over time.
TF_TOPIC = "/tf"
#: ROS type of the messages on both.
TF_MESSAGE_TYPE = "tf2_msgs/msg/TFMessage"

#: Largest deviation of R^T R from I (and of det R from 1) accepted as a rotation.
ROTATION_TOLERANCE = 1e-6

#: The +Z-up fixed frame at the root of the tree (camera_rig_publisher's ``fixed_frame``).
DEFAULT_FIXED_FRAME = "world"

#: Quaternion (x, y, z, w) of the rotation that takes room (+Y up) vectors into a +Z-up frame:
#: +90 degrees about X (room +Y -> +Z, room +Z -> -Y).
Y_UP_TO_Z_UP = (float(np.sqrt(0.5)), 0.0, 0.0, float(np.sqrt(0.5)))


def rotation_to_quaternion(rotation) -> tuple[float, float, float, float]:
    """Unit quaternion ``(x, y, z, w)``, ``w >= 0``, of a 3x3 rotation matrix.

    Raises ``ValueError`` for a matrix that is not a finite proper rotation (orthonormal with
    determinant +1 within :data:`ROTATION_TOLERANCE`).
    """
    R = np.asarray(rotation, dtype=np.float64)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ValueError(f"a rotation must be a finite 3x3 matrix, got shape {R.shape}")
    if (np.abs(R.T @ R - np.eye(3)).max() > ROTATION_TOLERANCE
            or abs(np.linalg.det(R) - 1.0) > ROTATION_TOLERANCE):
        raise ValueError(f"not a rotation matrix (orthonormal, det +1): {R.tolist()}")
    # Shepperd's method: take the largest of 4w^2, 4x^2, 4y^2, 4z^2 for a stable square root.
    trace = np.trace(R)
    diagonal = np.diag(R)
    k = int(np.argmax([trace, *diagonal]))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1], 0.25 * s * s]) / s
    else:
        i = k - 1
        j, m = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[m, m])
        q = np.empty(4)
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[m] = (R[m, i] + R[i, m]) / s
        q[3] = (R[m, j] - R[j, m]) / s
    q /= np.linalg.norm(q)
    if q[3] < 0:
        q = -q
    return float(q[0]), float(q[1]), float(q[2]), float(q[3])


def rotations_to_quaternions(rotations) -> np.ndarray:
    """Unit quaternions ``(N, 4)`` as ``(x, y, z, w)``, ``w >= 0``, of rotation matrices
    ``(N, 3, 3)``: :func:`rotation_to_quaternion` vectorised (the same branch choice per matrix,
    so the two agree to rounding). ``ValueError`` when any matrix is not a finite proper
    rotation within :data:`ROTATION_TOLERANCE`."""
    R = np.asarray(rotations, dtype=np.float64)
    if R.ndim != 3 or R.shape[1:] != (3, 3) or not np.all(np.isfinite(R)):
        raise ValueError(f"rotations must be finite (N, 3, 3) matrices, got shape {R.shape}")
    error = np.abs(np.einsum("nki,nkj->nij", R, R) - np.eye(3)).max(axis=(1, 2), initial=0.0)
    bad = (error > ROTATION_TOLERANCE) | (np.abs(np.linalg.det(R) - 1.0) > ROTATION_TOLERANCE)
    if np.any(bad):
        raise ValueError(f"not rotation matrices (orthonormal, det +1) at rows {np.flatnonzero(bad).tolist()}")
    diagonal = np.einsum("nii->ni", R)
    trace = diagonal.sum(axis=1)
    # Shepperd's method per matrix: 4 * (w^2, x^2, y^2, z^2) up to a common offset; the largest
    # is the component whose square root is stable.
    k = np.argmax(np.column_stack([trace, diagonal]), axis=1)
    q = np.empty((len(R), 4))
    w_rows = k == 0
    s = 2.0 * np.sqrt(1.0 + trace[w_rows])
    Rw = R[w_rows]
    q[w_rows] = np.column_stack([Rw[:, 2, 1] - Rw[:, 1, 2], Rw[:, 0, 2] - Rw[:, 2, 0],
                                 Rw[:, 1, 0] - Rw[:, 0, 1], 0.25 * s * s]) / s[:, None]
    for i in range(3):
        rows = k == i + 1
        if not np.any(rows):
            continue
        j, m = (i + 1) % 3, (i + 2) % 3
        Ri = R[rows]
        s = 2.0 * np.sqrt(1.0 + Ri[:, i, i] - Ri[:, j, j] - Ri[:, m, m])
        q[rows, i] = 0.25 * s
        q[rows, j] = (Ri[:, j, i] + Ri[:, i, j]) / s
        q[rows, m] = (Ri[:, m, i] + Ri[:, i, m]) / s
        q[rows, 3] = (Ri[:, m, j] - Ri[:, j, m]) / s
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.where(q[:, 3:] < 0, -q, q)


@dataclass(frozen=True)
class FrameTransform:
    """The pose of frame ``child`` in frame ``parent``: ``p_parent = R(rotation) p_child + translation``."""

    parent: str
    child: str
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]  # unit quaternion (x, y, z, w)

    def __post_init__(self) -> None:
        for name in ("parent", "child"):
            value = getattr(self, name)
            if not isinstance(value, str) or not value:
                raise ValueError(f"frame transform: {name} frame must be a non-empty string, got {value!r}")
        if self.parent == self.child:
            raise ValueError(f"frame transform: parent and child are both {self.parent!r}")
        t = np.asarray(self.translation, dtype=np.float64)
        q = np.asarray(self.rotation, dtype=np.float64)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise ValueError(f"frame transform {self.parent} -> {self.child}: translation must be 3 finite numbers")
        if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > 1e-6:
            raise ValueError(f"frame transform {self.parent} -> {self.child}: rotation must be a unit quaternion "
                             "(x, y, z, w)")
        object.__setattr__(self, "translation", tuple(float(v) for v in t))
        object.__setattr__(self, "rotation", tuple(float(v) for v in q))

    @property
    def matrix(self) -> np.ndarray:
        """4x4 homogeneous matrix taking child coordinates to parent coordinates."""
        out = np.eye(4)
        out[:3, :3] = quaternion_to_matrix(self.rotation, tolerance=None)
        out[:3, 3] = self.translation
        return out

    def apply(self, points_child) -> np.ndarray:
        """Points (..., 3) in child coordinates -> parent coordinates."""
        points = np.asarray(points_child, dtype=np.float64)
        return points @ quaternion_to_matrix(self.rotation, tolerance=None).T + np.asarray(self.translation)


def frame_transform(parent: str, child: str, rotation, translation) -> FrameTransform:
    """:class:`FrameTransform` from a child -> parent rotation matrix (3x3) and the child's
    origin in the parent frame."""
    tx, ty, tz = np.asarray(translation, np.float64).reshape(3)
    return FrameTransform(parent, child, (tx, ty, tz), rotation_to_quaternion(rotation))


def camera_transform(camera, parent: str) -> FrameTransform:
    """The optical frame of a rig camera (:class:`~hmocap_ros.geometry.pinhole_camera.PinholeCamera`:
    its ``frame_id``, centre ``position`` and optical -> room rotation ``R_wc``) in ``parent``,
    the rig's room frame."""
    return frame_transform(parent, camera.frame_id, camera.R_wc, camera.position)


def rig_transforms(rig, fixed_frame: str = DEFAULT_FIXED_FRAME) -> list[FrameTransform]:
    """With ``fixed_frame`` (+Z up) first ``fixed_frame`` -> room (:data:`Y_UP_TO_Z_UP`, same
    origin), then room frame -> optical frame of each camera of ``rig``, in rig order. An empty
    ``fixed_frame`` leaves the room at the root (for a tree that places it otherwise)."""
    out = []
    if fixed_frame:
        out.append(FrameTransform(fixed_frame, rig.frame_id, (0.0, 0.0, 0.0), Y_UP_TO_Z_UP))
    out += [camera_transform(camera, rig.frame_id) for camera in rig.cameras]
    return out


def to_transform_stamped(transform: FrameTransform, stamp_ns: int, factory):
    """``geometry_msgs/msg/TransformStamped`` of ``transform`` at ``stamp_ns``, built with
    ``factory.make`` (an rclpy message or a rosbags dataclass)."""
    from hmocap_ros.io.msg_factory import make_header

    tx, ty, tz = transform.translation
    qx, qy, qz, qw = transform.rotation
    return factory.make(
        "geometry_msgs/msg/TransformStamped",
        header=make_header(factory, int(stamp_ns), transform.parent),
        child_frame_id=transform.child,
        transform=factory.make(
            "geometry_msgs/msg/Transform",
            translation=factory.make("geometry_msgs/msg/Vector3", x=tx, y=ty, z=tz),
            rotation=factory.make("geometry_msgs/msg/Quaternion", x=qx, y=qy, z=qz, w=qw),
        ),
    )


def tf_message(transforms, stamp_ns: int, factory):
    """``tf2_msgs/msg/TFMessage`` holding ``transforms`` (:class:`FrameTransform`), all at
    ``stamp_ns``."""
    return factory.make(TF_MESSAGE_TYPE,
                        transforms=[to_transform_stamped(t, stamp_ns, factory) for t in transforms])


def from_transform_stamped(msg) -> FrameTransform:
    """:class:`FrameTransform` of a ``TransformStamped`` (rclpy message or rosbags dataclass)."""
    t, q = msg.transform.translation, msg.transform.rotation
    return FrameTransform(msg.header.frame_id, msg.child_frame_id, (t.x, t.y, t.z), (q.x, q.y, q.z, q.w))
