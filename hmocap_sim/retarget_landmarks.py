"""Skeleton families of BVH motion capture: which BVH point stands for which body landmark.

For each family that ``bvh.detect_family`` knows (cgspeed MotionBuilder-friendly ``cmu_mb``,
cgspeed Daz-friendly ``daz``, iClone ``cc_base``) a table maps the body's joints and end sites
(``pelvis``, ``l_elbow``, ``head_top``, ...) to BVH points, and a second table names the BVH joint
whose rotation moves the same body segment (step 1 and 3 of :mod:`hmocap_sim.retarget`).
``t_pose_frames`` finds the added T-pose at the start of cgspeed files from those landmarks.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from hmocap_sim.bvh import Bvh, BvhPose
from hmocap_sim.retarget_rotations import unit_vectors

__all__ = ["FAMILY_LANDMARKS", "FAMILY_TWIST_SOURCES", "RestChain", "Virtual", "bvh_point",
           "t_pose_frames"]


@dataclass(frozen=True)
class Virtual:
    """A BVH point fixed in a joint's frame: ``p_joint + R_joint @ offset`` (file units)."""

    joint: str
    offset: tuple[float, float, float]


@dataclass(frozen=True)
class RestChain:
    """Where ``target`` (a joint or End Site below ``joint``) would be if every joint between
    them kept its zero rotation: a point rigid in ``joint``'s frame.

    Used for hand and toe tips, so that finger and toe curls (and glitches in those channels,
    e.g. a finger marker swap in CMU 13_26 near frame 2650) do not swing the whole hand or foot.
    """

    joint: str
    target: str


# A BVH point spec: a joint or End Site name ("<joint>_end"), a Virtual or RestChain point, or a
# tuple of specs tried in order (the first one the file has).

_SIDES = (("l_", "Left", "l", "L"), ("r_", "Right", "r", "R"))


def _cmu_mb_landmarks() -> dict:
    out = {
        "pelvis": "Hips", "spine": "LowerBack", "chest": "Spine1", "neck": "Neck1",
        "head": "Head", "head_top": "Head_end",
    }
    for body, mb, short, _ in _SIDES:
        side = body[0]
        out |= {
            f"{side}_clavicle": f"{mb}Shoulder", f"{side}_shoulder": f"{mb}Arm",
            f"{side}_elbow": f"{mb}ForeArm", f"{side}_wrist": f"{mb}Hand",
            # 31-joint files name the finger chain LeftHandIndex1 or LFingers.
            f"{side}_hand_tip": (RestChain(f"{mb}Hand", f"{mb}HandIndex1_end"),
                                 RestChain(f"{mb}Hand", f"{short.upper()}Fingers_end")),
            f"{side}_hip": f"{mb}UpLeg", f"{side}_knee": f"{mb}Leg",
            f"{side}_ankle": f"{mb}Foot", f"{side}_toe": RestChain(f"{mb}Foot", f"{mb}ToeBase_end"),
        }
    return out


def _daz_landmarks() -> dict:
    out = {
        "pelvis": "hip", "spine": "abdomen", "chest": "chest", "neck": "neck", "head": "head",
        # Daz heads have no End Site on top; the head's local +Y is up in the Daz rest pose.
        "head_top": Virtual("head", (0.0, 15.0, 0.0)),
        "l_eye": "leftEye", "r_eye": "rightEye",
    }
    for body, _, s, _ in _SIDES:
        side = body[0]
        out |= {
            f"{side}_clavicle": f"{s}Collar", f"{side}_shoulder": f"{s}Shldr",
            f"{side}_elbow": f"{s}ForeArm", f"{side}_wrist": f"{s}Hand",
            f"{side}_hand_tip": f"{s}Mid1",  # knuckle: rigid in the hand, unlike the finger tip
            f"{side}_hip": f"{s}Thigh", f"{side}_knee": f"{s}Shin",
            f"{side}_ankle": f"{s}Foot", f"{side}_toe": f"{s}Foot_end",
        }
    return out


def _cc_base_landmarks() -> dict:
    out = {
        "pelvis": "CC_Base_Pelvis", "spine": "CC_Base_Waist", "chest": "CC_Base_Spine02",
        "neck": "CC_Base_NeckTwist01", "head": "CC_Base_Head",
        # CC_Base bones are Y-along-bone; the head bone's +Y points to the top of the head.
        "head_top": Virtual("CC_Base_Head", (0.0, 15.0, 0.0)),
        "l_eye": "CC_Base_L_Eye", "r_eye": "CC_Base_R_Eye",
    }
    for body, _, _, c in _SIDES:
        side, p = body[0], f"CC_Base_{c}_"
        # Twist bones (UpperarmTwist01/02, ForearmTwist01/02, ThighTwist, CalfTwist) and share
        # bones sit on or along the main bones: only the main bones are used.
        out |= {
            f"{side}_clavicle": p + "Clavicle", f"{side}_shoulder": p + "Upperarm",
            f"{side}_elbow": p + "Forearm", f"{side}_wrist": p + "Hand",
            # Knuckle and ball of the foot: rigid in the hand and foot, unlike finger/toe tips.
            f"{side}_hand_tip": p + "Mid1",
            f"{side}_hip": p + "Thigh", f"{side}_knee": p + "Calf", f"{side}_ankle": p + "Foot",
            f"{side}_toe": p + "ToeBase",
        }
    return out


