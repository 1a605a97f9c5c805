"""Biovision Hierarchy (BVH) motion files: parser and vectorised forward kinematics.

A BVH file has two parts (Biovision / Meredith & Maddock, "Motion capture file formats
explained", 2001):

* ``HIERARCHY``: a tree of ``ROOT`` / ``JOINT`` blocks, each with an ``OFFSET`` (translation
  from the parent joint in the parent's frame, in file units) and ``CHANNELS n ...`` naming, in
  order, the values the joint reads from every frame line (``Xposition``, ``Yposition``,
  ``Zposition``, ``Xrotation``, ``Yrotation``, ``Zrotation``, in any order); leaves carry an
  ``End Site`` block with an ``OFFSET`` only.
* ``MOTION``: ``Frames: N``, ``Frame Time: dt`` and N lines of whitespace-separated numbers, one
  value per channel, in the order the channels appear in the hierarchy (depth first).

Conventions used here (the common ones, as in Blender's importer and the CMU/cgspeed files):

* rotation channels are Euler angles in degrees; the local rotation is the product of the
  elementary rotations in the order the channels are listed, ``R = R_c1 @ R_c2 @ R_c3`` (for
  ``Zrotation Yrotation Xrotation``: ``Rz @ Ry @ Rx``), acting on column vectors;
* a joint with position channels uses them as its translation from the parent *instead of* its
  OFFSET (for roots the OFFSET is normally zero anyway); missing position axes keep the OFFSET's;
* world rotation ``G_j = G_parent @ R_j``, world position ``p_j = p_parent + G_parent @ t_j``.

The parser (:class:`Bvh`, :func:`load_bvh`, :func:`parse_bvh`, :class:`BvhError`) lives in
:mod:`hmocap_sim.bvh_parser` and is re-exported here. Only numpy is used; the MOTION block is
converted to floats in one numpy call, and forward kinematics loops over joints (tens), never over
frames or values.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from hmocap_sim.bvh_parser import (
    AXES,
    CHANNEL_NAMES,
    Bvh,
    BvhError,
    load_bvh,
    parse_bvh,
)

__all__ = [
    "Bvh",
    "BvhError",
    "BvhPose",
    "CMU_UNIT_M",
    "FAMILY_UNITS_M",
    "detect_family",
    "euler_to_matrix",
    "forward_kinematics",
    "load_bvh",
    "parse_bvh",
]

#: CMU ASF length unit used by the cgspeed MotionBuilder-friendly files: 1/0.45 inch, in metres.
CMU_UNIT_M = 0.0254 / 0.45

#: Metres per file unit for each known skeleton family (see ``detect_family``).
FAMILY_UNITS_M = {
    "cmu_mb": CMU_UNIT_M,  # cgspeed MotionBuilder-friendly, CMU ASF units
    "daz": 0.01,  # cgspeed Daz-friendly: centimetres (a generic Daz figure, hips ~0.84 m high)
    "cc_base": 0.01,  # iClone CC_Base retargets: centimetres
}


class BvhPose(NamedTuple):
    """World-space result of ``forward_kinematics`` (positions in metres if ``scale`` converts)."""

    positions: np.ndarray  # (F, J, 3) joint positions
    rotations: np.ndarray  # (F, J, 3, 3) joint world rotations (frame of each joint's children)
    end_sites: np.ndarray  # (F, E, 3) End Site positions

    def point(self, bvh: Bvh, name: str) -> np.ndarray:
        """(F, 3) position of a joint or an End Site (``"<joint>_end"``) by name."""
        if name in bvh.joint_names:
            return self.positions[:, bvh.joint_names.index(name)]
        if name in bvh.end_site_names:
            return self.end_sites[:, bvh.end_site_names.index(name)]
        raise KeyError(f"{bvh.source}: no joint or End Site named {name!r}")


# ----------------------------------------------------------------------------- families


def detect_family(bvh: Bvh) -> str | None:
    """Which known skeleton family a BVH uses, from its joint names.

    Returns ``"cmu_mb"`` (cgspeed MotionBuilder-friendly CMU conversion: Hips, LHipJoint,
    LeftUpLeg, LowerBack, Spine1, ...), ``"daz"`` (cgspeed Daz-friendly: hip, abdomen, chest,
    lShldr, lThigh, ...), ``"cc_base"`` (Reallusion iClone CC_Base rig: CC_Base_Hip,
    CC_Base_L_Upperarm, ...) or ``None``.
    """
    names = set(bvh.joint_names)
    if {"Hips", "LeftUpLeg", "RightUpLeg", "LeftArm", "RightArm", "LeftForeArm", "Head"} <= names:
        return "cmu_mb"
    if {"hip", "abdomen", "chest", "lThigh", "rThigh", "lShldr", "rShldr", "head"} <= names:
        return "daz"
    if {"CC_Base_Hip", "CC_Base_L_Thigh", "CC_Base_R_Thigh", "CC_Base_L_Upperarm",
            "CC_Base_Head"} <= names:
        return "cc_base"
    return None


# --------------------------------------------------------------------------- kinematics


def euler_to_matrix(angles_deg: np.ndarray, order: str) -> np.ndarray:
    """Rotation matrices from Euler angles applied in BVH channel order.

    Args:
        angles_deg: (..., k) angles in degrees, column i about axis ``order[i]``.
        order: axis letters, e.g. ``"ZYX"``; the result is ``R_order[0] @ R_order[1] @ ...``
            (intrinsic rotations, as BVH channel lists are read).

    Returns:
        (..., 3, 3) rotation matrices.
    """
    angles = np.radians(np.asarray(angles_deg, dtype=np.float64))
    if angles.shape[-1] != len(order):
        raise ValueError(f"{angles.shape[-1]} angles for rotation order {order!r}")
    result = np.broadcast_to(np.eye(3), angles.shape[:-1] + (3, 3)).copy()
    for i, axis in enumerate(order.upper()):
        c, s = np.cos(angles[..., i]), np.sin(angles[..., i])
        elementary = np.zeros(angles.shape[:-1] + (3, 3))
        a = AXES[axis]
        b, d = (a + 1) % 3, (a + 2) % 3
        elementary[..., a, a] = 1.0
        elementary[..., b, b] = c
        elementary[..., d, d] = c
        elementary[..., b, d] = -s
        elementary[..., d, b] = s
        result = result @ elementary
    return result


def local_transforms(bvh: Bvh, motion: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-joint local rotations (F, J, 3, 3) and translations (F, J, 3), file units."""
    motion = bvh.motion if motion is None else np.asarray(motion, dtype=np.float64)
    n_frames = motion.shape[0]
    rotations = np.broadcast_to(np.eye(3), (n_frames, bvh.n_joints, 3, 3)).copy()
    translations = np.broadcast_to(bvh.offsets, (n_frames, bvh.n_joints, 3)).copy()
    for j, channels in enumerate(bvh.channels):
        start = int(bvh.channel_start[j])
        rot_cols, rot_axes = [], ""
        for k, channel in enumerate(channels):
            kind, axis = CHANNEL_NAMES[channel]
            if kind == "position":
                translations[:, j, axis] = motion[:, start + k]
            else:
                rot_cols.append(start + k)
                rot_axes += "XYZ"[axis]
        if rot_cols:
            rotations[:, j] = euler_to_matrix(motion[:, rot_cols], rot_axes)
    return rotations, translations


