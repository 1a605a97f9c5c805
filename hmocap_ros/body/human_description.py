"""REP-155's kinematic model of a person (ROS4HRI ``human_description``) fitted to a tracked body.

ROS4HRI describes a body by the URDF of ``human_description/urdf/human-tpl.xacro``: a root link
``body_<id>`` (x forward, y to the person's left, z up; here the tracker's pelvis joint, the hips
``hip_drop`` below it, where the template has them at the root), a ``waist``
pitch joint under a rigid ``torso`` link at shoulder height, the head on three joints
(``r_head``, ``y_head``, ``p_head``), each arm on ``y_shoulder``, ``p_shoulder``,
``r_shoulder`` and ``elbow``, each leg on ``y_hip``, ``p_hip``, ``r_hip`` and ``knee`` (all
suffixed ``_<id>``, the arms and legs prefixed ``l_`` / ``r_``). ``robot_state_publisher``
turns that URDF and ``humans/bodies/<id>/joint_states`` (the URDF's joint names) into the
body's frames.

- :func:`dimensions_from_joints`: the template's lengths measured on the tracked body (bone
  lengths do not change with the pose; the body's height sets the head);
- :func:`human_urdf`: the template's links, joints, limits and visuals at those lengths;
- :func:`urdf_joint_positions`: the angles of :data:`URDF_JOINTS` that put the URDF's upper
  arms, forearms, thighs, shins and head along the tracked body's (directions from the joint
  positions, the roll of each limb from the plane its elbow or knee bends in);
- :func:`urdf_link_poses`: the forward kinematics of a URDF (what robot_state_publisher
  computes), to check a posed URDF against the tracked body.

No rclpy here.
"""

from __future__ import annotations

from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = ["URDF_JOINTS", "HumanDimensions", "dimensions_from_joints", "human_urdf", "urdf_joint_names",
           "urdf_joint_positions", "urdf_link_poses"]

#: The URDF's movable joints (before ``_<id>``), in joint_states order.
URDF_JOINTS = ("waist", "r_head", "y_head", "p_head",
               "l_y_shoulder", "l_p_shoulder", "l_r_shoulder", "l_elbow",
               "r_y_shoulder", "r_p_shoulder", "r_r_shoulder", "r_elbow",
               "l_y_hip", "l_p_hip", "l_r_hip", "l_knee",
               "r_y_hip", "r_p_hip", "r_r_hip", "r_knee")
#: human_description's radius of the limbs' cylinders (m)
LIMB_RADIUS = 0.03
#: a limb this close to straight (rad) takes its roll from the body's forward axis
_STRAIGHT = 1e-3


@dataclass(frozen=True)
class HumanDimensions:
    """The lengths of human_description's template (metres), named as its xacro properties."""

    head_radius: float
    neck_length: float
    neck_shoulder_length: float
    upperarm_length: float
    forearm_length: float
    torso_height: float
    waist_length: float
    thigh_length: float  # the template's ``tight_length``
    tibia_length: float
    hip_drop: float = 0.0  # the hips' middle below body_<id> (the template: 0)

    @classmethod
    def from_height(cls, height: float = 1.65) -> HumanDimensions:
        """The template's own proportions for a person of ``height`` (its defaults: 1.65 m)."""
        unit = height / 7.5
        return cls(unit / 2, unit * 0.25, unit * 0.8, unit * 1.6, unit, unit * 2.75, unit * 1.2, unit * 1.5,
                   unit * 2)


def _index(joint_names) -> dict:
    return {str(name): k for k, name in enumerate(joint_names)}


