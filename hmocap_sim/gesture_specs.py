"""The gestures as pose builders, with the point each one is annotated at: :data:`GESTURES`
maps a class name to a :class:`GestureKind` (the six classes of thesis fig. 3.4 / table 3.2,
then the two gestures to teach, :data:`~hmocap_ros.gestures.classes.NEW_GESTURES`).

A builder draws a random instance of its gesture from a :class:`PoseContext` (the base pose,
the main hand, the camera position in the body frame) and returns the IK stages
``(dof_names, tasks, prior)`` of a :class:`~hmocap_sim.gesture_ik.PoseSpec`; the random
draws happen in the order they are written, so a seed gives the same pose.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hmocap_ros.gestures.classes import ALL_GESTURES
from hmocap_sim.gesture_body import (
    FORWARD,
    SIDES,
    UP,
    Kinematics,
    Subject,
    hand_joints,
    lateral,
    unit,
)
from hmocap_sim.gesture_ik import PoseSpec, Task
from hmocap_sim.gesture_pose import (
    PoseContext,
    arm_dofs,
    arm_prior,
    camera_direction,
    elbow_hint,
    perpendicular_unit,
    random_tilt,
    rotate_towards,
    set_hand,
    start_pose,
)


def _tee(c: PoseContext) -> list:
    """Time out: the main hand vertical in front of the chest, the other flat on its
    fingertips, palm down."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s, o, lat, med = c.side, c.other, c.lateral, c.medial
    for side_ in SIDES:
        set_hand(model, p, side_, "flat", rng, 2.0)
    tip = pt("sternum") + FORWARD * u(0.25, 0.35) + UP * u(0.08, 0.2) + lat * u(-0.06, 0.04)
    stem_d = random_tilt(UP, rng, 10)
    stem_volar = perpendicular_unit(rotate_towards(med, -FORWARD, u(-10, 25)), stem_d)
    top_d = perpendicular_unit(random_tilt(lat + FORWARD * u(-0.2, 0.3), rng, 8), UP)
    return [(arm_dofs(s) + arm_dofs(o),
             [Task("point", f"{s}_hand_tip", tip),
              Task("axis", f"{s}_d", stem_d, weight=0.3),
              Task("axis", f"{s}_volar", stem_volar, weight=0.15),
              Task("touch", f"{s}_hand_tip", b=f"{o}_palm", target=UP * 0.022, weight=2.0),
              Task("axis", f"{o}_d", top_d, weight=0.2),
              Task("axis", f"{o}_volar", -UP, weight=0.3)],
             {**arm_prior(s), **arm_prior(o)})]


def _pause(c: PoseContext) -> list:
    """One arm raised, the open palm towards the camera, fingers up."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s, lat = c.side, c.lateral
    set_hand(model, p, s, "spread", rng, 3.0)
    target = pt(f"{s}_shoulder") + lat * u(0.02, 0.22) + UP * u(0.05, 0.30) + FORWARD * u(0.18, 0.38)
    volar = random_tilt(camera_direction(c.camera_body, target), rng, 12)
    d = perpendicular_unit(random_tilt(UP + lat * u(-0.1, 0.35), rng, 8), volar)
    return [(arm_dofs(s), [Task("point", f"{s}_palm", target),
                           Task("axis", f"{s}_volar", volar, weight=0.25),
                           Task("axis", f"{s}_d", d, weight=0.15),
                           elbow_hint(pt, s, u(0.1, 0.6), u(0.2, 0.6), u(0.6, 1.0), 0.15)],
             arm_prior(s, wrist_flex=-40))]


def _silence(c: PoseContext) -> list:
    """The index finger upright on the lips, the other fingers curled."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s, lat, med = c.side, c.lateral, c.medial
    set_hand(model, p, s, "point", rng, 3.0)
    head_fwd = unit(pt("mouth") - 0.5 * (pt("l_ear") + pt("r_ear")))
    target = pt("mouth") + UP * u(0.015, 0.03) + head_fwd * u(0.008, 0.016) + lat * u(-0.01, 0.01)
    finger = random_tilt(UP, rng, 10)
    volar = unit(-head_fwd + med * u(0.3, 1.0))
    return [(arm_dofs(s), [Task("point", f"{s}_index_tip", target, weight=2.0),
                           Task("dir", f"{s}_index1", finger, b=f"{s}_index_tip", weight=0.3),
                           Task("axis", f"{s}_volar", volar, weight=0.08),
                           elbow_hint(pt, s, u(0.8, 1.0), u(0.3, 0.6), u(0.0, 0.3), 0.15)],
             arm_prior(s))]


