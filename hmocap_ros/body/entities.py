"""Anthropometric entities (thesis table 2.1, plus a few needed to generate whole subjects).

An entity has a bone scale and a radial scale factor (1 = the model's own proportions); a
bone or segment that belongs to several entities gets the product of their factors, e.g. the
thesis' "shoulder height" scales all torso and leg bones together while "legs" and "torso"
refine them separately. The deformation they drive is :mod:`hmocap_ros.body.shape_deformation`;
their sizes and priors are in :mod:`hmocap_ros.body.anthropometry`.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ENTITIES", "ENTITY_NAMES", "LEG_BONES", "TABLE_2_1", "TORSO_BONES", "Entity"]


@dataclass(frozen=True)
class Entity:
    """One anthropometric entity: the bones it scales, the segments it thickens, its size.

    bones: child names (joint or end site) of the bones; "hands" in a name list expands
    to all hand/finger bones of the model.  radial_mode: "iso", "x" or "z".
    prior_cm = (M_k, sigma_k^2) from thesis table 2.1, or None (then rel_std applies).
    sampled: whether ``sample_shape`` draws it (aggregates are left at 1 so that sampled
    sizes follow the table's spreads).
    """

    name: str
    bones: tuple
    radial: tuple
    size: str
    prior_cm: tuple | None = None
    rel_std: float = 0.05
    radial_mode: str = "iso"
    sampled: bool = True


TORSO_BONES = ("spine", "chest", "neck", "l_clavicle", "r_clavicle")
LEG_BONES = ("l_knee", "l_ankle", "r_knee", "r_ankle")

ENTITIES = (
    Entity("shoulder_height", TORSO_BONES + LEG_BONES, (), "shoulder_height", (140.0, 17.0),
           sampled=False),
    Entity("head", ("head", "head_top"), ("head",), "head", (25.0, 5.0)),
    Entity("clavicles", ("l_shoulder", "r_shoulder"), (), "clavicles", (35.0, 7.0)),
    Entity("arms", ("l_elbow", "l_wrist", "r_elbow", "r_wrist"),
           ("l_shoulder", "l_elbow", "r_shoulder", "r_elbow"), "arms", (55.5, 10.0), sampled=False),
    Entity("upperarms", ("l_elbow", "r_elbow"), ("l_shoulder", "r_shoulder"), "upperarms", (25.5, 4.0)),
    Entity("lowerarms", ("l_wrist", "r_wrist"), ("l_elbow", "r_elbow"), "lowerarms", (30.5, 10.0)),
    Entity("legs", LEG_BONES, ("l_hip", "l_knee", "r_hip", "r_knee"), "legs", (90.5, 17.0)),
    Entity("torso", TORSO_BONES, ("pelvis", "spine", "chest"), "torso", (52.0, 8.0)),
    Entity("lowerlegs", ("l_ankle", "r_ankle"), ("l_knee", "r_knee"), "lowerlegs", rel_std=0.03),
    Entity("hip_width", ("l_hip", "r_hip"), (), "hip_width", rel_std=0.06),
    Entity("torso_width", (), ("pelvis", "spine", "chest"), "torso_width", rel_std=0.07,
           radial_mode="x"),
    Entity("torso_depth", (), ("pelvis", "spine", "chest"), "torso_depth", rel_std=0.07,
           radial_mode="z"),
    Entity("hands", ("hands",), ("hands",), "hands", rel_std=0.05),
    Entity("feet", ("l_toe", "r_toe"), ("l_ankle", "r_ankle"), "feet", rel_std=0.05),
)
ENTITY_NAMES = tuple(e.name for e in ENTITIES)
# Table 2.1 verbatim: entity -> (mean M_k in cm, variance sigma_k^2 in cm^2).
TABLE_2_1 = {e.name: e.prior_cm for e in ENTITIES if e.prior_cm is not None}
