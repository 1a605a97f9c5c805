"""Kinematic tree and pose parameterisation (thesis sec. 2.3.1, eq. 2.11).

The pose is Theta = (theta_1..theta_D) ∪ xi_0: the root's 6 DoF (translation of the
pelvis joint in the world, then yaw/pitch/roll) plus joint angles.  Every angle is a
revolute "twist" about a fixed axis, and a joint's local rotation is the product of the
exponential maps of its DoFs in the order listed (eq. 2.11), except for the two ball
joints (shoulders, hips) which use a swing-twist split: R = exp([s]x) exp(t[d]x), where d
is the rest bone direction, s = flex * a_flex + abd * a_abd is the swing vector (⟂ d) and t
the twist.  That keeps the shoulder free of gimbal lock everywhere except with the arm
pointing opposite to its rest direction (up and across the head), where no arm goes.

Conventions (shared by the whole package):

* model frame: metres, +Y up, the body faces +Z, +X is the person's left;
* all parameters zero = rest pose (MakeHuman A-pose), except the root translation,
  which is the world position of the pelvis joint (``rest_pose`` gives the rest vector);
* a **local rotation** ``R[j]`` is the rotation of joint j relative to its parent, written
  in the parent's rest-aligned axes (joint frames are parallel to the model frame at
  rest), so the global rotation is ``G[j] = G[parent] @ R[j]`` and a motion-capture
  retargeter computes ``R[j] = G[parent]^T G[j]`` from world bone rotations;
* positive angles: flexion (bending forward / curling), abduction (away from the body
  midline or, for arms, raising sideways), internal rotation (twist of limbs), turning
  and bending to the person's left (spine, neck, head, root yaw/roll), dorsiflexion
  (ankle), elevation and protraction (clavicle), pronation (elbow twist), palmar flexion
  and radial deviation (wrist), spreading towards the thumb (finger MCP spread).

Each DoF axis is derived from the rest skeleton: a non-twist DoF turns the joint's bone
(towards its primary child) towards a named direction, ``axis = normalise(d × target⊥)``;
a twist DoF turns a reference vector about ``±d`` towards a target.  Axes of one joint are
made orthonormal (Gram-Schmidt, twist axis first).

DoF table (degrees, relative to the A-pose; T = in the ``tracking`` set, {s} = l or r):

    DoF                          motion                        limits              set
    root_tx, root_ty, root_tz    world pelvis position (m)     ±50, -1..3, ±50     T
    root_yaw                     turn left                     -180..180 (wraps)   T
    root_pitch                   lean forward                  -90..90             T
    root_roll                    lean left                     -90..90             T
    spine_flex/bend/twist        lumbar joint                  -30..80, ±35, ±45   T
    chest_flex/bend/twist        thoracic joint                -20..40, ±20, ±30
    neck_flex/bend/twist         lower neck                    -50..60, ±40, ±70   T
    head_flex/bend/twist         skull on neck                 ±30, ±20, ±20
    {s}_clavicle_elev/prot       shrug, shoulder forward       -15..35, -20..25
    {s}_shoulder_flex/abd        swing of the upper arm        -70..170, -60..140  T
    {s}_shoulder_twist           internal rotation             ±90                 T
    {s}_elbow_flex               rest is 46° flexed            -50..105            T
    {s}_elbow_twist              forearm pronation             ±80
    {s}_wrist_flex/dev           palmar flexion, radial dev.   -70..80, -35..20
    {s}_hip_flex/abd             swing of the thigh            -30..125, -30..50   T
    {s}_hip_twist                internal rotation             ±45                 T
    {s}_knee_flex                rest is ~8° flexed            -10..140            T
    {s}_ankle_flex               dorsiflexion                  -50..30             T
    {s}_ankle_inv                inversion                     -25..35
    {s}_thumb1_flex/abd          CMC: across / off the palm    -30..50, -30..60
    {s}_thumb2_flex, thumb3_flex MCP, IP                       -20..60, -20..85
    {s}_<f>1_flex/spread         MCP (f = index..pinky)        -20..95, ±25
    {s}_<f>2_flex, <f>3_flex     PIP, DIP                      -10..110, -10..80

Ball-joint swing vectors are also kept within 170° (``clip_pose``).

The tracking set has 30 DoF (6 root + 24 angles) grouped like the thesis' layers
(sec. 2.5.2: torso and head, each leg, each shoulder, each elbow); ``full`` adds chest,
head, clavicles, forearm twist, wrists, ankle inversion and, where the model has finger
joints, 20 finger DoF per hand.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hmocap_ros.geometry.rotations import rotvec_to_matrix

from .dof_table import master_dof_table
from .rotations import axis_angle_matrix, euler2_angles, euler3_angles, hinge_angle, swing_twist_angles

DOF_SETS = ("tracking", "full")
SWING_NORM_MAX = np.deg2rad(170.0)  # swing cone kept away from the antipodal singularity

# Bone direction of a joint = towards this child (joint or end site); joints not listed
# use their only child joint, or else their only end site.
PRIMARY_CHILD = {"pelvis": "spine", "chest": "neck", "head": "head_top",
                 "l_wrist": "l_hand_tip", "r_wrist": "r_hand_tip",
                 "l_ankle": "l_toe", "r_ankle": "r_toe"}


@dataclass(frozen=True, eq=False)
class Skeleton:
    """Kinematic tree plus the chosen pose parameterisation (immutable, arrays read-only).

    joint_kind[j] is "fixed", "hinge" (1 axis), "euler2", "euler3" (products of revolute
    exponential maps), "swing_twist" or "root" (euler3 + translation).  joint_axes[j]
    holds the unit axes of joint j's DoFs in application order (rows; for swing_twist:
    flex, abd, twist), joint_dofs[j] their indices in the parameter vector.
    """

    joint_names: tuple
    parents: np.ndarray
    joints_rest: np.ndarray
    bone_dirs: np.ndarray
    dof_names: tuple
    dof_joint: np.ndarray
    dof_groups: tuple
    lower: np.ndarray
    upper: np.ndarray
    joint_kind: tuple
    joint_dofs: tuple
    joint_axes: tuple
    translation_dofs: np.ndarray
    wrap_dofs: np.ndarray
    dof_set: str

    @property
    def n_dofs(self) -> int:
        return len(self.dof_names)

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    def dof_index(self, name: str) -> int:
        return self.dof_names.index(name)

    def group_dofs(self, group: str) -> np.ndarray:
        """Parameter indices of one layer group (e.g. "torso", "l_leg", "r_elbow")."""
        return np.array([i for i, g in enumerate(self.dof_groups) if g == group], dtype=np.intp)


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    if n < 1e-9:
        raise ValueError("degenerate direction while building DoF axes")
    return v / n


def _hand_frame(side: str, points: dict) -> tuple:
    """(radial, volar) unit vectors of one hand from the knuckle landmarks.

    radial points from the pinky to the index knuckle (thumb side); the palm normal is
    d × radial for the left hand and radial × d for the right (d = wrist -> hand tip).
    """
    radial = _unit(points[f"{side}_index_knuckle"] - points[f"{side}_pinky_knuckle"])
    d = _unit(points[f"{side}_hand_tip"] - points[f"{side}_wrist"])
    radial = _unit(radial - (radial @ d) * d)
    volar = np.cross(d, radial) if side == "l" else np.cross(radial, d)
    return radial, _unit(volar)


def _direction(name: str, joint: str, points: dict, parent_of: dict) -> np.ndarray:
    side = joint[:2] if joint[:2] in ("l_", "r_") else ""
    lateral = {"l_": 1.0, "r_": -1.0}.get(side, 1.0)
    fixed = {"up": (0, 1, 0), "down": (0, -1, 0), "forward": (0, 0, 1), "back": (0, 0, -1),
             "left": (1, 0, 0), "lateral": (lateral, 0, 0), "medial": (-lateral, 0, 0)}
    if name in fixed:
        return np.asarray(fixed[name], dtype=np.float64)
    if name == "to_parent":
        return _unit(points[parent_of[joint]] - points[joint])
    radial, volar = _hand_frame(side[0], points)
    return {"radial": radial, "ulnar": -radial, "volar": volar,
            "thumb_curl": _unit(volar - radial)}[name]


def primary_child(joint: str, children: dict, end_children: dict, names) -> str:
    """Name of the joint or end site that defines ``joint``'s bone direction."""
    if joint in PRIMARY_CHILD and PRIMARY_CHILD[joint] in names:
        return PRIMARY_CHILD[joint]
    if len(children.get(joint, [])) == 1:
        return children[joint][0]
    if len(end_children.get(joint, [])) == 1:
        return end_children[joint][0]
    raise ValueError(f"cannot choose a bone direction for joint {joint}")


