"""Simulated subjects of the gesture set and the forward kinematics of their poses.

A :class:`Subject` is a ``hands`` body (thesis table 2.1 priors plus clothing) with body
landmarks (palm centres, mouth, ears, sternum) rigidly attached to joints; :func:`kinematics`
poses its skeleton and landmarks, :func:`posed_vertices` skins its mesh (eq. 2.12).

Frames are the body model's (``skeleton.py``): metres, +Y up, the body faces +Z, +X is the
person's left; sides are ``"l"`` and ``"r"`` (the person's left and right).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from hmocap_ros.body import BodyShape, apply_shape, load_body_model, sample_shape
from hmocap_ros.body.kinematics import (
    end_site_positions,
    forward_kinematics,
    skin_vertices,
    skinning_matrices,
)
from hmocap_ros.body.rotations import axis_angle_matrix, rotvec_to_matrix
from hmocap_ros.body.skeleton import pose_to_local_rotations

SIDES = ("l", "r")
FORWARD = np.array([0.0, 0.0, 1.0])
UP = np.array([0.0, 1.0, 0.0])
LEFT = np.array([1.0, 0.0, 0.0])
# Seed stream of subject identities: a subject's body depends on its id only, so sets
# generated with disjoint ids (``--subject-offset``) never share a person.
SUBJECT_STREAM = 0x6E57
FINGER_NAMES = ("index", "middle", "ring", "pinky")


def lateral(side: str) -> np.ndarray:
    """Unit vector away from the body midline on ``side`` (body frame)."""
    return LEFT if side == "l" else -LEFT


def other(side: str) -> str:
    """The other hand's side."""
    return "r" if side == "l" else "l"


def unit(v):
    """``v`` divided by its length (along the last axis)."""
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)



@dataclass(frozen=True, eq=False)
class Subject:
    """One simulated person: body shape (with clothing girth) and its shaped rest geometry.

    landmarks: name -> (joint index, rest position): body points rigidly attached to a
    joint (palm centres, mouth, ears, sternum), posed with :func:`landmark_positions`.
    """

    subject_id: int
    shape: BodyShape
    rest_joints: np.ndarray
    rest_ends: np.ndarray
    rest_vertices: np.ndarray
    landmarks: dict
    height: float


@lru_cache(maxsize=None)
def _landmark_vertices() -> dict:
    """Vertex indices (on the ``hands`` mesh) of the head and torso landmarks, found once
    on the rest mesh: the lips (front-most head vertex 3.5-4.5 cm below the head joint),
    the ears (outer-most head vertices 1-4 cm above it) and the sternum."""
    model = load_body_model("hands")
    v = np.asarray(model.vertices, dtype=np.float64)
    part = np.asarray(model.vertex_part)
    head_j = model.joints_rest[model.joint_index("head")]
    chest_j = model.joints_rest[model.joint_index("chest")]
    idx = np.arange(len(v))
    head = idx[part == model.joint_index("head")]
    dy = v[head, 1] - head_j[1]
    band = head[(dy > -0.045) & (dy < -0.035) & (np.abs(v[head, 0]) < 0.015)]
    mouth = int(band[np.argmax(v[band, 2])])
    ears = {}
    band = head[(dy > 0.01) & (dy < 0.04)]
    ears["l"] = int(band[np.argmax(v[band, 0])])
    ears["r"] = int(band[np.argmin(v[band, 0])])
    torso = idx[np.isin(part, [model.joint_index("chest"), model.joint_index("spine")])]
    band = torso[(np.abs(v[torso, 0]) < 0.02) & (np.abs(v[torso, 1] - (chest_j[1] - 0.03)) < 0.02)]
    sternum = int(band[np.argmax(v[band, 2])])
    return {"mouth": mouth, "l_ear": ears["l"], "r_ear": ears["r"], "sternum": sternum}