def _cross(c: PoseContext) -> list:
    """Forearms crossed in an X in front of the chest, the main hand's forearm in front."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    preset = "fist" if rng.random() < 0.5 else "relaxed"
    for side_ in SIDES:
        set_hand(model, p, side_, preset, rng)
    centre = pt("sternum") + FORWARD * u(0.13, 0.2) + UP * u(-0.12, 0.04)
    front = c.side
    tasks = []
    for side_ in SIDES:
        a = np.deg2rad(u(35, 58))
        along = unit(-lateral(side_) * np.cos(a) + UP * np.sin(a))
        off = FORWARD * (0.042 if side_ == front else -0.042)
        length = np.linalg.norm(pt(f"{side_}_wrist") - pt(f"{side_}_elbow"))
        k = u(0.45, 0.62)
        tasks += [Task("point", f"{side_}_elbow", centre + off - along * k * length),
                  Task("point", f"{side_}_wrist", centre + off + along * (1 - k) * length),
                  Task("axis", f"{side_}_volar", -FORWARD, weight=0.05)]
    return [(arm_dofs("l") + arm_dofs("r"), tasks, {**arm_prior("l"), **arm_prior("r")})]


def _ok(c: PoseContext) -> list:
    """Thumb-index ring, the other fingers extended, the hand raised with the palm turned
    30-60 deg medially from the camera so that the ring faces it."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s, lat, med = c.side, c.lateral, c.medial
    set_hand(model, p, s, "ok", rng, 3.0)
    target = pt(f"{s}_shoulder") + lat * u(-0.05, 0.18) + UP * u(-0.12, 0.15) + FORWARD * u(0.25, 0.40)
    volar = unit(rotate_towards(camera_direction(c.camera_body, target), med, u(30, 60)))
    d = perpendicular_unit(random_tilt(UP + med * u(0.0, 0.4), rng, 10), volar)
    arm = (arm_dofs(s), [Task("point", f"{s}_palm", target),
                         Task("axis", f"{s}_volar", volar, weight=0.25),
                         Task("axis", f"{s}_d", d, weight=0.15),
                         elbow_hint(pt, s, u(0.7, 1.0), u(0.2, 0.5), u(0.2, 0.5), 0.15)],
           arm_prior(s, wrist_flex=-30))
    fingers = (f"{s}_thumb1_flex", f"{s}_thumb1_abd", f"{s}_thumb2_flex", f"{s}_thumb3_flex",
               f"{s}_index1_flex", f"{s}_index2_flex", f"{s}_index3_flex")
    ring = (fingers, [Task("touch", f"{s}_thumb_tip", b=f"{s}_index_tip", weight=3.0)],
            {f"{s}_index1_flex": u(25, 45), f"{s}_index2_flex": u(35, 55),
             f"{s}_index3_flex": 25, f"{s}_thumb2_flex": 15, f"{s}_thumb3_flex": 15})
    return [arm, ring]


def _volume_up(c: PoseContext) -> list:
    """The hand cupped behind the ear, palm forwards."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s, lat, med = c.side, c.lateral, c.medial
    set_hand(model, p, s, "cupped", rng, 3.0)
    ear = pt(f"{s}_ear")
    head_fwd = unit(pt("mouth") - 0.5 * (pt("l_ear") + pt("r_ear")))
    target = ear - head_fwd * u(0.015, 0.045) + lat * u(0.025, 0.05) + UP * u(-0.02, 0.02)
    volar = random_tilt(unit(head_fwd + med * u(0.1, 0.5)), rng, 10)
    d = perpendicular_unit(random_tilt(UP - head_fwd * 0.2, rng, 10), volar)
    return [(arm_dofs(s), [Task("point", f"{s}_palm", target),
                           Task("axis", f"{s}_volar", volar, weight=0.2),
                           Task("axis", f"{s}_d", d, weight=0.15),
                           elbow_hint(pt, s, u(-0.2, 0.3), u(0.2, 0.6), u(0.8, 1.0), 0.15)],
             arm_prior(s))]


def _thumbs_up(c: PoseContext) -> list:
    """A fist in front of the body, palm towards the midline, the thumb pointing up."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s, lat, med = c.side, c.lateral, c.medial
    set_hand(model, p, s, "thumb", rng, 3.0)
    target = pt(f"{s}_shoulder") + lat * u(-0.12, 0.08) + UP * u(-0.28, 0.02) + FORWARD * u(0.25, 0.40)
    d = random_tilt(unit(FORWARD + med * u(0.0, 0.5)), rng, 10)
    volar = perpendicular_unit(unit(med - UP * u(0.0, 0.3)), d)
    return [(arm_dofs(s), [Task("point", f"{s}_palm", target),
                           Task("axis", f"{s}_d", d, weight=0.15),
                           Task("axis", f"{s}_volar", volar, weight=0.15),
                           Task("dir", f"{s}_thumb2", random_tilt(UP, rng, 12), b=f"{s}_thumb_tip", weight=0.4),
                           elbow_hint(pt, s, u(0.8, 1.0), u(0.2, 0.5), u(0.0, 0.3), 0.15)],
             arm_prior(s))]