def dimensions_from_joints(joint_names, joints: np.ndarray, height: float) -> HumanDimensions:
    """The template's lengths of a tracked body: ``joints`` (J, 3) its joint positions (any
    pose: the lengths are the skeleton's bones), ``joint_names`` the tracking skeleton's
    (``l_shoulder``, ``l_elbow``, ...), ``height`` its standing height (m)."""
    at = _index(joint_names)
    p = np.asarray(joints, dtype=np.float64)

    def length(a: str, b: str) -> float:
        return float(np.mean([np.linalg.norm(p[at[f"{s}_{a}"]] - p[at[f"{s}_{b}"]]) for s in "lr"]))

    pelvis = p[at["pelvis"]]
    hips = (p[at["l_hip"]] + p[at["r_hip"]]) / 2
    shoulders = (p[at["l_shoulder"]] + p[at["r_shoulder"]]) / 2
    head_radius = height / 15.0
    return HumanDimensions(
        head_radius=head_radius,
        neck_length=max(float(np.linalg.norm(p[at["head"]] - shoulders)), 0.02),
        neck_shoulder_length=float(np.linalg.norm(p[at["l_shoulder"]] - p[at["r_shoulder"]])) / 2,
        upperarm_length=length("shoulder", "elbow"), forearm_length=length("elbow", "wrist"),
        torso_height=float(np.linalg.norm(shoulders - pelvis)),
        waist_length=float(np.linalg.norm(p[at["l_hip"]] - p[at["r_hip"]])),
        thigh_length=length("hip", "knee"), tibia_length=length("knee", "ankle"),
        hip_drop=float(np.linalg.norm(hips - pelvis)))


def urdf_joint_names(body_id: str) -> list[str]:
    """The joint_states names of body ``body_id``: :data:`URDF_JOINTS` suffixed ``_<id>``."""
    return [f"{name}_{body_id}" for name in URDF_JOINTS]


# ---------------------------------------------------------------------------------- URDF


def _v(*values: float) -> str:
    return " ".join(f"{v:.6g}" for v in values)


class _Urdf:
    def __init__(self, body_id: str):
        self.id = body_id
        self.lines: list[str] = []

    def link(self, name: str, visuals: tuple = ()) -> None:
        if not visuals:
            self.lines.append(f"  <link name={quoteattr(f'{name}_{self.id}')}/>")
            return
        self.lines.append(f"  <link name={quoteattr(f'{name}_{self.id}')}>")
        for geometry, material, xyz, rpy in visuals:
            self.lines += ["    <visual>", f"      <geometry>{geometry}</geometry>",
                           f"      <material name=\"{material}\"/>",
                           f"      <origin xyz=\"{_v(*xyz)}\" rpy=\"{_v(*rpy)}\"/>", "    </visual>"]
        self.lines.append("  </link>")

    def joint(self, name: str, parent: str, child: str, xyz=(0.0, 0.0, 0.0), axis=None, limits=None) -> None:
        kind = "fixed" if axis is None else "revolute"
        self.lines += [f"  <joint name={quoteattr(f'{name}_{self.id}')} type=\"{kind}\">",
                       f"    <parent link={quoteattr(f'{parent}_{self.id}')}/>",
                       f"    <child link={quoteattr(f'{child}_{self.id}')}/>",
                       f"    <origin xyz=\"{_v(*xyz)}\" rpy=\"0 0 0\"/>"]
        if axis is not None:
            lower, upper = limits
            self.lines += [f"    <axis xyz=\"{_v(*axis)}\"/>",
                           f"    <limit effort=\"1000\" lower=\"{lower:g}\" upper=\"{upper:g}\" velocity=\"0.5\"/>"]
        self.lines.append("  </joint>")


def _cylinder(length: float, xyz, rpy=(0.0, 0.0, 0.0), material: str = "yellow-skin") -> tuple:
    return (f"<cylinder length=\"{length:.6g}\" radius=\"{LIMB_RADIUS:g}\"/>", material, xyz, rpy)


def _sphere(radius: float, xyz, material: str = "yellow-skin") -> tuple:
    return (f"<sphere radius=\"{radius:.6g}\"/>", material, xyz, (0.0, 0.0, 0.0))