def make_subject(model, subject_id: int) -> Subject:
    """The subject with identity ``subject_id``: a body from the table 2.1 priors
    (``sample_shape``) plus clothing (looser torso/arm/leg girth), seeded by the id alone."""
    rng = np.random.default_rng([SUBJECT_STREAM, int(subject_id)])
    shape = sample_shape(rng)
    bone, radial = shape.bone_scale.copy(), shape.radial_scale.copy()
    names = list(shape.entity_names)
    # Clothing: a jacket or jumper thickens torso and arms, trousers the legs, hair the head.
    jacket = rng.uniform(1.0, 1.12)
    for name, gain in (("torso_width", jacket), ("torso_depth", jacket),
                       ("upperarms", rng.uniform(1.0, 1.12)), ("lowerarms", rng.uniform(1.0, 1.1)),
                       ("legs", rng.uniform(1.0, 1.08)), ("head", rng.uniform(1.0, 1.08))):
        radial[names.index(name)] *= gain
    shape = BodyShape(bone, radial, float(shape.global_scale) * rng.uniform(0.97, 1.06))
    rest = apply_shape(model, shape)
    joints = np.asarray(rest.joints, dtype=np.float64)
    ends = np.asarray(rest.end_sites, dtype=np.float64)
    verts = np.asarray(rest.vertices, dtype=np.float64)
    j = model.joint_index
    lm = {}
    for s in SIDES:
        knuckles = np.mean([joints[j(f"{s}_{f}1")] for f in ("index", "middle", "ring", "pinky")], 0)
        lm[f"{s}_palm"] = (j(f"{s}_wrist"), 0.5 * joints[j(f"{s}_wrist")] + 0.5 * knuckles)
    vid = _landmark_vertices()
    for name in ("mouth", "l_ear", "r_ear"):
        lm[name] = (j("head"), verts[vid[name]])
    lm["sternum"] = (j("chest"), verts[vid["sternum"]])
    height = float(verts[:, 1].max() - verts[:, 1].min())
    return Subject(int(subject_id), shape, joints, ends, verts, lm, height)


# Seed stream of a subject's clothing reflectance (apart from SUBJECT_STREAM: the body stays).
ALBEDO_STREAM = 0x41B0
#: Near-infrared diffuse reflectance of skin (hands, head) at 830-850 nm.
SKIN_ALBEDO = 0.5
#: Range of a subject's clothing reflectance: black synthetics absorb the projector's light
#: (a few per cent), light cotton returns most of it.
CLOTHING_ALBEDO = (0.03, 0.7)
_SKIN_JOINTS = ("head", "neck", "l_wrist", "r_wrist")


def body_albedo(model, subject_id: int) -> np.ndarray:
    """Per-face near-infrared albedo (F,) of the subject ``subject_id``'s body: skin on the
    hands (wrist and finger joints) and the head, its clothing (one value drawn from
    :data:`CLOTHING_ALBEDO` by the id alone) elsewhere."""
    clothing = np.random.default_rng([ALBEDO_STREAM, int(subject_id)]).uniform(*CLOTHING_ALBEDO)
    names = model.joint_names
    skin = [i for i, n in enumerate(names)
            if n in _SKIN_JOINTS or any(f in n for f in ("thumb", *FINGER_NAMES))]
    part = np.asarray(model.vertex_part)[np.asarray(model.faces)[:, 0]]
    return np.where(np.isin(part, skin), np.float32(SKIN_ALBEDO), np.float32(clothing)).astype(np.float32)


@dataclass(frozen=True, eq=False)
class Kinematics:
    """Posed skeleton of a batch: global transforms (B, J, 4, 4), joints (B, J, 3), end
    sites (B, E, 3) and landmarks name -> (B, 3)."""

    transforms: np.ndarray
    joints: np.ndarray
    ends: np.ndarray
    landmarks: dict

    def point(self, model, name: str) -> np.ndarray:
        """(B, 3) position of a joint, end site or landmark by name."""
        if name in self.landmarks:
            return self.landmarks[name]
        if name in model.joint_names:
            return self.joints[:, model.joint_index(name)]
        return self.ends[:, model.end_site_names.index(name)]


def posed_vertices(model, subject: Subject, params: np.ndarray) -> np.ndarray:
    """Skinned mesh vertices (V, 3) float32 of one pose of ``subject`` (eq. 2.12 on its
    shaped rest mesh, without re-shaping it as ``model.forward`` does)."""
    kin = kinematics(model, subject, params)
    mats = skinning_matrices(kin.transforms, subject.rest_joints)
    return skin_vertices(mats, subject.rest_vertices, model.sparse_weights)[0]


