"""A retargeted body motion (:class:`Motion`), its resampling and its placement in the room."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from hmocap_sim.retarget_rotations import rotation_about_y

__all__ = ["Motion", "heading_of", "place_in_room", "resample"]


@dataclass(frozen=True)
class Motion:
    """A body motion: per-frame local joint rotations and root position, body frame.

    Forward kinematics (``retarget_rotations.joint_forward_kinematics``): ``G_root = local[root]``,
    ``p_root = root_translation``, ``G_j = G_parent @ local[j]``,
    ``p_j = p_parent + G_parent @ (rest_j - rest_parent)``; all rotations identity gives the
    body's rest pose with the pelvis at ``root_translation``.

    Attributes:
        fps: frames per second.
        local_rotations: (F, J, 3, 3) rotation of each joint relative to its parent and rest.
        root_translation: (F, 3) world position of the root joint (pelvis), metres, +Y up.
        joint_names: the body's joint names, in the order of axis 1 of ``local_rotations``.
        source: where the motion came from (BVH path).
        family: BVH skeleton family (``bvh.detect_family``), if any.
        source_frames: (F,) BVH frame of each frame (None after ``resample``).
        bvh_to_body: (3, 3) rotation from BVH world axes to body axes used by ``retarget``.
        scale: body leg length / BVH leg length (in BVH units).
    """

    fps: float
    local_rotations: np.ndarray
    root_translation: np.ndarray
    joint_names: tuple[str, ...]
    source: str = ""
    family: str | None = None
    source_frames: np.ndarray | None = None
    bvh_to_body: np.ndarray = field(default_factory=lambda: np.eye(3))
    scale: float = 1.0

    @property
    def n_frames(self) -> int:
        return int(self.local_rotations.shape[0])

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return (self.n_frames - 1) / self.fps


def resample(motion: Motion, fps_out: float) -> Motion:
    """The motion at another frame rate: slerp for rotations, linear for the root.

    The output has ``round(duration * fps_out) + 1`` frames spanning exactly the input's first
    to last frame (so both are kept); the step is therefore ``1 / fps_out`` up to a stretch of at
    most half an output frame over the whole clip.
    """
    if not fps_out > 0:
        raise ValueError(f"fps_out must be > 0, got {fps_out}")
    n_in = motion.n_frames
    n_out = max(int(round((n_in - 1) * fps_out / motion.fps)) + 1, 1)
    if n_in == 1 or n_out == 1:
        return replace(motion, fps=float(fps_out), source_frames=None,
                       local_rotations=motion.local_rotations[:1].copy(),
                       root_translation=motion.root_translation[:1].copy())
    t = np.linspace(0.0, n_in - 1, n_out)
    i0 = np.minimum(np.floor(t).astype(int), n_in - 2)
    alpha = t - i0
    n_joints = motion.local_rotations.shape[1]
    quats = Rotation.from_matrix(motion.local_rotations.reshape(-1, 3, 3)).as_quat()
    quats = quats.reshape(n_in, n_joints, 4)
    q0, q1 = quats[i0], quats[i0 + 1]
    dot = np.einsum("fjk,fjk->fj", q0, q1)
    q1 = np.where(dot[..., None] < 0, -q1, q1)  # shortest arc
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    small = theta < 1e-6
    sin_t = np.where(small, 1.0, np.sin(theta))
    a = alpha[:, None]
    w0 = np.where(small, 1.0 - a, np.sin((1.0 - a) * theta) / sin_t)
    w1 = np.where(small, a, np.sin(a * theta) / sin_t)
    q = w0[..., None] * q0 + w1[..., None] * q1
    rot = Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(n_out, n_joints, 3, 3)
    # Keep the end frames bit-exact.
    rot[0], rot[-1] = motion.local_rotations[0], motion.local_rotations[-1]
    trans = (1.0 - alpha)[:, None] * motion.root_translation[i0] + alpha[
        :, None
    ] * motion.root_translation[i0 + 1]
    trans[0], trans[-1] = motion.root_translation[0], motion.root_translation[-1]
    return replace(motion, fps=float(fps_out), local_rotations=rot, root_translation=trans,
                   source_frames=None)


def heading_of(motion: Motion, frame: int = 0, root: int = 0) -> float:
    """Facing direction of the root in a frame: angle about +Y from +Z towards +X (radians)."""
    forward = motion.local_rotations[frame, root] @ np.array([0.0, 0.0, 1.0])
    return float(np.arctan2(forward[0], forward[2]))


def place_in_room(
    motion: Motion,
    position_xz: Sequence[float],
    heading: float,
    *,
    anchor: str = "mean",
    root: int = 0,
) -> Motion:
    """Turn the motion about the vertical and move it so it plays at a place in the room.

    Args:
        motion: retargeted motion (feet already on y = 0, see ``retarget``).
        position_xz: (x, z) in metres where the anchor of the root trajectory is put.
        heading: direction the person faces in the first frame, radians about +Y from +Z
            towards +X (0: facing +Z, pi/2: facing +X).
        anchor: ``"mean"`` puts the mean of the root's horizontal trajectory at
            ``position_xz`` (the clip is centred there), ``"first"`` puts the first frame there.
        root: index of the root joint.

    Returns:
        The moved motion; heights are unchanged, so the feet stay on the floor.
    """
    if anchor not in ("mean", "first"):
        raise ValueError(f"anchor must be 'mean' or 'first', got {anchor!r}")
    turn = rotation_about_y(heading - heading_of(motion, 0, root))
    trans = motion.root_translation
    centre = trans.mean(axis=0) if anchor == "mean" else trans[0].copy()
    centre[1] = 0.0
    target = np.array([position_xz[0], 0.0, position_xz[1]], dtype=np.float64)
    new_trans = (trans - centre) @ turn.T + target
    local = motion.local_rotations.copy()
    local[:, root] = turn @ local[:, root]
    return replace(motion, local_rotations=local, root_translation=new_trans)