def _bone_dir(joint: str, children: dict, end_children: dict, points: dict) -> np.ndarray:
    return _unit(points[primary_child(joint, children, end_children, points)] - points[joint])


def build_skeleton(joint_names, parents, joints_rest, end_site_names, end_site_parents,
                   end_sites_rest, landmarks: dict | None = None,
                   dof_set: str = "tracking") -> Skeleton:
    """Skeleton for a rest skeleton and a DoF set ("tracking": 30 DoF, "full": all).

    DoFs of the master table whose joint the model lacks are dropped.  landmarks maps
    names such as "l_index_knuckle" to rest positions (needed for wrist/finger axes).
    """
    if dof_set not in DOF_SETS:
        raise ValueError(f"dof_set must be one of {DOF_SETS}, got {dof_set!r}")
    joint_names = tuple(str(n) for n in joint_names)
    parents = np.asarray(parents, dtype=np.intp)
    if parents[0] != -1 or np.any(parents[1:] >= np.arange(1, len(parents))):
        raise ValueError("joints must be ordered parents first with the root at index 0")
    joints_rest = np.asarray(joints_rest, dtype=np.float64)
    points, end_children = _rest_points(joint_names, joints_rest, end_site_names,
                                        end_site_parents, end_sites_rest, landmarks)
    children: dict = {}
    parent_of = {}
    for j, p in enumerate(parents):
        if p >= 0:
            children.setdefault(joint_names[p], []).append(joint_names[j])
            parent_of[joint_names[j]] = joint_names[p]
    specs = _model_dofs(points, dof_set)
    bone_dirs = _bone_directions(joint_names, children, end_children, points, specs)
    kinds, dofs_of, axes_of = [], [], []
    for j, name in enumerate(joint_names):
        idx = [i for i, d in enumerate(specs) if d.joint == name and d.kind != "translation"]
        mine = [specs[i] for i in idx]
        kinds.append(_joint_kind(name, mine))
        dofs_of.append(tuple(idx))
        axes_of.append(_joint_axes(name, bone_dirs[j], mine, points, parent_of))
    trans = np.array([i for i, d in enumerate(specs) if d.kind == "translation"], dtype=np.intp)
    if len(trans) != 3 or [specs[i].target for i in trans] != ["0", "1", "2"]:
        raise ValueError("the root needs translation DoFs x, y, z")
    to_rad = np.array([1.0 if d.kind == "translation" else np.pi / 180.0 for d in specs])
    lower = np.array([d.lo for d in specs]) * to_rad
    upper = np.array([d.hi for d in specs]) * to_rad
    wrap = np.array([i for i, d in enumerate(specs) if d.name == "root_yaw"], dtype=np.intp)
    arrays = [parents, joints_rest, bone_dirs, lower, upper, trans, wrap] + axes_of
    for a in arrays:
        a.flags.writeable = False
    dof_joint = np.array([joint_names.index(d.joint) for d in specs], dtype=np.intp)
    dof_joint.flags.writeable = False
    return Skeleton(joint_names=joint_names, parents=parents, joints_rest=joints_rest,
                    bone_dirs=bone_dirs, dof_names=tuple(d.name for d in specs),
                    dof_joint=dof_joint, dof_groups=tuple(d.group for d in specs),
                    lower=lower, upper=upper, joint_kind=tuple(kinds),
                    joint_dofs=tuple(dofs_of), joint_axes=tuple(axes_of),
                    translation_dofs=trans, wrap_dofs=wrap, dof_set=dof_set)