def _local_rotations(skel, params: np.ndarray, joints, base: np.ndarray) -> np.ndarray:
    """``pose_to_local_rotations`` for the listed joints only, the others taken from
    ``base`` (J, 3, 3): the IK changes a few joints, and rebuilding all 49 dominates."""
    rot = np.repeat(base[None], len(params), axis=0)
    for j in joints:
        kind, dofs, axes = skel.joint_kind[j], skel.joint_dofs[j], skel.joint_axes[j]
        if kind == "swing_twist":
            swing = params[:, dofs[0], None] * axes[0] + params[:, dofs[1], None] * axes[1]
            rot[:, j] = rotvec_to_matrix(swing) @ axis_angle_matrix(axes[2], params[:, dofs[2]])
        elif kind != "fixed":
            m = axis_angle_matrix(axes[0], params[:, dofs[0]])
            for k in range(1, len(dofs)):
                m = m @ axis_angle_matrix(axes[k], params[:, dofs[k]])
            rot[:, j] = m
    return rot


def kinematics(model, subject: Subject, params: np.ndarray, base_rotations: np.ndarray | None = None,
               joints=()) -> Kinematics:
    """Forward kinematics (no skinning) of parameter vectors (B, D) for one subject.

    With ``base_rotations`` (J, 3, 3), only the local rotations of ``joints`` are rebuilt
    from ``params`` (a speed-up for the IK, which moves a few joints and never the root).
    """
    params = np.atleast_2d(np.asarray(params, dtype=np.float64))
    if base_rotations is None:
        rot, root_t = pose_to_local_rotations(model.skeleton, params)
    else:
        rot = _local_rotations(model.skeleton, params, joints, base_rotations)
        root_t = params[:, model.skeleton.translation_dofs]
    tf, joints = forward_kinematics(rot, root_t, subject.rest_joints, model.parents)
    ends = end_site_positions(tf, subject.rest_ends, model.end_site_parents, subject.rest_joints)
    lm = {}
    for name, (ji, x) in subject.landmarks.items():
        lm[name] = tf[:, ji, :3, 3] + np.einsum("bik,k->bi", tf[:, ji, :3, :3], x - subject.rest_joints[ji])
    return Kinematics(tf, joints, ends, lm)


@lru_cache(maxsize=None)
def _rest_hand_axes(side: str) -> np.ndarray:
    """Rest (d, radial, volar) unit vectors of one hand (rows), as ``skeleton._hand_frame``:
    d = wrist -> middle fingertip, radial = pinky -> index knuckle (thumb side), volar =
    palm normal (out of the palm)."""
    model = load_body_model("hands")
    lmk = model.landmarks
    wrist = model.joints_rest[model.joint_index(f"{side}_wrist")]
    tip = model.end_sites_rest[model.end_site_names.index(f"{side}_hand_tip")]
    d = unit(tip - wrist)
    radial = lmk[f"{side}_index_knuckle"] - lmk[f"{side}_pinky_knuckle"]
    radial = unit(radial - (radial @ d) * d)
    volar = np.cross(d, radial) if side == "l" else np.cross(radial, d)
    return np.stack([d, radial, unit(volar)])


def hand_axes(model, kin: Kinematics, side: str) -> tuple:
    """Posed (d, radial, volar) of a hand, each (B, 3): fingers direction, thumb side, palm normal."""
    g = kin.transforms[:, model.joint_index(f"{side}_wrist"), :3, :3]
    axes = _rest_hand_axes(side)
    return tuple(np.einsum("bik,k->bi", g, a) for a in axes)


def hand_joints(model, side: str) -> list:
    """Joint indices of one hand (wrist and finger joints): its skin is "the hand"."""
    names = [f"{side}_wrist"] + [f"{side}_{f}{k}" for f in ("thumb",) + FINGER_NAMES for k in (1, 2, 3)]
    return [model.joint_index(n) for n in names]
