"""Retarget BVH motion capture onto the body model by matching bone directions.

The BVH skeletons (three families, see ``bvh.detect_family``) have other bone lengths, rest poses
(T-pose against the body's MakeHuman A-pose) and bone rolls than the body, so Euler angles cannot
be copied. Instead, for every body joint ``j`` the *global* rotation ``G_j`` is solved so that the
body's bones point where the corresponding BVH bones point (notes/body-model.md, "Motion"):

1. Landmarks. Each family maps the body's joints and end sites (``pelvis``, ``l_elbow``,
   ``head_top``, ...) to BVH points (a joint, an End Site, or a point fixed in a BVH joint's
   frame); twist bones, share bones and finger and toe rotations of the BVH are not used. World
   positions come from BVH forward kinematics, converted to the body's axes (+Y up).
2. Position frame ``P_j(t)``: weighted Kabsch/SVD (Kabsch 1976; Markley 1988 for the weighted
   form) taking unit vectors between body rest landmarks to the same vectors between BVH
   landmarks. Joints with several children use a lateral and an up vector (pelvis: hip to hip and
   hips to neck; chest: shoulder to shoulder and spine to neck), which fixes twist. Single-child
   joints use their bone plus a secondary direction that fixes twist where it is defined (upper
   arm: the forearm, i.e. the elbow plane; forearm: the upper arm; thigh and shin: the foot;
   foot: the shin; spine and neck: the shoulder line; head: the eye line where the BVH has eyes),
   plus a weak pull to the parent's frame so that twist falls back to the parent's when the
   secondary direction is parallel to the bone (a straight elbow).
3. Twist from the BVH segment. ``P_j`` is noisy or undefined in some frames (straight limbs, a
   head without face landmarks), whereas the BVH joint ``k`` of the same segment carries the full
   rotation in every frame. So a constant offset ``C_j = proj_SO(3)(sum_t c_t R_k(t)^T P_j(t))``
   is fitted over the clip (``c_t``: how well ``P_j`` is conditioned in frame ``t``) and
   ``Q_j(t) = R_k(t) C_j``. Neither the BVH's T-pose nor its zero pose is needed, so the same
   code serves clips with and without an added T-pose.
4. Exact bone direction. For a single-child joint the minimal rotation (swing) taking
   ``Q_j d0`` to the observed BVH bone direction is applied: ``G_j = swing(Q_j d0 -> d) Q_j``,
   so the bone points exactly along the BVH bone and the twist is that of step 3.
5. ``local_j = G_parent^T G_j``; the pelvis is placed at the BVH hip-joint midpoint (scaled by
   body leg length / BVH leg length) plus the body's own pelvis-above-hips offset, and one
   constant vertical shift puts the feet on the floor (y = 0).

Bone lengths are the body's own (forward kinematics with the rest offsets), so ground truth for
evaluation is the posed body, not the BVH positions.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from typing import Mapping, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from hmocap_ros.sim.bvh import Bvh, BvhPose, detect_family, forward_kinematics, load_bvh

__all__ = [
    "FAMILY_LANDMARKS",
    "FAMILY_TWIST_SOURCES",
    "Motion",
    "RestChain",
    "Virtual",
    "bone_direction_errors",
    "heading_of",
    "kabsch",
    "load_motion",
    "place_in_room",
    "resample",
    "retarget",
    "swing",
    "t_pose_frames",
]


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

# Body-side frame vectors (step 2 of the module docstring). Each entry: (from landmarks, to
# landmarks, weight); a landmark tuple means its mean. Pairs whose landmarks only the BVH has
# take their body direction from _BODY_CONSTANT_VECTORS.
_FRAME_VECTORS: dict[str, list] = {
    "pelvis": [(("r_hip",), ("l_hip",), 1.0), (("l_hip", "r_hip"), ("neck",), 1.0)],
    "chest": [(("r_shoulder",), ("l_shoulder",), 1.0), (("spine",), ("neck",), 1.0)],
    "spine": [(("r_shoulder",), ("l_shoulder",), 0.5)],
    "neck": [(("r_shoulder",), ("l_shoulder",), 0.5)],
    "head": [(("r_eye",), ("l_eye",), 1.0)],
}
for _s in "lr":
    _FRAME_VECTORS |= {
        f"{_s}_clavicle": [(("spine",), ("neck",), 0.5)],
        f"{_s}_shoulder": [((f"{_s}_elbow",), (f"{_s}_wrist",), 1.0)],
        f"{_s}_elbow": [((f"{_s}_elbow",), (f"{_s}_shoulder",), 1.0)],
        f"{_s}_wrist": [],
        f"{_s}_hip": [((f"{_s}_ankle",), (f"{_s}_toe",), 1.0)],
        f"{_s}_knee": [((f"{_s}_ankle",), (f"{_s}_toe",), 1.0)],
        f"{_s}_ankle": [((f"{_s}_knee",), (f"{_s}_ankle",), 0.5)],
    }
# Landmarks that exist only on the BVH side; the body side is the rest direction between them.
_BODY_CONSTANT_VECTORS = {(("r_eye",), ("l_eye",)): np.array([1.0, 0.0, 0.0])}
_PARENT_PULL = 0.05  # weight of the parent's axes in P_j: decides twist only when nothing else does


@dataclass(frozen=True)
class Motion:
    """A body motion: per-frame local joint rotations and root position, body frame.

    Forward kinematics (``_fk``): ``G_root = local[root]``, ``p_root = root_translation``,
    ``G_j = G_parent @ local[j]``, ``p_j = p_parent + G_parent @ (rest_j - rest_parent)``; all
    rotations identity gives the body's rest pose with the pelvis at ``root_translation``.

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


