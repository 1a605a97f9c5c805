"""Building blocks of the gesture and negative poses: the standing base pose, hand presets,
arm DoFs and priors, direction helpers, placement in the room and the walking cycle.

A pose builder (:mod:`hmocap_sim.gesture_specs`, :mod:`hmocap_sim.gesture_negatives`)
starts from :func:`start_pose`: a random standing pose with the head turned partly towards
the camera, and the main hand drawn unless given.  Poses are solved with the body at the
origin facing +Z (root yaw 0) and put in the room with :func:`place`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hmocap_ros.body.skeleton import clip_pose
from hmocap_sim.gesture_body import (
    FINGER_NAMES,
    FORWARD,
    SIDES,
    UP,
    Kinematics,
    Subject,
    kinematics,
    lateral,
    other,
    unit,
)
from hmocap_sim.gesture_ik import Task

ARM_DOFS = ("clavicle_elev", "clavicle_prot", "shoulder_flex", "shoulder_abd", "shoulder_twist",
            "elbow_flex", "elbow_twist", "wrist_flex", "wrist_dev")
# A natural arm: IK is pulled (weakly) towards no clavicle motion and no limb twist.
ARM_PRIOR = {"clavicle_elev": 0.0, "clavicle_prot": 0.0, "shoulder_twist": 0.0,
             "elbow_twist": 0.0, "wrist_flex": 0.0, "wrist_dev": 0.0}

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
    "thumb": dict(fingers=[(85, 100, 60), (88, 100, 60), (90, 100, 60), (92, 100, 60)],
                  spread=(0, 0, 0, -3), thumb=(-10, 40, 0, 0)),
}


def set_dofs(model, params, values: dict) -> None:
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
    set_dofs(model, params, vals)


def arm_dofs(side: str) -> tuple:
    """The IK DoFs of one arm (clavicle to wrist)."""
    return tuple(f"{side}_{d}" for d in ARM_DOFS)


def arm_prior(side: str, **overrides) -> dict:
    """The natural-arm prior (:data:`ARM_PRIOR`, degrees) of one arm, with overrides."""
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
    set_dofs(model, p, vals)
    for s in SIDES:
        set_hand(model, p, s, "relaxed", rng)
    return p

@dataclass(frozen=True, eq=False)
class PoseContext:
    """What a pose builder starts from: the base pose ``params`` (the builder edits it in
    place: fingers, torso), its kinematics ``kin``, the random stream, the main hand ``side``
    and the camera position in the body frame (None: straight ahead)."""

    model: object
    params: np.ndarray
    kin: Kinematics
    rng: np.random.Generator
    side: str
    camera_body: np.ndarray | None

    def pt(self, name: str) -> np.ndarray:
        """(3,) position of a joint, end site or landmark in the base pose."""
        return self.kin.point(self.model, name)[0]

    @property
    def other(self) -> str:
        return other(self.side)

    @property
    def lateral(self) -> np.ndarray:
        """Away from the midline on the main hand's side."""
        return lateral(self.side)

    @property
    def medial(self) -> np.ndarray:
        """Towards the midline from the main hand's side."""
        return -lateral(self.side)


def start_pose(model, subject: Subject, rng: np.random.Generator, camera_body=None,
               side: str | None = None) -> PoseContext:
    """The :class:`PoseContext` of a new pose: :func:`base_pose`, then the main hand
    (``side``, or drawn: right 60 %)."""
    p = base_pose(model, subject, rng, camera_body)
    kin = kinematics(model, subject, p)
    return PoseContext(model, p, kin, rng, _pick_side(rng, side), camera_body)


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
    """Room points to the body frame of a pose placed by :func:`place` (inverse of :func:`body_to_world`)."""
    c, s = np.cos(yaw), np.sin(yaw)
    r = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return (np.asarray(points, dtype=np.float64) - np.array([x, 0.0, z])) @ r


def rotate_towards(v, w, angle_deg):
    """Tilt unit vector v by ``angle_deg`` towards the direction w (any vector)."""
    w = np.asarray(w, dtype=np.float64) - (np.dot(w, v)) * v
    n = np.linalg.norm(w)
    if n < 1e-9:
        return v
    a = np.deg2rad(angle_deg)
    return np.cos(a) * v + np.sin(a) * w / n


def random_tilt(v, rng, max_deg):
    """Unit vector ``v`` tilted by a random angle up to ``max_deg`` in a random direction."""
    return unit(rotate_towards(unit(v), rng.normal(size=3), rng.uniform(0, max_deg)))


def perpendicular_unit(d, n):
    """d made orthogonal to n (unit)."""
    d = np.asarray(d, dtype=np.float64) - np.dot(d, n) * n
    return unit(d)


def _pick_side(rng, side):
    """``side`` if given, else the right hand with probability 0.6."""
    return side if side in SIDES else ("r" if rng.random() < 0.6 else "l")


def elbow_hint(pt, side: str, down: float, forward: float, out: float, weight: float = 0.3) -> Task:
    """A weak task placing the elbow (offsets in upper-arm lengths from the shoulder):
    it steers the IK to the natural arm among the many that reach the hand target."""
    shoulder = pt(f"{side}_shoulder")
    length = np.linalg.norm(pt(f"{side}_elbow") - shoulder)
    direction = unit(-UP * down + FORWARD * forward + lateral(side) * out)
    return Task("point", f"{side}_elbow", shoulder + direction * length, weight=weight)


def camera_direction(camera_body, point):
    """Unit vector from ``point`` to the camera (body frame); +Z when the camera is unknown."""
    if camera_body is None:
        return FORWARD
    return unit(np.asarray(camera_body, dtype=np.float64) - point)


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