def _rest_points(joint_names: tuple, joints_rest: np.ndarray, end_site_names, end_site_parents,
                 end_sites_rest, landmarks: dict | None) -> tuple:
    """Rest positions of joints, end sites and landmarks by name, and each joint's end sites."""
    points = {n: joints_rest[i] for i, n in enumerate(joint_names)}
    end_children: dict = {}
    for n, p, x in zip(end_site_names, end_site_parents, np.asarray(end_sites_rest, np.float64)):
        points[str(n)] = x
        end_children.setdefault(joint_names[int(p)], []).append(str(n))
    for n, x in (landmarks or {}).items():
        points[str(n)] = np.asarray(x, dtype=np.float64)
    return points, end_children


def _model_dofs(points: dict, dof_set: str) -> list:
    """The master table's DoFs of ``dof_set`` whose joint (and, for hand directions, knuckle
    landmarks) the model has."""
    return [d for d in master_dof_table()
            if d.joint in points and (dof_set == "full" or d.tracking)
            and not (d.kind != "translation" and d.target in ("volar", "radial", "ulnar", "thumb_curl")
                     and f"{d.joint[0]}_index_knuckle" not in points)]


def _bone_directions(joint_names: tuple, children: dict, end_children: dict, points: dict,
                     specs: list) -> np.ndarray:
    """Unit rest bone direction (J, 3) of every joint; zero for a joint without DoFs and
    without a defined bone."""
    bone_dirs = np.zeros((len(joint_names), 3))
    for j, name in enumerate(joint_names):
        if name == "pelvis":
            bone_dirs[j] = (0.0, 1.0, 0.0)  # the root's yaw axis is the world vertical
        else:
            try:
                bone_dirs[j] = _bone_dir(name, children, end_children, points)
            except ValueError:
                if any(d.joint == name for d in specs):
                    raise
    return bone_dirs