# ------------------------------------------------------------------------- rotation helpers


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def kabsch(
    rest_dirs: np.ndarray, observed_dirs: np.ndarray, weights: np.ndarray | None = None
) -> np.ndarray:
    """Rotations R minimising ``sum_i w_i |R a_i - b_i|^2`` (Kabsch 1976, with weights).

    Args:
        rest_dirs: (..., N, 3) vectors ``a_i`` (broadcast against ``observed_dirs``).
        observed_dirs: (..., N, 3) vectors ``b_i``.
        weights: (N,) or (..., N) non-negative weights; ones by default.

    Returns:
        (..., 3, 3) proper rotations (det +1).
    """
    a = np.asarray(rest_dirs, dtype=np.float64)
    b = np.asarray(observed_dirs, dtype=np.float64)
    w = np.ones(a.shape[-2]) if weights is None else np.asarray(weights, dtype=np.float64)
    h = np.einsum("...n,...ni,...nj->...ij", w, b, a)
    return _nearest_rotation(h)


def _nearest_rotation(m: np.ndarray) -> np.ndarray:
    """Projection of (..., 3, 3) matrices onto SO(3) (polar decomposition with det fix)."""
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt))
    d = np.where(d == 0, 1.0, d)
    u = u.copy()
    u[..., :, 2] *= d[..., None]
    return u @ vt