def forward_kinematics(
    bvh: Bvh, frames: slice | np.ndarray | None = None, scale: float = 1.0
) -> BvhPose:
    """World positions and rotations of every joint in every (selected) frame.

    Args:
        bvh: parsed file.
        frames: optional slice or index array of frames; all frames by default.
        scale: metres per file unit (e.g. ``FAMILY_UNITS_M[detect_family(bvh)]``); positions are
            multiplied by it, rotations are unaffected.

    Returns:
        ``BvhPose`` with positions (F, J, 3), rotations (F, J, 3, 3), end_sites (F, E, 3), in
        the file's axes.
    """
    motion = bvh.motion if frames is None else bvh.motion[frames]
    local_r, local_t = local_transforms(bvh, motion)
    world_r = np.empty_like(local_r)
    world_p = np.empty_like(local_t)
    for j, parent in enumerate(bvh.parents):
        if parent < 0:
            world_r[:, j] = local_r[:, j]
            world_p[:, j] = local_t[:, j]
        else:
            world_r[:, j] = world_r[:, parent] @ local_r[:, j]
            world_p[:, j] = world_p[:, parent] + np.einsum(
                "fab,fb->fa", world_r[:, parent], local_t[:, j]
            )
    if len(bvh.end_site_names):
        ends = world_p[:, bvh.end_site_parents] + np.einsum(
            "feab,eb->fea", world_r[:, bvh.end_site_parents], bvh.end_site_offsets
        )
    else:
        ends = np.zeros((motion.shape[0], 0, 3))
    return BvhPose(world_p * scale, world_r, ends * scale)