#: Per family: body landmark (joint or end site name, or l_eye/r_eye) -> BVH point spec: a joint
#: or End Site name, a ``Virtual`` or ``RestChain`` point, or a tuple of specs (first present).
FAMILY_LANDMARKS: dict[str, dict] = {
    "cmu_mb": _cmu_mb_landmarks(),
    "daz": _daz_landmarks(),
    "cc_base": _cc_base_landmarks(),
}


def _twist_sources(landmarks: dict, overrides: dict) -> dict:
    out = {
        name: point for name, point in landmarks.items()
        if isinstance(point, str) and not name.endswith(("_tip", "_toe", "_top", "_eye"))
    }
    return out | overrides


#: Per family: body joint -> BVH joint whose world rotation moves the same body segment.
FAMILY_TWIST_SOURCES: dict[str, dict[str, str]] = {
    "cmu_mb": _twist_sources(FAMILY_LANDMARKS["cmu_mb"], {"spine": "Spine"}),
    "daz": _twist_sources(FAMILY_LANDMARKS["daz"], {}),
    "cc_base": _twist_sources(FAMILY_LANDMARKS["cc_base"], {"spine": "CC_Base_Spine01"}),
}


def bvh_point(bvh: Bvh, pose: BvhPose, spec) -> np.ndarray | None:
    """(F, 3) position of a BVH point spec, or None when the file lacks it."""
    if isinstance(spec, str):
        if spec in bvh.joint_names or spec in bvh.end_site_names:
            return pose.point(bvh, spec)
        return None
    if isinstance(spec, Virtual):
        if spec.joint not in bvh.joint_names:
            return None
        j = bvh.joint_names.index(spec.joint)
        return pose.positions[:, j] + pose.rotations[:, j] @ np.asarray(spec.offset, float)
    if isinstance(spec, RestChain):
        offset = _rest_chain_offset(bvh, spec.joint, spec.target)
        if offset is None:
            return None
        j = bvh.joint_names.index(spec.joint)
        return pose.positions[:, j] + pose.rotations[:, j] @ offset
    for alternative in spec:
        point = bvh_point(bvh, pose, alternative)
        if point is not None:
            return point
    return None


def _rest_chain_offset(bvh: Bvh, joint: str, target: str) -> np.ndarray | None:
    """Sum of OFFSETs from ``joint`` (exclusive) down to ``target`` (inclusive), in
    ``joint``'s frame and BVH units (rest-pose scale, see ``RestChain``), or None."""
    if joint not in bvh.joint_names:
        return None
    top = bvh.joint_names.index(joint)
    if target in bvh.end_site_names:
        e = bvh.end_site_names.index(target)
        total, j = bvh.end_site_offsets[e].copy(), int(bvh.end_site_parents[e])
    elif target in bvh.joint_names:
        j = bvh.joint_names.index(target)
        total = np.zeros(3)
    else:
        return None
    while j != top:
        if j < 0:
            return None  # target is not below joint
        total += bvh.offsets[j]
        j = int(bvh.parents[j])
    return total


def t_pose_frames(landmarks: Mapping[str, np.ndarray]) -> int:
    """Number of leading frames to drop because frame 0 is an added T-pose (0 if it is not).

    cgspeed files (MotionBuilder- and Daz-friendly) start with a T-pose that is not part of the
    motion, as do some iClone exports. Frame 0 is taken as such when both upper arms point
    sideways (within ~30 deg of the shoulder line), both thighs point down, and the pose jumps
    from frame 0 to frame 1 by more than five times the clip's median frame-to-frame change; the
    following frames that still jump that much (a blend into the motion) are dropped with it.
    """
    need = ("l_shoulder", "r_shoulder", "l_elbow", "r_elbow", "l_hip", "r_hip", "l_knee",
            "r_knee", "neck")
    if not all(n in landmarks for n in need) or len(landmarks["neck"]) < 3:
        return 0
    lm = {n: np.asarray(landmarks[n], float) for n in need}
    lateral = unit_vectors(lm["l_shoulder"][0] - lm["r_shoulder"][0])
    up = unit_vectors(lm["neck"][0] - 0.5 * (lm["l_hip"][0] + lm["r_hip"][0]))
    arms = (
        unit_vectors(lm["l_elbow"][0] - lm["l_shoulder"][0]) @ lateral > 0.85
        and unit_vectors(lm["r_elbow"][0] - lm["r_shoulder"][0]) @ -lateral > 0.85
    )
    legs = (
        unit_vectors(lm["l_knee"][0] - lm["l_hip"][0]) @ -up > 0.9
        and unit_vectors(lm["r_knee"][0] - lm["r_hip"][0]) @ -up > 0.9
    )
    if not (arms and legs):
        return 0
    root = 0.5 * (lm["l_hip"] + lm["r_hip"])
    rel = np.stack([lm[n] - root for n in need], axis=1)
    change = np.linalg.norm(np.diff(rel, axis=0), axis=2).max(axis=1)
    jump = change > 5.0 * max(float(np.median(change)), 1e-9)
    if not jump[0]:
        return 0
    # Daz-friendly files blend from the T-pose into the motion over a few frames: drop the blend
    # too (every step up to the first ordinary one), but never more than a quarter second's worth.
    n = 1
    while n < min(len(jump), 30) and jump[n]:
        n += 1
    return n