def swing(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Minimal rotations taking directions ``u`` to ``v`` (..., 3) -> (..., 3, 3).

    Rodrigues' formula with ``k = u x v``: ``R = I + [k]x + [k]x^2 / (1 + u.v)``; for opposite
    directions a half turn about an axis perpendicular to ``u``.
    """
    u, v = np.broadcast_arrays(_unit(np.asarray(u, float)), _unit(np.asarray(v, float)))
    k = np.cross(u, v)
    c = np.einsum("...i,...i->...", u, v)
    kx = np.zeros(k.shape + (3,))
    kx[..., 0, 1], kx[..., 0, 2], kx[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    kx[..., 1, 0], kx[..., 2, 0], kx[..., 2, 1] = k[..., 2], -k[..., 1], k[..., 0]
    opposite = c < -1.0 + 1e-9
    denom = np.where(opposite, 1.0, 1.0 + c)
    r = np.eye(3) + kx + kx @ kx / denom[..., None, None]
    if np.any(opposite):
        helper = np.where(np.abs(u[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        n = _unit(np.cross(u, helper))
        half_turn = 2.0 * n[..., :, None] * n[..., None, :] - np.eye(3)
        r = np.where(opposite[..., None, None], half_turn, r)
    return r


def _rot_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


# --------------------------------------------------------------------------------- landmarks


def _bvh_point(bvh: Bvh, pose: BvhPose, spec) -> np.ndarray | None:
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
        point = _bvh_point(bvh, pose, alternative)
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


def _body_landmarks(
    rest_joints: np.ndarray, joint_names: Sequence[str],
    end_sites_rest: np.ndarray | None, end_site_names: Sequence[str] | None,
) -> dict[str, np.ndarray]:
    out = {name: np.asarray(p, float) for name, p in zip(joint_names, rest_joints)}
    if end_sites_rest is not None and end_site_names is not None:
        out |= {name: np.asarray(p, float) for name, p in zip(end_site_names, end_sites_rest)}
    return out


def _mean_of(points: Mapping[str, np.ndarray], names: Sequence[str]) -> np.ndarray | None:
    if not all(n in points for n in names):
        return None
    return np.mean([points[n] for n in names], axis=0)


def _topological_order(parents: np.ndarray) -> list[int]:
    depth = np.zeros(len(parents), dtype=int)
    for j in range(len(parents)):
        p, d = parents[j], 0
        while p >= 0:
            p, d = parents[p], d + 1
            if d > len(parents):
                raise ValueError("body parents contain a cycle")
        depth[j] = d
    return [int(j) for j in np.argsort(depth, kind="stable")]


def _up_axis_rotation(up: np.ndarray) -> np.ndarray:
    """Rotation taking the BVH axis nearest to ``up`` onto +Y, horizontal axes kept if possible."""
    axis = np.zeros(3)
    i = int(np.argmax(np.abs(up)))
    axis[i] = np.sign(up[i])
    if np.allclose(axis, [0, 1, 0]):
        return np.eye(3)
    if np.allclose(axis, [0, -1, 0]):
        return np.diag([1.0, -1.0, -1.0])
    return np.rint(swing(axis, np.array([0.0, 1.0, 0.0])))


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
    lateral = _unit(lm["l_shoulder"][0] - lm["r_shoulder"][0])
    up = _unit(lm["neck"][0] - 0.5 * (lm["l_hip"][0] + lm["r_hip"][0]))
    arms = (
        _unit(lm["l_elbow"][0] - lm["l_shoulder"][0]) @ lateral > 0.85
        and _unit(lm["r_elbow"][0] - lm["r_shoulder"][0]) @ -lateral > 0.85
    )
    legs = (
        _unit(lm["l_knee"][0] - lm["l_hip"][0]) @ -up > 0.9
        and _unit(lm["r_knee"][0] - lm["r_hip"][0]) @ -up > 0.9
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


# ---------------------------------------------------------------------------- retargeting


def retarget(
    bvh: Bvh,
    body_rest_joints: np.ndarray,
    body_parents: Sequence[int],
    joint_names: Sequence[str],
    end_sites_rest: np.ndarray | None = None,
    end_site_parents: Sequence[int] | None = None,
    end_site_names: Sequence[str] | None = None,
    *,
    family: str | None = None,
    landmarks: Mapping | None = None,
    twist_sources: Mapping[str, str] | None = None,
    frames: slice | np.ndarray | None = None,
    drop_t_pose: bool = True,
    floor_percentile: float = 10.0,
) -> Motion:
    """Retarget a parsed BVH onto the body (algorithm: module docstring).

    Args:
        bvh: parsed BVH (``bvh.load_bvh``).
        body_rest_joints: (J, 3) body rest joint positions, metres, +Y up, facing +Z.
        body_parents: (J,) parent index per joint, -1 for the root.
        joint_names: (J,) body joint names (the landmark tables use the reference body's names:
            pelvis, spine, chest, neck, head, l_clavicle, l_shoulder, l_elbow, l_wrist, ...).
        end_sites_rest: (E, 3) end-site rest positions (head_top, l_hand_tip, ..., l_toe, ...);
            without them the head, wrists and ankles follow their BVH segment's rotation only.
        end_site_parents: (E,) joint index of each end site.
        end_site_names: (E,) end-site names.
        family: BVH family; detected from joint names by default.
        landmarks: body landmark -> BVH point table (default ``FAMILY_LANDMARKS[family]``).
        twist_sources: body joint -> BVH joint table (default ``FAMILY_TWIST_SOURCES[family]``).
        frames: BVH frames to use (slice or indices), after dropping an added T-pose.
        drop_t_pose: drop a leading added T-pose frame (``t_pose_frames``).
        floor_percentile: the feet's lowest point is put on y = 0 in this percentile of frames.

    Returns:
        ``Motion`` at the BVH frame rate.

    Raises:
        ValueError: unknown family without tables, or a BVH lacking the landmarks needed.
    """
    rest = np.asarray(body_rest_joints, dtype=np.float64)
    parents = np.asarray(body_parents, dtype=np.int64)
    names = tuple(str(n) for n in joint_names)
    if rest.shape != (len(names), 3) or parents.shape != (len(names),):
        raise ValueError(
            f"body: {len(names)} joint names, rest joints {rest.shape}, parents {parents.shape}"
        )
    family = family or detect_family(bvh)
    if landmarks is None:
        if family not in FAMILY_LANDMARKS:
            raise ValueError(
                f"{bvh.source}: unknown BVH skeleton family (joints {bvh.joint_names[:6]}...): "
                "pass landmarks= and twist_sources="
            )
        landmarks = FAMILY_LANDMARKS[family]
    if twist_sources is None:
        twist_sources = FAMILY_TWIST_SOURCES.get(family, {})
    site_names = tuple(str(n) for n in end_site_names) if end_site_names is not None else ()
    site_parents = (
        np.asarray(end_site_parents, dtype=np.int64) if end_site_parents is not None else None
    )
    body_pts = _body_landmarks(rest, names, end_sites_rest, site_names)

    # ---- BVH landmarks and rotations in body axes
    pose = forward_kinematics(bvh)
    bvh_pts = {name: p for name, spec in landmarks.items()
               if (p := _bvh_point(bvh, pose, spec)) is not None}
    needed = ("l_hip", "r_hip", "l_knee", "r_knee", "l_ankle", "r_ankle", "neck")
    missing = [n for n in needed if n not in bvh_pts]
    if missing:
        raise ValueError(f"{bvh.source}: BVH lacks the landmarks {missing} ({family})")
    missing = [n for n in needed if n not in body_pts]
    if missing:
        raise ValueError(f"body lacks the joints {missing} (joint names {names})")
    n_drop = t_pose_frames(bvh_pts) if drop_t_pose else 0
    keep = np.arange(n_drop, bvh.n_frames)
    if frames is not None:
        keep = keep[frames]
    if keep.size == 0:
        raise ValueError(f"{bvh.source}: no frames left to retarget")
    mid_hips = 0.5 * (bvh_pts["l_hip"] + bvh_pts["r_hip"])
    to_body = _up_axis_rotation(np.mean(bvh_pts["neck"] - mid_hips, axis=0))
    obs = {n: p[keep] @ to_body.T for n, p in bvh_pts.items()}
    bvh_rot = {
        j: to_body @ pose.rotations[keep, bvh.joint_names.index(k)]
        for j, k in twist_sources.items() if k in bvh.joint_names
    }

    glob = _global_rotations(names, parents, site_names, site_parents, body_pts, obs, bvh_rot)
    local = glob.copy()
    for j, p in enumerate(parents):
        if p >= 0:
            local[:, j] = np.swapaxes(glob[:, p], -1, -2) @ glob[:, j]

    # ---- root translation: hip midpoint, scaled by leg length, plus the body's pelvis offset
    root = int(np.flatnonzero(parents < 0)[0])
    scale = _leg_length(body_pts) / _leg_length(obs)
    hips_body = _mean_of(body_pts, ("l_hip", "r_hip"))
    hips_obs = _mean_of(obs, ("l_hip", "r_hip"))
    root_t = scale * hips_obs + glob[:, root] @ (rest[root] - hips_body)
    motion = Motion(
        fps=bvh.fps, local_rotations=local, root_translation=root_t, joint_names=names,
        source=bvh.source, family=family, source_frames=keep, bvh_to_body=to_body,
        scale=float(scale),
    )
    return _feet_on_floor(motion, rest, parents, end_sites_rest, site_parents, floor_percentile)


def _global_rotations(
    names: tuple[str, ...],
    parents: np.ndarray,
    site_names: tuple[str, ...],
    site_parents: np.ndarray | None,
    body_pts: Mapping[str, np.ndarray],
    obs: Mapping[str, np.ndarray],
    bvh_rot: Mapping[str, np.ndarray],
) -> np.ndarray:
    """(F, J, 3, 3) global body rotations, steps 2-4 of the module docstring."""
    children: dict[int, list[str]] = {j: [] for j in range(len(names))}
    for c, p in enumerate(parents):
        if p >= 0:
            children[int(p)].append(names[c])
    if site_parents is not None:
        for s, p in zip(site_names, site_parents):
            children[int(p)].append(s)
    n_frames = next(iter(obs.values())).shape[0]
    glob = np.empty((n_frames, len(names), 3, 3))
    for j in _topological_order(parents):
        name, parent = names[j], int(parents[j])
        kids = children[j]
        aim = kids[0] if len(kids) == 1 and {kids[0], name} <= (body_pts.keys() & obs.keys()) \
            else None
        g_parent = glob[:, parent] if parent >= 0 else np.broadcast_to(np.eye(3), (n_frames, 3, 3))
        frame, conditioning = _position_frame(name, aim, body_pts, obs, g_parent)
        if name in bvh_rot:
            # Constant offset between the BVH segment and the body segment, fitted over the clip
            # with the frames where the position frame is well defined counting most.
            seg = bvh_rot[name]
            weight = np.maximum(conditioning, 0.05)
            offset = _nearest_rotation(np.einsum("f,fji,fjk->ik", weight, seg, frame))
            frame = seg @ offset
        if aim is not None:
            d0 = frame @ _unit(body_pts[aim] - body_pts[name])
            frame = swing(d0, obs[aim] - obs[name]) @ frame
        glob[:, j] = frame
    return glob


def _position_frame(
    name: str,
    aim: str | None,
    body_pts: Mapping[str, np.ndarray],
    obs: Mapping[str, np.ndarray],
    g_parent: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Position-based global rotation ``P_j`` (F, 3, 3) of one joint and its conditioning (F,).

    Weighted Kabsch over the joint's bone (``aim``) and its ``_FRAME_VECTORS``, plus a pull of
    weight ``_PARENT_PULL`` towards the parent's frame. Conditioning is the ratio of the second
    to the first singular value of the vectors' cross-covariance: 0 when they are all parallel
    (twist undefined), 1 for two perpendicular vectors of equal weight.
    """
    rest_vecs, obs_vecs, weights = [], [], []
    if aim is not None:
        rest_vecs.append(body_pts[aim] - body_pts[name])
        obs_vecs.append(obs[aim] - obs[name])
        weights.append(1.0)
    for frm, to, w in _FRAME_VECTORS.get(name, []):
        o_from, o_to = _mean_of(obs, frm), _mean_of(obs, to)
        if o_from is None or o_to is None:
            continue
        b_from, b_to = _mean_of(body_pts, frm), _mean_of(body_pts, to)
        if b_from is not None and b_to is not None:
            rest_vecs.append(b_to - b_from)
        elif (frm, to) in _BODY_CONSTANT_VECTORS:
            rest_vecs.append(_BODY_CONSTANT_VECTORS[(frm, to)])
        else:
            continue
        obs_vecs.append(o_to - o_from)
        weights.append(w)
    if not rest_vecs:
        return np.array(g_parent), np.ones(g_parent.shape[0])
    a = _unit(np.stack(rest_vecs))  # (N, 3)
    b = _unit(np.stack(obs_vecs, axis=1))  # (F, N, 3)
    h = np.einsum("n,fni,nj->fij", np.asarray(weights), b, a)
    sv = np.linalg.svd(h, compute_uv=False)
    conditioning = sv[:, 1] / np.maximum(sv[:, 0], 1e-12)
    # The parent's axes e_i -> G_parent e_i, weakly: they decide twist only when nothing else does.
    return _nearest_rotation(h + _PARENT_PULL * g_parent), conditioning


def _leg_length(points: Mapping[str, np.ndarray]) -> float:
    """Mean over both legs of thigh + shin length (median over frames for (F, 3) points)."""
    total = []
    for s in "lr":
        a, b, c = (points.get(f"{s}_{n}") for n in ("hip", "knee", "ankle"))
        if a is None or b is None or c is None:
            continue
        total.append(
            np.median(np.linalg.norm(np.atleast_2d(b - a), axis=-1))
            + np.median(np.linalg.norm(np.atleast_2d(c - b), axis=-1))
        )
    if not total:
        raise ValueError("need hip, knee and ankle landmarks to scale the motion")
    return float(np.mean(total))


def _feet_on_floor(
    motion: Motion, rest: np.ndarray, parents: np.ndarray,
    end_sites_rest: np.ndarray | None, end_site_parents: np.ndarray | None, percentile: float,
) -> Motion:
    """Shift the motion vertically so the feet touch y = 0.

    In every frame the lowest foot point's height above its rest height (rest: feet flat on the
    floor) is a contact height; the ``percentile`` of it over the clip is taken as the floor, so a
    jump does not lift the clip and a foot-skating outlier does not sink it.
    """
    positions, glob = _fk(motion.local_rotations, motion.root_translation, rest, parents)
    points, rest_points = [positions], [rest]
    if end_sites_rest is not None and end_site_parents is not None and len(end_site_parents):
        sites = _fk_end_sites(positions, glob, rest, end_sites_rest, end_site_parents)
        points.append(sites)
        rest_points.append(np.asarray(end_sites_rest, float))
    heights = np.concatenate(points, axis=1)[..., 1]
    rest_h = np.concatenate(rest_points, axis=0)[:, 1]
    low = rest_h < rest_h.min() + 0.12  # the feet (ankles, toes): within 12 cm of the floor
    contact = (heights[:, low] - rest_h[low]).min(axis=1)
    shift = -float(np.percentile(contact, percentile))
    return replace(motion, root_translation=motion.root_translation + [0.0, shift, 0.0])


def load_motion(
    path: str | os.PathLike,
    body_rest_joints: np.ndarray,
    body_parents: Sequence[int],
    joint_names: Sequence[str],
    end_sites_rest: np.ndarray | None = None,
    end_site_parents: Sequence[int] | None = None,
    end_site_names: Sequence[str] | None = None,
    *,
    fps: float | None = None,
    **options,
) -> Motion:
    """Load a BVH file and retarget it onto the body (``retarget``), optionally resampled.

    Args:
        path: BVH file.
        body_rest_joints, body_parents, joint_names, end_sites_rest, end_site_parents,
            end_site_names: the body (see ``retarget``).
        fps: resample to this frame rate (``resample``); the file's rate by default.
        **options: passed to ``retarget`` (family, landmarks, twist_sources, frames,
            drop_t_pose, floor_percentile).
    """
    motion = retarget(
        load_bvh(path), body_rest_joints, body_parents, joint_names,
        end_sites_rest, end_site_parents, end_site_names, **options,
    )
    return motion if fps is None else resample(motion, fps)


# ------------------------------------------------------------------------------ diagnostics


def bone_direction_errors(
    motion: Motion,
    bvh: Bvh,
    body_rest_joints: np.ndarray,
    body_parents: Sequence[int],
    end_sites_rest: np.ndarray | None = None,
    end_site_parents: Sequence[int] | None = None,
    end_site_names: Sequence[str] | None = None,
    landmarks: Mapping | None = None,
) -> dict[str, np.ndarray]:
    """Angle (degrees, per frame) between each posed body bone and the BVH's bone.

    For every body bone ``parent -> child`` (child a joint or an end site) whose two landmarks
    the family maps, the body's bone direction from ``_fk`` is compared with the direction
    between the BVH landmarks in the same source frame. Needs ``motion.source_frames`` (a motion
    straight from ``retarget``, not resampled).

    Returns:
        ``{"parent->child": (F,) angles}``; NaN where the two BVH landmarks coincide.
    """
    if motion.source_frames is None:
        raise ValueError("motion has no source frames (resampled?)")
    rest = np.asarray(body_rest_joints, float)
    parents = np.asarray(body_parents, int)
    names = motion.joint_names
    landmarks = FAMILY_LANDMARKS[motion.family] if landmarks is None else landmarks
    positions, glob = _fk(motion.local_rotations, motion.root_translation, rest, parents)
    body = {n: positions[:, i] for i, n in enumerate(names)}
    bones = [(names[p], names[c]) for c, p in enumerate(parents) if p >= 0]
    if end_sites_rest is not None and end_site_parents is not None and end_site_names is not None:
        sites = _fk_end_sites(positions, glob, rest, end_sites_rest, end_site_parents)
        body |= {n: sites[:, i] for i, n in enumerate(end_site_names)}
        bones += [(names[p], str(n)) for n, p in zip(end_site_names, end_site_parents)]
    pose = forward_kinematics(bvh, frames=motion.source_frames)
    out = {}
    for a, b in bones:
        if a not in landmarks or b not in landmarks:
            continue
        pa, pb = _bvh_point(bvh, pose, landmarks[a]), _bvh_point(bvh, pose, landmarks[b])
        if pa is None or pb is None:
            continue
        v_bvh = (pb - pa) @ motion.bvh_to_body.T
        d_body = _unit(body[b] - body[a])
        cos = np.clip(np.einsum("fi,fi->f", _unit(v_bvh), d_body), -1.0, 1.0)
        angle = np.degrees(np.arccos(cos))
        # Two landmarks on the same BVH point (cmu_mb: LowerBack at Hips) define no direction.
        angle[np.linalg.norm(v_bvh, axis=-1) < 1e-9] = np.nan
        out[f"{a}->{b}"] = angle
    return out


# ------------------------------------------------------------------- resampling, placement


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
    turn = _rot_y(heading - heading_of(motion, 0, root))
    trans = motion.root_translation
    centre = trans.mean(axis=0) if anchor == "mean" else trans[0].copy()
    centre[1] = 0.0
    target = np.array([position_xz[0], 0.0, position_xz[1]], dtype=np.float64)
    new_trans = (trans - centre) @ turn.T + target
    local = motion.local_rotations.copy()
    local[:, root] = turn @ local[:, root]
    return replace(motion, local_rotations=local, root_translation=new_trans)


# ------------------------------------------------------------------------------ kinematics


def _fk(
    local_rotations: np.ndarray, root_translation: np.ndarray, rest_joints: np.ndarray,
    parents: Sequence[int],
) -> tuple[np.ndarray, np.ndarray]:
    """Body forward kinematics (convention in ``Motion``).

    Returns positions (F, J, 3) and global rotations (F, J, 3, 3). A private stand-in with the
    convention of ``hmocap_ros.body.kinematics.forward_kinematics`` (tested to agree), so this
    module does not depend on the body package.
    """
    local = np.asarray(local_rotations, float)
    rest = np.asarray(rest_joints, float)
    parents = np.asarray(parents, int)
    glob = np.empty_like(local)
    pos = np.empty(local.shape[:2] + (3,))
    for j in _topological_order(parents):
        p = parents[j]
        if p < 0:
            glob[:, j] = local[:, j]
            pos[:, j] = root_translation
        else:
            glob[:, j] = glob[:, p] @ local[:, j]
            pos[:, j] = pos[:, p] + glob[:, p] @ (rest[j] - rest[p])
    return pos, glob


def _fk_end_sites(
    positions: np.ndarray, glob: np.ndarray, rest_joints: np.ndarray,
    end_sites_rest: np.ndarray, end_site_parents: Sequence[int],
) -> np.ndarray:
    """(F, E, 3) end-site positions from posed joints and their global rotations."""
    par = np.asarray(end_site_parents, int)
    offsets = np.asarray(end_sites_rest, float) - np.asarray(rest_joints, float)[par]
    return positions[:, par] + np.einsum("feij,ej->fei", glob[:, par], offsets)