def _raised_fist(c: PoseContext) -> list:
    """A fist raised above the shoulder, forearm upright."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s, lat = c.side, c.lateral
    set_hand(model, p, s, "fist", rng, 3.0)
    target = pt(f"{s}_shoulder") + lat * u(0.0, 0.2) + UP * u(0.3, 0.5) + FORWARD * u(0.05, 0.25)
    volar = random_tilt(unit(camera_direction(c.camera_body, target) - lat * u(0.0, 1.0)), rng, 15)
    d = perpendicular_unit(random_tilt(UP, rng, 10), volar)
    return [(arm_dofs(s), [Task("point", f"{s}_palm", target),
                           Task("axis", f"{s}_volar", volar, weight=0.15),
                           Task("axis", f"{s}_d", d, weight=0.15),
                           elbow_hint(pt, s, u(0.0, 0.4), u(0.2, 0.6), u(0.6, 1.0), 0.15)],
             arm_prior(s))]


# ---------------------------------------------------------------------------------------
# Reference points and the body parts that may be seen at them
# ---------------------------------------------------------------------------------------


def closest_on_segments(point, a, b):
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


def _palm_centre(model, kin: Kinematics, side: str) -> np.ndarray:
    return kin.point(model, f"{side}_palm")


def _hand_contact(model, kin: Kinematics, side: str) -> np.ndarray:
    """The vertical hand's middle fingertip, where it meets the other palm."""
    return kin.point(model, f"{side}_hand_tip")


def _crossing(model, kin: Kinematics, side: str) -> np.ndarray:
    return forearm_crossing(kin, model)


def _finger_on_lips(model, kin: Kinematics, side: str) -> np.ndarray:
    """The point of the index finger's two distal segments closest to the mouth."""
    mouth = kin.point(model, "mouth")
    cands = [closest_on_segments(mouth, kin.point(model, a), kin.point(model, b))
             for a, b in ((f"{side}_index2", f"{side}_index3"), (f"{side}_index3", f"{side}_index_tip"))]
    dist = np.stack([np.linalg.norm(c - mouth, axis=-1) for c in cands])
    return np.where((dist[0] <= dist[1])[:, None], cands[0], cands[1])


def _one_hand(model, side: str) -> list:
    return hand_joints(model, side)


def _both_hands(model, side: str) -> list:
    return hand_joints(model, "l") + hand_joints(model, "r")


def _hand_and_head(model, side: str) -> list:
    return hand_joints(model, side) + [model.joint_index("head")]


def _forearms(model, side: str) -> list:
    return [model.joint_index(n) for n in ("l_elbow", "r_elbow", "l_wrist", "r_wrist")]


@dataclass(frozen=True)
class GestureKind:
    """One gesture class: ``build(context) -> IK stages`` draws a random instance,
    ``reference(model, kin, side) -> (B, 3)`` is its annotated point and
    ``parts(model, side) -> joint indices`` the skin that may be seen at that point."""

    build: Callable[[PoseContext], list]
    reference: Callable
    parts: Callable


#: The gestures by name, in class-id order (:data:`~hmocap_ros.gestures.classes.ALL_GESTURES`).
GESTURES = {
    "tee": GestureKind(_tee, _hand_contact, _both_hands),
    "pause": GestureKind(_pause, _palm_centre, _one_hand),
    "silence": GestureKind(_silence, _finger_on_lips, _hand_and_head),
    "cross": GestureKind(_cross, _crossing, _forearms),
    "ok": GestureKind(_ok, _palm_centre, _one_hand),
    "volume_up": GestureKind(_volume_up, _palm_centre, _one_hand),
    "thumbs_up": GestureKind(_thumbs_up, _palm_centre, _one_hand),
    "raised_fist": GestureKind(_raised_fist, _palm_centre, _one_hand),
}


def gesture_spec(model, subject: Subject, name: str, rng: np.random.Generator, *,
                 camera_body=None, side: str | None = None) -> PoseSpec:
    """A random instance of gesture ``name`` (:data:`GESTURES`) for ``subject``.

    camera_body: camera position in the body frame (see
    :func:`~hmocap_sim.gesture_pose.world_to_body`), so the palm of pause/ok faces the
    camera and the head turns to it; side: "l"/"r" or random.
    """
    if name not in ALL_GESTURES:
        raise ValueError(f"unknown gesture {name!r}; choose one of {ALL_GESTURES}")
    c = start_pose(model, subject, rng, camera_body, side)
    return PoseSpec(name, c.side, c.params, GESTURES[name].build(c))


def reference_point(model, kin: Kinematics, name: str, side: str) -> np.ndarray:
    """The annotated 3D point (B, 3) of gesture ``name`` in ``kin``'s frame."""
    if name not in GESTURES:
        raise ValueError(f"unknown gesture {name!r}")
    return GESTURES[name].reference(model, kin, side)


def reference_parts(model, name: str, side: str) -> list:
    """Joint indices whose skin (``model.vertex_part``) may be seen at the reference pixel
    for the annotation to count as visible (e.g. the gesturing hand for pause)."""
    if name not in GESTURES:
        raise ValueError(f"unknown gesture {name!r}")
    return GESTURES[name].parts(model, side)
