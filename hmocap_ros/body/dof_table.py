"""The master table of pose degrees of freedom (thesis sec. 2.3.1, eq. 2.11; the table in
:mod:`hmocap_ros.body.skeleton`'s docstring lists it in degrees).

Each :class:`DofSpec` names its joint, how its axis is derived from the rest skeleton, its
limits, its layer group (sec. 2.5.2) and whether the 30-DoF ``tracking`` set has it. A model
keeps the DoFs whose joints it has (:func:`~hmocap_ros.body.skeleton.build_skeleton`).
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["FINGERS", "DofSpec", "master_dof_table"]

FINGERS = ("thumb", "index", "middle", "ring", "pinky")


@dataclass(frozen=True)
class DofSpec:
    """One degree of freedom of the master table.

    kind: "translation" (axis index in ``target``), "toward" (turns the joint's bone
    towards the direction ``target``), "swing" (same, as one component of a swing-twist
    joint) or "twist" (turns ``ref`` about the bone towards ``target``).  Directions are
    symbolic (see ``skeleton._direction``).  Limits in degrees (metres for translations).
    """

    name: str
    joint: str
    kind: str
    target: str
    lo: float
    hi: float
    group: str
    tracking: bool
    ref: str = ""


def _side_dofs(s: str) -> list:
    t = True
    return [
        DofSpec(f"{s}_clavicle_elev", f"{s}_clavicle", "toward", "up", -15, 35, f"{s}_shoulder", False),
        DofSpec(f"{s}_clavicle_prot", f"{s}_clavicle", "toward", "forward", -20, 25, f"{s}_shoulder", False),
        DofSpec(f"{s}_shoulder_flex", f"{s}_shoulder", "swing", "forward", -70, 170, f"{s}_shoulder", t),
        DofSpec(f"{s}_shoulder_abd", f"{s}_shoulder", "swing", "up", -60, 140, f"{s}_shoulder", t),
        DofSpec(f"{s}_shoulder_twist", f"{s}_shoulder", "twist", "medial", -90, 90, f"{s}_shoulder", t,
                ref="forward"),
        DofSpec(f"{s}_elbow_flex", f"{s}_elbow", "toward", "to_parent", -50, 105, f"{s}_elbow", t),
        DofSpec(f"{s}_elbow_twist", f"{s}_elbow", "twist", "medial", -80, 80, f"{s}_elbow", False,
                ref="forward"),
        DofSpec(f"{s}_wrist_flex", f"{s}_wrist", "toward", "volar", -70, 80, f"{s}_elbow", False),
        DofSpec(f"{s}_wrist_dev", f"{s}_wrist", "toward", "radial", -35, 20, f"{s}_elbow", False),
    ]


def _leg_dofs(s: str) -> list:
    t = True
    return [
        DofSpec(f"{s}_hip_flex", f"{s}_hip", "swing", "forward", -30, 125, f"{s}_leg", t),
        DofSpec(f"{s}_hip_abd", f"{s}_hip", "swing", "lateral", -30, 50, f"{s}_leg", t),
        DofSpec(f"{s}_hip_twist", f"{s}_hip", "twist", "medial", -45, 45, f"{s}_leg", t, ref="forward"),
        DofSpec(f"{s}_knee_flex", f"{s}_knee", "toward", "back", -10, 140, f"{s}_leg", t),
        DofSpec(f"{s}_ankle_flex", f"{s}_ankle", "toward", "up", -50, 30, f"{s}_leg", t),
        DofSpec(f"{s}_ankle_inv", f"{s}_ankle", "twist", "medial", -25, 35, f"{s}_leg", False, ref="down"),
    ]


def _finger_dofs(s: str) -> list:
    """Per hand: thumb CMC 2 + MCP/IP 1 + 1; other fingers MCP 2 (flex, spread) + PIP + DIP."""
    g = f"{s}_hand"
    out = [
        DofSpec(f"{s}_thumb1_flex", f"{s}_thumb1", "toward", "ulnar", -30, 50, g, False),
        DofSpec(f"{s}_thumb1_abd", f"{s}_thumb1", "toward", "volar", -30, 60, g, False),
        DofSpec(f"{s}_thumb2_flex", f"{s}_thumb2", "toward", "thumb_curl", -20, 60, g, False),
        DofSpec(f"{s}_thumb3_flex", f"{s}_thumb3", "toward", "thumb_curl", -20, 85, g, False),
    ]
    for f in FINGERS[1:]:
        out += [
            DofSpec(f"{s}_{f}1_flex", f"{s}_{f}1", "toward", "volar", -20, 95, g, False),
            DofSpec(f"{s}_{f}1_spread", f"{s}_{f}1", "toward", "radial", -25, 25, g, False),
            DofSpec(f"{s}_{f}2_flex", f"{s}_{f}2", "toward", "volar", -10, 110, g, False),
            DofSpec(f"{s}_{f}3_flex", f"{s}_{f}3", "toward", "volar", -10, 80, g, False),
        ]
    return out


def master_dof_table() -> tuple:
    """All DoFs any model may have, in parameter-vector order."""
    t = True
    table = [
        DofSpec("root_tx", "pelvis", "translation", "0", -50, 50, "torso", t),
        DofSpec("root_ty", "pelvis", "translation", "1", -1, 3, "torso", t),
        DofSpec("root_tz", "pelvis", "translation", "2", -50, 50, "torso", t),
        DofSpec("root_yaw", "pelvis", "twist", "left", -180, 180, "torso", t, ref="forward"),
        DofSpec("root_pitch", "pelvis", "toward", "forward", -90, 90, "torso", t),
        DofSpec("root_roll", "pelvis", "toward", "left", -90, 90, "torso", t),
        DofSpec("spine_flex", "spine", "toward", "forward", -30, 80, "torso", t),
        DofSpec("spine_bend", "spine", "toward", "left", -35, 35, "torso", t),
        DofSpec("spine_twist", "spine", "twist", "left", -45, 45, "torso", t, ref="forward"),
        DofSpec("chest_flex", "chest", "toward", "forward", -20, 40, "torso", False),
        DofSpec("chest_bend", "chest", "toward", "left", -20, 20, "torso", False),
        DofSpec("chest_twist", "chest", "twist", "left", -30, 30, "torso", False, ref="forward"),
        DofSpec("neck_flex", "neck", "toward", "forward", -50, 60, "torso", t),
        DofSpec("neck_bend", "neck", "toward", "left", -40, 40, "torso", t),
        DofSpec("neck_twist", "neck", "twist", "left", -70, 70, "torso", t, ref="forward"),
        DofSpec("head_flex", "head", "toward", "forward", -30, 30, "torso", False),
        DofSpec("head_bend", "head", "toward", "left", -20, 20, "torso", False),
        DofSpec("head_twist", "head", "twist", "left", -20, 20, "torso", False, ref="forward"),
    ]
    table += _side_dofs("l") + _side_dofs("r") + _leg_dofs("l") + _leg_dofs("r")
    table += _finger_dofs("l") + _finger_dofs("r")
    return tuple(table)