def _joint_axes(name: str, d: np.ndarray, mine: list, points: dict, parent_of: dict) -> np.ndarray:
    """Unit axes (n, 3) of one joint's DoFs ``mine`` about its bone direction ``d``.

    A twist DoF turns about ``±d``; any other turns the bone towards its target,
    ``axis = normalise(d × target⊥)``. Gram-Schmidt makes the axes orthonormal, twist first.
    """
    axes = np.zeros((len(mine), 3))
    done: list = []
    for k in sorted(range(len(mine)), key=lambda k: mine[k].kind != "twist"):
        spec = mine[k]
        target = _direction(spec.target, name, points, parent_of)
        if spec.kind == "twist":
            ref = _direction(spec.ref, name, points, parent_of)
            s = d @ np.cross(ref, target)
            if abs(s) < 1e-3:
                raise ValueError(f"twist {spec.name}: reference and target parallel to the bone")
            a = np.sign(s) * d
        else:
            a = np.cross(d, target - (target @ d) * d)
            for b in done:
                a = a - (a @ b) * b
            a = _unit(a)
        axes[k] = a
        done.append(a)
    return axes


def _joint_kind(name: str, mine: list) -> str:
    """:attr:`Skeleton.joint_kind` of a joint with the DoFs ``mine``."""
    n = len(mine)
    if name == "pelvis":
        return "root"
    if n == 0:
        return "fixed"
    if any(m.kind == "swing" for m in mine):
        if [m.kind for m in mine] != ["swing", "swing", "twist"]:
            raise ValueError(f"swing-twist joint {name} needs (swing, swing, twist) DoFs")
        return "swing_twist"
    return {1: "hinge", 2: "euler2", 3: "euler3"}[n]


def rest_pose(skel: Skeleton) -> np.ndarray:
    """Parameter vector (D,) of the rest pose: angles zero, root at the rest pelvis."""
    p = np.zeros(skel.n_dofs)
    p[skel.translation_dofs] = skel.joints_rest[0]
    return p


def clip_pose(skel: Skeleton, params: np.ndarray) -> np.ndarray:
    """Clip parameters (..., D) to the joint limits; root yaw wraps to [-pi, pi); swing
    vectors of ball joints are shortened to at most SWING_NORM_MAX."""
    p = np.array(params, dtype=np.float64, copy=True)
    p[..., skel.wrap_dofs] = (p[..., skel.wrap_dofs] + np.pi) % (2.0 * np.pi) - np.pi
    wrap = np.zeros(skel.n_dofs, dtype=bool)
    wrap[skel.wrap_dofs] = True
    p[..., ~wrap] = np.clip(p[..., ~wrap], skel.lower[~wrap], skel.upper[~wrap])
    for kind, dofs in zip(skel.joint_kind, skel.joint_dofs):
        if kind == "swing_twist":
            sw = p[..., list(dofs[:2])]
            norm = np.linalg.norm(sw, axis=-1, keepdims=True)
            p[..., list(dofs[:2])] = sw * np.minimum(1.0, SWING_NORM_MAX / np.maximum(norm, 1e-12))
    return p