def human_urdf(body_id: str, dims: HumanDimensions) -> str:
    """human_description's URDF of body ``body_id`` at the lengths ``dims``: the template's
    links, joints (names, axes, limits) and visuals, the joint origins scaled to ``dims``."""
    d = dims
    u = _Urdf(body_id)
    u.lines += ["<?xml version=\"1.0\"?>", f"<robot name={quoteattr(f'human_{body_id}')}>",
                "  <material name=\"yellow-skin\"><color rgba=\"1 0.7 0 1\"/></material>",
                "  <material name=\"yellow-skin-dark\"><color rgba=\"0.9 0.6 0 1\"/></material>",
                "  <material name=\"black\"><color rgba=\"0 0 0 1\"/></material>"]
    th, wl = d.torso_height, d.waist_length
    u.link("body")
    u.link("waist")
    u.link("torso", (
        _cylinder(3 * th / 4, (0, 0, -3 * th / 8)),
        _cylinder(2 * d.neck_shoulder_length, (0, 0, 0), (np.pi / 2, 0, 0)),
        _cylinder(wl / 1.41, (0, -wl / 4, -7 * th / 8), (-np.pi / 4, 0, 0)),
        _cylinder(wl / 1.41, (0, wl / 4, -7 * th / 8), (np.pi / 4, 0, 0)),
        _sphere(LIMB_RADIUS, (0, 0, -3 * th / 4))))
    u.joint("waist", "body", "waist", axis=(0, 1, 0), limits=(-0.2, 1.0))
    u.joint("torso", "waist", "torso", xyz=(0, 0, th))
    hr = d.head_radius
    for name in ("r_head", "y_head", "p_head"):
        u.link(name)
    u.link("head", (_sphere(hr, (-hr / 2, 0, 0)),
                    _sphere(hr / 5, (hr * 0.9 - hr / 2, 2 * hr / 5, 0), "black"),
                    _sphere(hr / 5, (hr * 0.9 - hr / 2, -2 * hr / 5, 0), "black")))
    u.joint("r_head", "torso", "r_head", xyz=(0, 0, d.neck_length), axis=(1, 0, 0), limits=(-1.0, 1.0))
    u.joint("y_head", "r_head", "y_head", axis=(0, 0, 1), limits=(-1.4, 1.4))
    u.joint("p_head", "y_head", "p_head", axis=(0, -1, 0), limits=(-1.5, 1.5))
    u.joint("head", "p_head", "head", xyz=(hr / 2, 0, hr))
    for side, reflect in (("l", 1), ("r", -1)):
        _limb(u, side, reflect, "torso", ("shoulder", "elbow", "wrist"), (0, reflect * d.neck_shoulder_length, 0),
              (d.upperarm_length, d.forearm_length), arm=True)
    for side, reflect in (("l", 1), ("r", -1)):
        _limb(u, side, reflect, "body", ("hip", "knee", "ankle"), (0, reflect * wl / 2, -d.hip_drop),
              (d.thigh_length, d.tibia_length), arm=False)
    u.lines.append("</robot>")
    return "\n".join(u.lines) + "\n"


def _limb(u: _Urdf, side: str, reflect: int, parent: str, names: tuple, origin: tuple, lengths: tuple,
          arm: bool) -> None:
    """An arm or a leg of the template (its ``arm`` / ``leg`` macros)."""
    root, middle, end = (f"{side}_{n}" for n in names)
    upper, lower = lengths
    dark = (_sphere(LIMB_RADIUS, (0, 0, 0), "yellow-skin-dark"),)
    u.link(f"{side}_y_{names[0]}", dark)
    u.link(f"{side}_p_{names[0]}")
    u.joint(f"{side}_y_{names[0]}", parent, f"{side}_y_{names[0]}", xyz=origin,
            axis=(0, 0, -reflect) if arm else (0, 0, -1), limits=(-1.1, 1.9) if arm else (-0.1, 0.6))
    u.joint(f"{side}_p_{names[0]}", f"{side}_y_{names[0]}", f"{side}_p_{names[0]}", axis=(reflect, 0, 0),
            limits=(-0.4, 3.3))
    for link, length in ((root, upper), (middle, lower)):
        u.link(link, (_cylinder(length, (0, 0, -length / 2)), _sphere(LIMB_RADIUS, (0, 0, -length))))
    u.joint(f"{side}_r_{names[0]}", f"{side}_p_{names[0]}", root,
            axis=(0, 0, reflect) if arm else (0, -1, 0), limits=(-1.7, 1.5) if arm else (-0.4, 0.7))
    u.joint(middle, root, middle, xyz=(0, 0, -upper), axis=(0, -1, 0), limits=(0.0, 2.5) if arm else (-2.5, 0.0))
    u.link(end)
    u.joint(end, middle, end, xyz=(0, 0, -lower))


