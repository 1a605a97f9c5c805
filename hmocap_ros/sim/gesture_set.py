"""Static hand/arm gestures of thesis ch. 3 as parametrised poses of the ``hands`` body model.

The six gesture classes of thesis fig. 3.4 / table 3.2, in the fixed order of
:data:`GESTURE_CLASSES` (``class_id`` = index + 1; 0 is background and never labelled):

====  ===========  ==========================================================  ===========================
 id   name         pose                                                        reference point (u, v)
====  ===========  ==========================================================  ===========================
 1    tee          "time out": one hand vertical in front of the chest, the    the hands' contact point:
                   other flat on its fingertips, palm down (a T of hands)      the stem's middle fingertip
 2    pause        one arm raised, open palm towards the camera, fingers up    palm centre
 3    silence      index finger vertical on the lips, other fingers curled     the finger-on-lips point
                                                                               (index finger at the mouth)
 4    cross        forearms crossed in an X in front of the chest              forearm crossing point
 5    ok           thumb-index ring, other fingers extended, hand raised,      palm centre
                   palm turned 30-60 deg from the camera so the ring faces it
 6    volume_up    hand cupped behind the ear, palm forwards ("Audio" / "Vol   palm centre
                   up" in the thesis)
====  ===========  ==========================================================  ===========================

Tee is the hand "time out" T of the thesis' dataset (fig. 3.3), not arms spread in a T:
its annotation is the point where the fingertips of the vertical hand meet the palm of the
horizontal one.  The reference point is a body point (rigidly attached to a joint, so it
moves with the pose); the simulator projects it to get the pixel (u, v) and takes the 3D
position from the rendered surface at that pixel (``gesture_dataset``).

Negative (non-gesture) poses, :data:`NEGATIVE_KINDS`: idle standing, walking, random arm
poses and near misses of the gestures (arms folded, chin on the fist, phone at the ear,
pointing, scratching the head, hands on the hips, hands clasped, waving with the hand
sideways).

Every pose is built on the full DoF set (wrists, forearm twist, clavicles, 20 finger DoF
per hand) by a small damped least-squares inverse kinematics over the arm and finger DoFs
(numeric Jacobian, joint limits, a prior towards a natural arm, weak elbow hints, restarts
when a position target is missed), with per-sample random variation: target positions,
hand orientations, finger angles, which hand, torso lean and twist, head, legs.  The
gesture geometry (finger on the lips within 5 cm, thumb tip on index tip within 3 cm, palm
facing the camera, forearms crossing in front of the chest, hand at the ear, fingertips on
the other palm) is checked by ``test/test_sim_gestures.py``.
Poses are solved with the body at the origin facing +Z (root yaw 0) and placed afterwards
with :func:`place` (body yaw, position on the floor); anything that should face the camera
(the palm of pause and ok) is solved towards the camera position given in that body frame.

Frames are the body model's (``skeleton.py``): metres, +Y up, the body faces +Z, +X is the
person's left; sides are ``"l"`` and ``"r"`` (the person's left and right).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from hmocap_ros.body import BodyShape, apply_shape, load_body_model, sample_shape
from hmocap_ros.body.kinematics import (end_site_positions, forward_kinematics, skin_vertices,
                                        skinning_matrices)
from hmocap_ros.body.rotations import axis_angle_matrix, rotvec_to_matrix
from hmocap_ros.body.skeleton import clip_pose, pose_to_local_rotations

#: Gesture classes in class-id order: ``class_id = GESTURE_CLASSES.index(name) + 1``.
GESTURE_CLASSES = ("tee", "pause", "silence", "cross", "ok", "volume_up")

#: Where each gesture's annotated point is (see the module docstring).
REFERENCE_POINTS = {
    "tee": "contact point of the two hands (middle fingertip of the vertical hand)",
    "pause": "palm centre of the raised hand",
    "silence": "index finger on the lips (the mouth point, on the finger)",
    "cross": "crossing point of the two forearms (midpoint of their axes' closest approach)",
    "ok": "palm centre of the ok hand",
    "volume_up": "palm centre of the hand cupped at the ear",
}

#: Non-gesture pose kinds (background class): motion, idle and near misses.
NEGATIVE_KINDS = ("idle", "walk", "random_arms", "fold_arms", "chin", "phone", "point",
                  "scratch_head", "hips", "clasp", "wave_side")

SIDES = ("l", "r")
FORWARD = np.array([0.0, 0.0, 1.0])
UP = np.array([0.0, 1.0, 0.0])
LEFT = np.array([1.0, 0.0, 0.0])
# Seed stream of subject identities: a subject's body depends on its id only, so sets
# generated with disjoint ids (``--subject-offset``) never share a person.
SUBJECT_STREAM = 0x6E57


def class_id(name: str) -> int:
    """1-based class id of a gesture name (0 is background)."""
    return GESTURE_CLASSES.index(name) + 1


def lateral(side: str) -> np.ndarray:
    """Unit vector away from the body midline on ``side`` (body frame)."""
    return LEFT if side == "l" else -LEFT


def other(side: str) -> str:
    return "r" if side == "l" else "l"


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# ---------------------------------------------------------------------------------------
# Subjects and body landmarks
# ---------------------------------------------------------------------------------------


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
    d = _unit(tip - wrist)
    radial = lmk[f"{side}_index_knuckle"] - lmk[f"{side}_pinky_knuckle"]
    radial = _unit(radial - (radial @ d) * d)
    volar = np.cross(d, radial) if side == "l" else np.cross(radial, d)
    return np.stack([d, radial, _unit(volar)])


def hand_axes(model, kin: Kinematics, side: str) -> tuple:
    """Posed (d, radial, volar) of a hand, each (B, 3): fingers direction, thumb side, palm normal."""
    g = kin.transforms[:, model.joint_index(f"{side}_wrist"), :3, :3]
    axes = _rest_hand_axes(side)
    return tuple(np.einsum("bik,k->bi", g, a) for a in axes)


# ---------------------------------------------------------------------------------------
# Inverse kinematics
# ---------------------------------------------------------------------------------------


@dataclass
class Task:
    """One IK objective, weighted (weights are per metre for positions, per unit vector
    for directions).

    kind "point": point ``a`` at ``target``; "touch": points ``a`` and ``b`` together
    (``target`` an offset b - a, default 0); "dir": unit direction ``a`` -> ``b`` along
    ``target``; "axis": hand axis ``a`` ("l_volar", "r_d", "l_radial", ...) along
    ``target``.
    """

    kind: str
    a: str
    target: np.ndarray | None = None
    b: str = ""
    weight: float = 1.0


def _task_residuals(model, kin: Kinematics, tasks) -> np.ndarray:
    out = []
    for t in tasks:
        if t.kind == "point":
            out.append(t.weight * (kin.point(model, t.a) - t.target))
        elif t.kind == "touch":
            off = 0.0 if t.target is None else t.target
            out.append(t.weight * (kin.point(model, t.b) - kin.point(model, t.a) - off))
        elif t.kind == "dir":
            d = _unit(kin.point(model, t.b) - kin.point(model, t.a))
            out.append(t.weight * (d - t.target))
        elif t.kind == "axis":
            side, axis = t.a.split("_")
            d, radial, volar = hand_axes(model, kin, side)
            v = {"d": d, "radial": radial, "volar": volar}[axis]
            out.append(t.weight * (v - t.target))
        else:  # pragma: no cover - programming error
            raise ValueError(f"unknown IK task kind {t.kind!r}")
    return np.concatenate(out, axis=1)


def solve_ik(model, subject: Subject, params: np.ndarray, dof_names, tasks, *,
             prior: dict | None = None, prior_weight: float = 0.04, iterations: int = 40,
             tolerance: float = 1e-3, return_cost: bool = False):
    """Damped least squares (Levenberg-Marquardt) over the DoFs ``dof_names``.

    Minimises the sum of squared task residuals plus prior_weight^2 * (q - q_prior)^2
    (radians) for the DoFs named in ``prior`` (name -> degrees), inside the joint limits;
    the Jacobian is a forward difference evaluated as one batch.  Stops after
    ``iterations`` or when a step improves the cost by less than ``tolerance`` (relative,
    or the cost is below 1e-8).  Returns the new (D,)
    parameter vector (and the final cost with ``return_cost``).
    """
    skel = model.skeleton
    dof_names = list(dof_names)
    idx = np.array([skel.dof_index(n) for n in dof_names], dtype=np.intp)
    p = clip_pose(skel, np.asarray(params, dtype=np.float64))
    prior = {n: v for n, v in (prior or {}).items() if n in dof_names}
    p_idx = np.array([skel.dof_index(n) for n in prior], dtype=np.intp)
    q_prior = np.deg2rad(np.array(list(prior.values()), dtype=np.float64))
    lo, hi = skel.lower[idx], skel.upper[idx]
    eps = 1e-4
    lam = 1e-3

    base_rot = pose_to_local_rotations(skel, p[None])[0][0]
    joints = sorted({int(skel.dof_joint[i]) for i in idx})
    if 0 in joints:  # the root's rotation also carries its translation: rebuild everything
        base_rot, joints = None, ()

    def cost_terms(batch):
        r = _task_residuals(model, kinematics(model, subject, batch, base_rot, joints), tasks)
        reg = prior_weight * (batch[:, p_idx] - q_prior)
        return np.concatenate([r, reg], axis=1)

    r0 = cost_terms(p[None])[0]
    c0 = r0 @ r0
    for _ in range(iterations):
        batch = np.repeat(p[None], len(idx), axis=0)
        batch[np.arange(len(idx)), idx] += eps
        jac = (cost_terms(batch) - r0[None]).T / eps  # (R, n)
        jtj = jac.T @ jac
        g = jac.T @ r0
        while True:
            step = -np.linalg.solve(jtj + lam * (np.diag(np.diag(jtj)) + 1e-6 * np.eye(len(idx))), g)
            cand = p.copy()
            cand[idx] = np.clip(p[idx] + step, lo, hi)
            cand = clip_pose(skel, cand)
            r1 = cost_terms(cand[None])[0]
            c1 = r1 @ r1
            if c1 < c0:
                lam = max(lam * 0.3, 1e-7)
                break
            lam *= 10.0
            if lam > 1e6:
                return (p, c0) if return_cost else p
        improvement = c0 - c1
        p, r0, c0 = cand, r1, c1
        if improvement < tolerance * max(c0, 1e-12) or c0 < 1e-8:
            break
    return (p, c0) if return_cost else p


# ---------------------------------------------------------------------------------------
# Pose specifications
# ---------------------------------------------------------------------------------------

ARM_DOFS = ("clavicle_elev", "clavicle_prot", "shoulder_flex", "shoulder_abd", "shoulder_twist",
            "elbow_flex", "elbow_twist", "wrist_flex", "wrist_dev")
# A natural arm: IK is pulled (weakly) towards no clavicle motion and no limb twist.
ARM_PRIOR = {"clavicle_elev": 0.0, "clavicle_prot": 0.0, "shoulder_twist": 0.0,
             "elbow_twist": 0.0, "wrist_flex": 0.0, "wrist_dev": 0.0}
FINGER_NAMES = ("index", "middle", "ring", "pinky")

# Finger presets in degrees: (MCP flex, PIP flex, DIP flex) for index..pinky, spread
# (towards the thumb) and thumb (CMC flex, CMC abd, MCP, IP).
HAND_PRESETS = {
    "flat": dict(fingers=[(3, 3, 2)] * 4, spread=(0, 0, 0, 0), thumb=(0, 5, 0, 0)),
    "spread": dict(fingers=[(0, 2, 2)] * 4, spread=(12, 2, -8, -18), thumb=(-15, 15, 0, 5)),
    "relaxed": dict(fingers=[(18, 28, 15), (22, 32, 18), (26, 36, 20), (30, 40, 22)],
                    spread=(3, 0, -3, -6), thumb=(5, 15, 10, 15)),
    "cupped": dict(fingers=[(22, 28, 12), (24, 30, 14), (26, 30, 14), (28, 32, 15)],
                   spread=(0, 0, 0, 0), thumb=(10, 25, 10, 10)),
    "fist": dict(fingers=[(85, 100, 60), (88, 100, 60), (90, 100, 60), (92, 100, 60)],
                 spread=(0, 0, 0, -3), thumb=(40, 35, 30, 40)),
    "point": dict(fingers=[(0, 3, 2), (88, 100, 60), (90, 100, 60), (92, 100, 60)],
                  spread=(0, 0, 0, -3), thumb=(40, 35, 30, 40)),
    "ok": dict(fingers=[(35, 45, 30), (8, 8, 5), (12, 10, 5), (16, 12, 6)],
               spread=(0, 2, -5, -12), thumb=(20, 35, 15, 20)),
}


@dataclass
class PoseSpec:
    """A pose to solve: base parameters (torso, legs, fingers, starting arms) and IK stages
    ``(dof_names, tasks, prior)`` solved in order.  ``kind`` is a gesture class or a
    negative kind, ``side`` the main hand ("" when none)."""

    kind: str
    side: str
    base: np.ndarray
    stages: list = field(default_factory=list)

    @property
    def class_id(self) -> int:
        return class_id(self.kind) if self.kind in GESTURE_CLASSES else 0


def _set(model, params, values: dict) -> None:
    """Set DoFs by name (degrees) in a (D,) vector, in place."""
    for name, deg in values.items():
        params[model.skeleton.dof_index(name)] = np.deg2rad(deg)


def set_hand(model, params, side: str, preset: str, rng: np.random.Generator | None = None,
             jitter_deg: float = 5.0) -> None:
    """Finger DoFs of one hand from a preset (:data:`HAND_PRESETS`), with random jitter."""
    spec = HAND_PRESETS[preset]
    noise = (lambda: rng.normal(0.0, jitter_deg)) if rng is not None else (lambda: 0.0)
    vals = {}
    for f, (a, b, c), spread in zip(FINGER_NAMES, spec["fingers"], spec["spread"]):
        vals[f"{side}_{f}1_flex"] = a + noise()
        vals[f"{side}_{f}2_flex"] = b + noise()
        vals[f"{side}_{f}3_flex"] = c + 0.5 * noise()
        vals[f"{side}_{f}1_spread"] = spread + 0.5 * noise()
    t = spec["thumb"]
    for name, val in zip(("thumb1_flex", "thumb1_abd", "thumb2_flex", "thumb3_flex"), t):
        vals[f"{side}_{name}"] = val + 0.6 * noise()
    _set(model, params, vals)


def arm_dofs(side: str) -> tuple:
    return tuple(f"{side}_{d}" for d in ARM_DOFS)


def arm_prior(side: str, **overrides) -> dict:
    out = {f"{side}_{k}": v for k, v in ARM_PRIOR.items()}
    out.update({f"{side}_{k}": v for k, v in overrides.items()})
    return out


def base_pose(model, subject: Subject, rng: np.random.Generator, camera_body=None) -> np.ndarray:
    """Standing pose with random torso lean and twist, stance, arms hanging and relaxed
    hands; the head turns partly towards ``camera_body`` (camera position, body frame)."""
    p = model.rest_pose()
    p[model.skeleton.translation_dofs] = subject.rest_joints[0]
    u = rng.uniform
    vals = {"spine_flex": u(-4, 6), "spine_bend": u(-4, 4), "spine_twist": u(-8, 8),
            "chest_flex": u(-3, 4), "chest_bend": u(-2, 2), "chest_twist": u(-4, 4),
            "neck_flex": u(-5, 10), "neck_bend": u(-5, 5), "head_flex": u(-5, 8),
            "head_bend": u(-4, 4)}
    if camera_body is not None:
        c = np.asarray(camera_body, dtype=np.float64)
        look = np.rad2deg(np.arctan2(c[0], c[2]))  # + = camera on the person's left
        vals["neck_twist"] = np.clip(0.5 * look + u(-8, 8), -60, 60)
        vals["head_twist"] = np.clip(0.2 * look, -15, 15)
    else:
        vals["neck_twist"] = u(-10, 10)
    for s in SIDES:
        vals.update({f"{s}_hip_flex": u(-4, 6), f"{s}_hip_abd": u(0, 7), f"{s}_hip_twist": u(-8, 8),
                     f"{s}_knee_flex": u(-5, 8), f"{s}_ankle_flex": u(-3, 3),
                     f"{s}_shoulder_flex": u(-10, 15), f"{s}_shoulder_abd": u(-42, -28),
                     f"{s}_shoulder_twist": u(-10, 20), f"{s}_elbow_flex": u(-35, -5),
                     f"{s}_elbow_twist": u(-10, 30), f"{s}_wrist_flex": u(-5, 15),
                     f"{s}_wrist_dev": u(-5, 5)})
    _set(model, p, vals)
    for s in SIDES:
        set_hand(model, p, s, "relaxed", rng)
    return p


def ground(model, subject: Subject, params: np.ndarray) -> np.ndarray:
    """Raise or lower the root so the lowest ankle/toe point stays at its rest height."""
    p = np.array(params, dtype=np.float64, copy=True)
    feet = [model.joint_index(n) for n in ("l_ankle", "r_ankle")]
    toes = [model.end_site_names.index(n) for n in ("l_toe", "r_toe")]
    rest_low = min(subject.rest_joints[feet, 1].min(), subject.rest_ends[toes, 1].min())
    kin = kinematics(model, subject, p)
    low = min(kin.joints[0, feet, 1].min(), kin.ends[0, toes, 1].min())
    p[model.skeleton.translation_dofs[1]] += rest_low - low
    return p


def place(model, params: np.ndarray, x: float, z: float, yaw: float) -> np.ndarray:
    """Put a body-frame pose at floor position (x, z) turned by ``yaw`` (radians, + turns
    the person to their left).  The root height is kept (see :func:`ground`)."""
    p = np.array(params, dtype=np.float64, copy=True)
    skel = model.skeleton
    p[skel.translation_dofs[0]] = x
    p[skel.translation_dofs[2]] = z
    p[skel.dof_index("root_yaw")] = yaw
    return clip_pose(skel, p)


def body_to_world(x: float, z: float, yaw: float, points) -> np.ndarray:
    """Body-frame points (origin at the pelvis' floor position) to the room after :func:`place`."""
    c, s = np.cos(yaw), np.sin(yaw)
    r = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return np.asarray(points, dtype=np.float64) @ r.T + np.array([x, 0.0, z])


def world_to_body(x: float, z: float, yaw: float, points) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    r = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return (np.asarray(points, dtype=np.float64) - np.array([x, 0.0, z])) @ r


def _rotate_towards(v, w, angle_deg):
    """Tilt unit vector v by ``angle_deg`` towards the direction w (any vector)."""
    w = np.asarray(w, dtype=np.float64) - (np.dot(w, v)) * v
    n = np.linalg.norm(w)
    if n < 1e-9:
        return v
    a = np.deg2rad(angle_deg)
    return np.cos(a) * v + np.sin(a) * w / n


def _random_tilt(v, rng, max_deg):
    return _unit(_rotate_towards(_unit(v), rng.normal(size=3), rng.uniform(0, max_deg)))


def _ortho(d, n):
    """d made orthogonal to n (unit)."""
    d = np.asarray(d, dtype=np.float64) - np.dot(d, n) * n
    return _unit(d)


def _pick_side(rng, side):
    return side if side in SIDES else ("r" if rng.random() < 0.6 else "l")


def _elbow_hint(pt, side: str, down: float, forward: float, out: float, weight: float = 0.3) -> Task:
    """A weak task placing the elbow (offsets in upper-arm lengths from the shoulder):
    it steers the IK to the natural arm among the many that reach the hand target."""
    shoulder = pt(f"{side}_shoulder")
    length = np.linalg.norm(pt(f"{side}_elbow") - shoulder)
    direction = _unit(-UP * down + FORWARD * forward + lateral(side) * out)
    return Task("point", f"{side}_elbow", shoulder + direction * length, weight=weight)


def _camera_dir(camera_body, point):
    if camera_body is None:
        return FORWARD
    return _unit(np.asarray(camera_body, dtype=np.float64) - point)


def gesture_spec(model, subject: Subject, name: str, rng: np.random.Generator, *,
                 camera_body=None, side: str | None = None) -> PoseSpec:
    """A random instance of gesture ``name`` (see the module table) for ``subject``.

    camera_body: camera position in the body frame (see :func:`world_to_body`), so the
    palm of pause/ok faces the camera and the head turns to it; side: "l"/"r" or random.
    """
    if name not in GESTURE_CLASSES:
        raise ValueError(f"unknown gesture {name!r}; choose one of {GESTURE_CLASSES}")
    p = base_pose(model, subject, rng, camera_body)
    kin = kinematics(model, subject, p)
    pt = lambda n: kin.point(model, n)[0]  # noqa: E731
    u = rng.uniform
    s = _pick_side(rng, side)
    o = other(s)
    lat, med = lateral(s), -lateral(s)
    stages = []
    if name == "pause":
        set_hand(model, p, s, "spread", rng, 3.0)
        target = pt(f"{s}_shoulder") + lat * u(0.02, 0.22) + UP * u(0.05, 0.30) + FORWARD * u(0.18, 0.38)
        volar = _random_tilt(_camera_dir(camera_body, target), rng, 12)
        d = _ortho(_random_tilt(UP + lat * u(-0.1, 0.35), rng, 8), volar)
        stages.append((arm_dofs(s), [Task("point", f"{s}_palm", target),
                                     Task("axis", f"{s}_volar", volar, weight=0.25),
                                     Task("axis", f"{s}_d", d, weight=0.15),
                                     _elbow_hint(pt, s, u(0.1, 0.6), u(0.2, 0.6), u(0.6, 1.0), 0.15)],
                       arm_prior(s, wrist_flex=-40)))
    elif name == "ok":
        set_hand(model, p, s, "ok", rng, 3.0)
        target = pt(f"{s}_shoulder") + lat * u(-0.05, 0.18) + UP * u(-0.12, 0.15) + FORWARD * u(0.25, 0.40)
        # The palm turned 30-60 deg medially from the camera: the ring faces the camera.
        volar = _unit(_rotate_towards(_camera_dir(camera_body, target), med, u(30, 60)))
        d = _ortho(_random_tilt(UP + med * u(0.0, 0.4), rng, 10), volar)
        stages.append((arm_dofs(s), [Task("point", f"{s}_palm", target),
                                     Task("axis", f"{s}_volar", volar, weight=0.25),
                                     Task("axis", f"{s}_d", d, weight=0.15),
                                     _elbow_hint(pt, s, u(0.7, 1.0), u(0.2, 0.5), u(0.2, 0.5), 0.15)],
                       arm_prior(s, wrist_flex=-30)))
        fingers = (f"{s}_thumb1_flex", f"{s}_thumb1_abd", f"{s}_thumb2_flex", f"{s}_thumb3_flex",
                   f"{s}_index1_flex", f"{s}_index2_flex", f"{s}_index3_flex")
        stages.append((fingers, [Task("touch", f"{s}_thumb_tip", b=f"{s}_index_tip", weight=3.0)],
                       {f"{s}_index1_flex": u(25, 45), f"{s}_index2_flex": u(35, 55),
                        f"{s}_index3_flex": 25, f"{s}_thumb2_flex": 15, f"{s}_thumb3_flex": 15}))
    elif name == "silence":
        set_hand(model, p, s, "point", rng, 3.0)
        head_fwd = _unit(pt("mouth") - 0.5 * (pt("l_ear") + pt("r_ear")))
        target = pt("mouth") + UP * u(0.015, 0.03) + head_fwd * u(0.008, 0.016) + lat * u(-0.01, 0.01)
        finger = _random_tilt(UP, rng, 10)
        volar = _unit(-head_fwd + med * u(0.3, 1.0))
        stages.append((arm_dofs(s), [Task("point", f"{s}_index_tip", target, weight=2.0),
                                     Task("dir", f"{s}_index1", finger, b=f"{s}_index_tip", weight=0.3),
                                     Task("axis", f"{s}_volar", volar, weight=0.08),
                                     _elbow_hint(pt, s, u(0.8, 1.0), u(0.3, 0.6), u(0.0, 0.3), 0.15)],
                       arm_prior(s)))
    elif name == "volume_up":
        set_hand(model, p, s, "cupped", rng, 3.0)
        ear = pt(f"{s}_ear")
        head_fwd = _unit(pt("mouth") - 0.5 * (pt("l_ear") + pt("r_ear")))
        target = ear - head_fwd * u(0.015, 0.045) + lat * u(0.025, 0.05) + UP * u(-0.02, 0.02)
        volar = _random_tilt(_unit(head_fwd + med * u(0.1, 0.5)), rng, 10)
        d = _ortho(_random_tilt(UP - head_fwd * 0.2, rng, 10), volar)
        stages.append((arm_dofs(s), [Task("point", f"{s}_palm", target),
                                     Task("axis", f"{s}_volar", volar, weight=0.2),
                                     Task("axis", f"{s}_d", d, weight=0.15),
                                     _elbow_hint(pt, s, u(-0.2, 0.3), u(0.2, 0.6), u(0.8, 1.0), 0.15)],
                       arm_prior(s)))
    elif name == "cross":
        preset = "fist" if rng.random() < 0.5 else "relaxed"
        for side_ in SIDES:
            set_hand(model, p, side_, preset, rng)
        centre = pt("sternum") + FORWARD * u(0.13, 0.2) + UP * u(-0.12, 0.04)
        front = s  # the forearm in front
        tasks = []
        for side_ in SIDES:
            a = np.deg2rad(u(35, 58))
            along = _unit(-lateral(side_) * np.cos(a) + UP * np.sin(a))
            off = FORWARD * (0.042 if side_ == front else -0.042)
            length = np.linalg.norm(pt(f"{side_}_wrist") - pt(f"{side_}_elbow"))
            k = u(0.45, 0.62)
            tasks += [Task("point", f"{side_}_elbow", centre + off - along * k * length),
                      Task("point", f"{side_}_wrist", centre + off + along * (1 - k) * length),
                      Task("axis", f"{side_}_volar", -FORWARD, weight=0.05)]
        stages.append((arm_dofs("l") + arm_dofs("r"), tasks, {**arm_prior("l"), **arm_prior("r")}))
    elif name == "tee":
        for side_ in SIDES:
            set_hand(model, p, side_, "flat", rng, 2.0)
        tip = pt("sternum") + FORWARD * u(0.25, 0.35) + UP * u(0.08, 0.2) + lat * u(-0.06, 0.04)
        stem_d = _random_tilt(UP, rng, 10)
        stem_volar = _ortho(_rotate_towards(med, -FORWARD, u(-10, 25)), stem_d)
        top_d = _ortho(_random_tilt(lat + FORWARD * u(-0.2, 0.3), rng, 8), UP)
        stages.append((arm_dofs(s) + arm_dofs(o),
                       [Task("point", f"{s}_hand_tip", tip),
                        Task("axis", f"{s}_d", stem_d, weight=0.3),
                        Task("axis", f"{s}_volar", stem_volar, weight=0.15),
                        Task("touch", f"{s}_hand_tip", b=f"{o}_palm", target=UP * 0.022, weight=2.0),
                        Task("axis", f"{o}_d", top_d, weight=0.2),
                        Task("axis", f"{o}_volar", -UP, weight=0.3)],
                       {**arm_prior(s), **arm_prior(o)}))
    return PoseSpec(name, s, p, stages)


def solve_spec(model, subject: Subject, spec: PoseSpec, start: np.ndarray | None = None,
               iterations: int = 40, restarts: int | None = None) -> np.ndarray:
    """Solve a spec's IK stages (from ``start`` if given, else its base) and put the feet
    on the floor; returns the (D,) body-frame parameters.  A stage whose main position
    targets stay more than 2 cm off is re-solved from up to ``restarts`` (default
    :data:`RESTARTS`) other starting arms."""
    restarts = RESTARTS if restarts is None else restarts
    p = np.array(spec.base if start is None else start, dtype=np.float64, copy=True)
    if start is not None:  # keep the spec's torso, legs and non-IK fingers
        solved = {d for dofs, _, _ in spec.stages for d in dofs}
        keep = np.array([n not in solved for n in model.skeleton.dof_names])
        p[keep] = spec.base[keep]
    for dofs, tasks, prior in spec.stages:
        best, cost = solve_ik(model, subject, p, dofs, tasks, prior=prior, iterations=iterations,
                              return_cost=True)
        # A missed position target is a local minimum: restart from other arm configurations
        # (fixed seeds, so the result stays deterministic) and keep the best solution.
        for restart in range(restarts):
            if _worst_point_error(model, subject, best, tasks) < RESTART_ERROR_M:
                break
            start = p.copy()
            idx = [model.skeleton.dof_index(d) for d in dofs]
            lo, hi = model.skeleton.lower[idx], model.skeleton.upper[idx]
            start[idx] = lo + (hi - lo) * np.random.default_rng(restart).uniform(0.25, 0.75, len(idx))
            cand, c = solve_ik(model, subject, start, dofs, tasks, prior=prior, iterations=max(iterations, 40),
                               return_cost=True)
            if c < cost:
                best, cost = cand, c
        p = best
    return ground(model, subject, p)


RESTARTS = 4
RESTART_ERROR_M = 0.02


def _worst_point_error(model, subject: Subject, params: np.ndarray, tasks) -> float:
    """Largest error (m) of the point and touch tasks that carry most weight (>= 1)."""
    kin = kinematics(model, subject, params)
    errs = [np.linalg.norm(_task_residuals(model, kin, [t])) / t.weight
            for t in tasks if t.kind in ("point", "touch") and t.weight >= 1.0]
    return max(errs, default=0.0)


def jitter_spec(spec: PoseSpec, rng: np.random.Generator, position_sigma: float = 0.008,
                angle_sigma_deg: float = 1.5, model=None) -> PoseSpec:
    """The same pose with small random changes (for the motion of a held gesture): point
    targets move by N(0, position_sigma) metres, torso and head angles by
    N(0, angle_sigma_deg); relative tasks (touch, dir, axis) are unchanged."""
    base = spec.base.copy()
    if model is not None:
        names = model.skeleton.dof_names
        torso = [i for i, n in enumerate(names)
                 if n.split("_")[0] in ("spine", "chest", "neck", "head")]
        base[torso] += np.deg2rad(rng.normal(0.0, angle_sigma_deg, len(torso)))
    stages = []
    for dofs, tasks, prior in spec.stages:
        new = []
        for t in tasks:
            if t.kind == "point":
                t = Task(t.kind, t.a, t.target + rng.normal(0.0, position_sigma, 3), t.b, t.weight)
            new.append(t)
        stages.append((dofs, new, prior))
    return PoseSpec(spec.kind, spec.side, base, stages)


def _closest_on_segments(point, a, b):
    """Closest points (B, 3) on segments a-b (B, 3) to ``point`` (B, 3)."""
    ab = b - a
    t = np.clip(np.einsum("bi,bi->b", point - a, ab) / np.maximum(np.einsum("bi,bi->b", ab, ab), 1e-12), 0, 1)
    return a + t[:, None] * ab


def forearm_crossing(kin: Kinematics, model) -> np.ndarray:
    """Midpoint (B, 3) of the closest approach of the two forearm axes (elbow -> wrist)."""
    p1, p2 = kin.point(model, "l_elbow"), kin.point(model, "l_wrist")
    q1, q2 = kin.point(model, "r_elbow"), kin.point(model, "r_wrist")
    d1, d2, r = p2 - p1, q2 - q1, p1 - q1
    a = np.einsum("bi,bi->b", d1, d1)
    e = np.einsum("bi,bi->b", d2, d2)
    b = np.einsum("bi,bi->b", d1, d2)
    c = np.einsum("bi,bi->b", d1, r)
    f = np.einsum("bi,bi->b", d2, r)
    den = np.maximum(a * e - b * b, 1e-12)
    s = np.clip((b * f - c * e) / den, 0, 1)
    t = np.clip((b * s + f) / e, 0, 1)
    s = np.clip((b * t - c) / a, 0, 1)
    return 0.5 * (p1 + s[:, None] * d1 + q1 + t[:, None] * d2)


def reference_point(model, kin: Kinematics, name: str, side: str) -> np.ndarray:
    """The annotated 3D point (B, 3) of gesture ``name`` (module table) in ``kin``'s frame."""
    if name in ("pause", "ok", "volume_up"):
        return kin.point(model, f"{side}_palm")
    if name == "tee":
        return kin.point(model, f"{side}_hand_tip")
    if name == "cross":
        return forearm_crossing(kin, model)
    if name == "silence":
        mouth = kin.point(model, "mouth")
        cands = [_closest_on_segments(mouth, kin.point(model, a), kin.point(model, b))
                 for a, b in ((f"{side}_index2", f"{side}_index3"), (f"{side}_index3", f"{side}_index_tip"))]
        dist = np.stack([np.linalg.norm(c - mouth, axis=-1) for c in cands])
        return np.where((dist[0] <= dist[1])[:, None], cands[0], cands[1])
    raise ValueError(f"unknown gesture {name!r}")


def hand_joints(model, side: str) -> list:
    """Joint indices of one hand (wrist and finger joints): its skin is "the hand"."""
    names = [f"{side}_wrist"] + [f"{side}_{f}{k}" for f in ("thumb",) + FINGER_NAMES for k in (1, 2, 3)]
    return [model.joint_index(n) for n in names]


def reference_parts(model, name: str, side: str) -> list:
    """Joint indices whose skin (``model.vertex_part``) may be seen at the reference pixel
    for the annotation to count as visible (e.g. the gesturing hand for pause)."""
    if name in ("pause", "ok", "volume_up"):
        return hand_joints(model, side)
    if name == "tee":
        return hand_joints(model, "l") + hand_joints(model, "r")
    if name == "silence":
        return hand_joints(model, side) + [model.joint_index("head")]
    if name == "cross":
        return [model.joint_index(n) for n in ("l_elbow", "r_elbow", "l_wrist", "r_wrist")]
    raise ValueError(f"unknown gesture {name!r}")


#: Relative frequency of each negative kind in a generated set.
NEGATIVE_WEIGHTS = {"idle": 2.0, "walk": 1.5, "random_arms": 2.0, "fold_arms": 1.0, "chin": 1.0,
                    "phone": 1.0, "point": 1.0, "scratch_head": 0.7, "hips": 0.8, "clasp": 0.8,
                    "wave_side": 0.8}


def walk_params(model, params: np.ndarray, phase: float, stride_deg: float = 22.0) -> np.ndarray:
    """Overlay a walking cycle at ``phase`` (radians) on a standing pose: legs swing with
    knee flexion in the swing phase, arms swing in counter-phase, slight torso counter-twist."""
    p = np.array(params, dtype=np.float64, copy=True)
    s = np.sin(phase)
    vals = {"l_hip_flex": stride_deg * s, "r_hip_flex": -stride_deg * s,
            "l_knee_flex": 5 + 35 * max(0.0, np.sin(phase + 1.2)),
            "r_knee_flex": 5 + 35 * max(0.0, np.sin(phase + np.pi + 1.2)),
            "l_ankle_flex": 8 * np.cos(phase), "r_ankle_flex": -8 * np.cos(phase),
            "l_shoulder_flex": -0.8 * stride_deg * s, "r_shoulder_flex": 0.8 * stride_deg * s,
            "spine_twist": 4 * s}
    for name, deg in vals.items():
        p[model.skeleton.dof_index(name)] += np.deg2rad(deg)
    return clip_pose(model.skeleton, p)


def negative_spec(model, subject: Subject, kind: str, rng: np.random.Generator, *,
                  camera_body=None, side: str | None = None) -> PoseSpec:
    """A random non-gesture pose of ``kind`` (:data:`NEGATIVE_KINDS`): idle standing, the
    standing part of walking (the cycle is :func:`walk_params`), random arms, or a near
    miss of a gesture (arms folded vs cross, fist at the chin vs silence, phone at the ear
    vs volume up, hand sideways vs pause, ...)."""
    if kind not in NEGATIVE_KINDS:
        raise ValueError(f"unknown negative kind {kind!r}; choose one of {NEGATIVE_KINDS}")
    p = base_pose(model, subject, rng, camera_body)
    kin = kinematics(model, subject, p)
    pt = lambda n: kin.point(model, n)[0]  # noqa: E731
    u = rng.uniform
    s = _pick_side(rng, side)
    o = other(s)
    lat, med = lateral(s), -lateral(s)
    stages = []
    if kind == "idle":
        if rng.random() < 0.3:  # hands behind the back
            for side_ in SIDES:
                stages.append((arm_dofs(side_), [Task("point", f"{side_}_palm", pt("pelvis") - FORWARD * 0.17
                                                       + UP * u(-0.05, 0.05) + lateral(side_) * 0.05),
                                                  _elbow_hint(pt, side_, 0.9, -0.4, 0.3)], arm_prior(side_)))
    elif kind == "walk":
        _set(model, p, {"neck_twist": u(-10, 10), "head_twist": 0.0})
    elif kind == "random_arms":
        for side_ in SIDES if rng.random() < 0.5 else (s,):
            _set(model, p, {f"{side_}_shoulder_flex": u(-20, 110), f"{side_}_shoulder_abd": u(-45, 70),
                            f"{side_}_shoulder_twist": u(-40, 50), f"{side_}_elbow_flex": u(-40, 100),
                            f"{side_}_elbow_twist": u(-40, 60), f"{side_}_wrist_flex": u(-30, 50),
                            f"{side_}_clavicle_elev": u(-5, 15)})
            set_hand(model, p, side_, str(rng.choice(["relaxed", "fist", "flat", "cupped"])), rng, 8.0)
    elif kind == "fold_arms":
        low, high = (s, o) if rng.random() < 0.5 else (o, s)
        centre = pt("sternum") + FORWARD * u(0.1, 0.14) + UP * u(-0.2, -0.1)
        for side_, dy in ((low, -0.035), (high, 0.035)):
            set_hand(model, p, side_, "relaxed", rng)
            stages.append((arm_dofs(side_), [
                Task("point", f"{side_}_wrist", centre + UP * dy - lateral(side_) * u(0.12, 0.18)),
                Task("point", f"{side_}_elbow", centre + UP * dy + lateral(side_) * u(0.14, 0.2), weight=0.5),
                Task("axis", f"{side_}_volar", -FORWARD, weight=0.05)], arm_prior(side_)))
    elif kind == "chin":
        set_hand(model, p, s, "fist", rng)
        head_fwd = _unit(pt("mouth") - 0.5 * (pt("l_ear") + pt("r_ear")))
        target = pt("mouth") - UP * u(0.06, 0.09) + head_fwd * u(0.0, 0.03)
        stages.append((arm_dofs(s), [Task("point", f"{s}_palm", target),
                                     Task("axis", f"{s}_d", _unit(UP + head_fwd), weight=0.1),
                                     _elbow_hint(pt, s, 0.9, 0.5, 0.0, 0.2)], arm_prior(s)))
    elif kind == "phone":
        set_hand(model, p, s, "fist", rng)
        target = pt(f"{s}_ear") + lat * u(0.04, 0.06) + UP * u(-0.06, -0.02) + FORWARD * u(0.0, 0.04)
        stages.append((arm_dofs(s), [Task("point", f"{s}_palm", target),
                                     Task("axis", f"{s}_volar", med, weight=0.15),
                                     _elbow_hint(pt, s, 0.7, 0.6, 0.3, 0.2)], arm_prior(s)))
    elif kind == "point":
        set_hand(model, p, s, "point", rng, 3.0)
        direction = _unit(FORWARD * u(0.2, 1.0) + lat * u(0.2, 1.0) + UP * u(-0.2, 0.4))
        target = pt(f"{s}_shoulder") + direction * u(0.5, 0.6)
        stages.append((arm_dofs(s), [Task("point", f"{s}_index_tip", target, weight=2.0),
                                     Task("axis", f"{s}_d", direction, weight=0.2)], arm_prior(s)))
    elif kind == "scratch_head":
        set_hand(model, p, s, "relaxed", rng)
        top = kin.point(model, "head_top")[0]
        target = top + lat * u(0.02, 0.07) - UP * u(0.0, 0.03) + FORWARD * u(-0.04, 0.03)
        stages.append((arm_dofs(s), [Task("point", f"{s}_palm", target),
                                     Task("axis", f"{s}_volar", -UP, weight=0.1),
                                     _elbow_hint(pt, s, -0.3, 0.4, 1.0, 0.2)], arm_prior(s)))
    elif kind == "hips":
        for side_ in SIDES if rng.random() < 0.7 else (s,):
            set_hand(model, p, side_, "flat", rng)
            hip = pt(f"{side_}_hip")
            stages.append((arm_dofs(side_), [
                Task("point", f"{side_}_palm", hip + lateral(side_) * u(0.05, 0.09) + UP * u(0.07, 0.14)),
                Task("axis", f"{side_}_volar", -lateral(side_), weight=0.1),
                Task("axis", f"{side_}_d", -UP, weight=0.05),
                _elbow_hint(pt, side_, 0.6, -0.3, 1.0, 0.3)], arm_prior(side_)))
    elif kind == "clasp":
        for side_ in SIDES:
            set_hand(model, p, side_, "cupped", rng)
        centre = pt("spine") + FORWARD * u(0.17, 0.25) + UP * u(0.02, 0.18)
        stages.append((arm_dofs(s) + arm_dofs(o), [
            Task("point", f"{s}_palm", centre + lat * 0.025),
            Task("touch", f"{s}_palm", b=f"{o}_palm", target=med * 0.05, weight=1.0),
            Task("axis", f"{s}_volar", med, weight=0.1), Task("axis", f"{o}_volar", lat, weight=0.1),
            _elbow_hint(pt, s, 1.0, 0.2, 0.2), _elbow_hint(pt, o, 1.0, 0.2, 0.2)],
            {**arm_prior(s), **arm_prior(o)}))
    elif kind == "wave_side":
        set_hand(model, p, s, str(rng.choice(["flat", "spread", "relaxed"])), rng, 4.0)
        target = pt(f"{s}_shoulder") + lat * u(0.15, 0.35) + UP * u(0.05, 0.3) + FORWARD * u(0.0, 0.2)
        # the palm faces the midline or the floor, never the camera
        volar = _unit(med + (-UP if rng.random() < 0.5 else -FORWARD) * u(0.0, 0.6))
        stages.append((arm_dofs(s), [Task("point", f"{s}_palm", target),
                                     Task("axis", f"{s}_volar", volar, weight=0.25),
                                     _elbow_hint(pt, s, u(0.0, 0.5), u(0.0, 0.3), 1.0, 0.2)],
                       arm_prior(s)))
    return PoseSpec(kind, s, p, stages)


def pose_spec(model, subject: Subject, kind: str, rng: np.random.Generator, **kwargs) -> PoseSpec:
    """:func:`gesture_spec` for a gesture class, :func:`negative_spec` otherwise."""
    if kind in GESTURE_CLASSES:
        return gesture_spec(model, subject, kind, rng, **kwargs)
    return negative_spec(model, subject, kind, rng, **kwargs)