def pose_to_local_rotations(skel: Skeleton, params: np.ndarray) -> tuple:
    """Pose parameters (B, D) -> local rotations (B, J, 3, 3) and root translation (B, 3).

    Each joint's rotation is the ordered product of its DoFs' exponential maps (eq. 2.11);
    ball joints use swing-twist.  Vectorised over B; a Python loop only over joints.
    """
    params = np.asarray(params, dtype=np.float64)
    if params.ndim != 2 or params.shape[1] != skel.n_dofs:
        raise ValueError(f"params must have shape (B, {skel.n_dofs}), got {params.shape}")
    n = len(params)
    rot = np.empty((n, skel.n_joints, 3, 3))
    rot[:] = np.eye(3)
    for j, (kind, dofs, axes) in enumerate(zip(skel.joint_kind, skel.joint_dofs, skel.joint_axes)):
        if kind == "fixed":
            continue
        if kind == "swing_twist":
            swing = params[:, dofs[0], None] * axes[0] + params[:, dofs[1], None] * axes[1]
            rot[:, j] = rotvec_to_matrix(swing) @ axis_angle_matrix(axes[2], params[:, dofs[2]])
            continue
        m = axis_angle_matrix(axes[0], params[:, dofs[0]])
        for k in range(1, len(dofs)):
            m = m @ axis_angle_matrix(axes[k], params[:, dofs[k]])
        rot[:, j] = m
    return rot, params[:, skel.translation_dofs].copy()


def local_rotations_to_pose(skel: Skeleton, local_rotations: np.ndarray, root_translation,
                            clip: bool = True) -> np.ndarray:
    """Project local rotations (B, J, 3, 3) + root translation (B, 3) onto the parameters.

    Exact inverse of ``pose_to_local_rotations`` inside the limits: Euler decomposition
    in each joint's DoF order (3 DoF), sequential two-axis projection (2 DoF), closed-form
    least-squares hinge angle (1 DoF), swing-twist split for ball joints.  Rotation
    components a joint cannot express (e.g. forearm twist in the tracking set) are
    dropped; joints without DoFs are ignored.  clip=True applies ``clip_pose``.
    """
    r = np.asarray(local_rotations, dtype=np.float64)
    if r.ndim != 4 or r.shape[1:] != (skel.n_joints, 3, 3):
        raise ValueError(f"local_rotations must have shape (B, {skel.n_joints}, 3, 3)")
    n = len(r)
    params = np.zeros((n, skel.n_dofs))
    params[:, skel.translation_dofs] = np.broadcast_to(np.asarray(root_translation, np.float64), (n, 3))
    for j, (kind, dofs, axes) in enumerate(zip(skel.joint_kind, skel.joint_dofs, skel.joint_axes)):
        rj = r[:, j]
        if kind == "fixed":
            continue
        if kind == "hinge":
            params[:, dofs[0]] = hinge_angle(rj, axes[0])
        elif kind == "euler2":
            a, b = euler2_angles(rj, axes[0], axes[1])
            params[:, dofs[0]], params[:, dofs[1]] = a, b
        elif kind in ("euler3", "root"):
            params[:, list(dofs)] = euler3_angles(rj, axes)
        elif kind == "swing_twist":
            params[:, list(dofs)] = swing_twist_angles(rj, axes[:2], axes[2])
        else:  # pragma: no cover - guarded by build_skeleton
            raise ValueError(kind)
    return clip_pose(skel, params) if clip else params


def sample_pose(skel: Skeleton, rng: np.random.Generator, n: int, scale: float = 1.0,
                root_translation=None) -> np.ndarray:
    """Uniform random poses inside the limits (angles shrunk towards 0 by ``scale``).

    Root translation is set to ``root_translation`` (default: the rest pelvis).
    """
    lo, hi = skel.lower * scale, skel.upper * scale
    p = lo + (hi - lo) * rng.random((n, skel.n_dofs))
    p[:, skel.translation_dofs] = skel.joints_rest[0] if root_translation is None else root_translation
    return clip_pose(skel, p)