# ---------------------------------------------------------------------------------- angles


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    return v / n if n > 1e-12 else v


def _limb_frame(upper: np.ndarray, lower: np.ndarray, forward: np.ndarray, bend: float) -> tuple:
    """The frame of a limb segment hanging along -z whose next segment bends towards
    ``bend`` * x (+1: elbows forward, -1: knees backward), and the bend angle."""
    z = -_unit(upper)
    lower = _unit(lower)
    angle = float(np.arccos(np.clip(np.dot(-z, lower), -1.0, 1.0)))
    across = lower - np.dot(lower, z) * z
    if angle < _STRAIGHT or np.linalg.norm(across) < 1e-9:
        across = bend * (forward - np.dot(forward, z) * z)
    x = bend * _unit(across)
    return np.column_stack([x, np.cross(z, x), z]), angle


def _arm_angles(rot: np.ndarray, reflect: int) -> tuple:
    """(y, p, r) of an arm whose frame is ``rot`` = Rz(-reflect y) Rx(reflect p) Rz(reflect r)."""
    b = reflect * float(np.arccos(np.clip(rot[2, 2], -1.0, 1.0)))  # p >= 0, within the limits
    sb = np.sin(b)
    if abs(sb) < 1e-6:  # hanging straight: the yaw and the roll turn about one axis
        a, c = 0.0, float(np.arctan2(rot[1, 0], rot[0, 0]))
    else:
        c = float(np.arctan2(rot[2, 0] / sb, rot[2, 1] / sb))
        a = float(np.arctan2(rot[0, 2] / sb, -rot[1, 2] / sb))
    return -reflect * a, reflect * b, reflect * c


def _leg_angles(rot: np.ndarray, reflect: int) -> tuple:
    """(y, p, r) of a leg whose frame is ``rot`` = Rz(-y) Rx(reflect p) Ry(-r)."""
    beta = float(np.arcsin(np.clip(rot[2, 1], -1.0, 1.0)))
    alpha = float(np.arctan2(-rot[0, 1], rot[1, 1]))
    gamma = float(np.arctan2(-rot[2, 0], rot[2, 2]))
    return -alpha, reflect * beta, -gamma


def _head_angles(rot: np.ndarray) -> tuple:
    """(r, y, p) of the head whose frame in the torso's is ``rot`` = Rx(r) Rz(y) Ry(-p)."""
    beta = float(np.arcsin(np.clip(-rot[0, 1], -1.0, 1.0)))
    alpha = float(np.arctan2(rot[2, 1], rot[1, 1]))
    gamma = float(np.arctan2(rot[0, 2], rot[0, 0]))
    return alpha, beta, -gamma


def _ry(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def urdf_joint_positions(joint_names, joints: np.ndarray, body_rotation: np.ndarray,
                         head_rotation: np.ndarray | None = None) -> np.ndarray:
    """The angles of :data:`URDF_JOINTS` (rad) for a tracked pose.

    joints: (J, 3) joint positions in the room, ``joint_names`` the tracking skeleton's;
    body_rotation: the body frame ``body_<id>`` (at the ``pelvis`` joint) in the room (3x3, REP-155 axes: x forward,
    y left, z up); head_rotation: the head's frame in the room, same axes (None: the head
    keeps the torso's orientation). The waist pitches the torso towards the shoulders' middle;
    each upper arm, forearm, thigh and shin of the URDF then points along the tracked one, each
    limb rolled so that its elbow or knee bends in the tracked limb's plane.
    """
    at = _index(joint_names)
    p = np.asarray(joints, dtype=np.float64)
    body = np.asarray(body_rotation, dtype=np.float64)

    def local(frame: np.ndarray, a: str, b: str) -> np.ndarray:
        return frame.T @ (p[at[b]] - p[at[a]])

    shoulders = body.T @ ((p[at["l_shoulder"]] + p[at["r_shoulder"]]) / 2 - p[at["pelvis"]])
    waist = float(np.arctan2(shoulders[0], shoulders[2]))
    torso = body @ _ry(waist)
    out = {"waist": waist}
    head = np.eye(3) if head_rotation is None else torso.T @ np.asarray(head_rotation, dtype=np.float64)
    out["r_head"], out["y_head"], out["p_head"] = _head_angles(head)
    forward = np.array([1.0, 0.0, 0.0])
    for side, reflect in (("l", 1), ("r", -1)):
        rot, elbow = _limb_frame(local(torso, f"{side}_shoulder", f"{side}_elbow"),
                                 local(torso, f"{side}_elbow", f"{side}_wrist"), forward, 1.0)
        angles = _arm_angles(rot, reflect)
        for name, value in zip(("y_shoulder", "p_shoulder", "r_shoulder"), angles):
            out[f"{side}_{name}"] = value
        out[f"{side}_elbow"] = elbow
        rot, knee = _limb_frame(local(body, f"{side}_hip", f"{side}_knee"),
                                local(body, f"{side}_knee", f"{side}_ankle"), forward, -1.0)
        angles = _leg_angles(rot, reflect)
        for name, value in zip(("y_hip", "p_hip", "r_hip"), angles):
            out[f"{side}_{name}"] = value
        out[f"{side}_knee"] = -knee
    return np.array([out[name] for name in URDF_JOINTS])


def _attribute(element, path: str, name: str, default: str | None = None) -> str:
    """The attribute ``name`` of ``element``'s child ``path`` (ValueError when missing)."""
    child = element.find(path)
    value = default if child is None else child.get(name, default)
    if value is None:
        raise ValueError(f"joint {element.get('name')!r}: no {path} {name}")
    return value


def urdf_link_poses(urdf: str, angles: dict, root_pose: np.ndarray) -> dict:
    """Every link's 4x4 pose from a URDF's joints (fixed and revolute) at ``angles`` (joint name
    -> rad; missing: 0), its root link at ``root_pose``. ValueError for a URDF whose links do
    not form one tree."""
    import xml.etree.ElementTree as ET

    tree = ET.fromstring(urdf)
    links = {str(link.get("name")) for link in tree.findall("link")}
    joints = {_attribute(j, "child", "link"): j for j in tree.findall("joint")}
    if len(joints) != len(tree.findall("joint")) or not set(joints) <= links:
        raise ValueError("a link with two parents, or a joint of an undeclared link")
    roots = links - set(joints)
    if len(roots) != 1:
        raise ValueError(f"the URDF has {len(roots)} root links, not one")
    poses = {roots.pop(): np.asarray(root_pose, dtype=np.float64)}

    def pose(link: str, depth: int = 0) -> np.ndarray:
        if link not in poses:
            joint = joints[link]
            parent = _attribute(joint, "parent", "link")
            if parent not in links or depth > len(links):
                raise ValueError(f"link {link!r} does not hang from the root")
            local = np.eye(4)
            local[:3, 3] = [float(v) for v in _attribute(joint, "origin", "xyz", "0 0 0").split()]
            rpy = [float(v) for v in _attribute(joint, "origin", "rpy", "0 0 0").split()]
            local[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()
            if joint.get("type") in ("revolute", "continuous"):
                axis = np.array([float(v) for v in _attribute(joint, "axis", "xyz").split()])
                turn = np.eye(4)
                turn[:3, :3] = Rotation.from_rotvec(axis * angles.get(joint.get("name"), 0.0)).as_matrix()
                local = local @ turn
            poses[link] = pose(parent, depth + 1) @ local
        return poses[link]

    for link in links:
        pose(link)
    return poses
