"""Non-gesture (background) poses as builders: :data:`NEGATIVE_BUILDERS` maps each kind of
:data:`~hmocap_sim.gesture_kinds.NEGATIVE_KINDS` to a function of a
:class:`~hmocap_sim.gesture_pose.PoseContext` that returns the pose's IK stages.

The kinds are idle standing, the standing part of walking (the cycle is
:func:`~hmocap_sim.gesture_pose.walk_params`), random arms, and near misses of the
gestures: arms folded vs cross, fist at the chin vs silence, phone at the ear vs volume up,
pointing, scratching the head, hands on the hips, hands clasped, a hand raised sideways vs
pause.  The random draws happen in the order they are written.
"""
from __future__ import annotations

import numpy as np

from hmocap_sim.gesture_body import FORWARD, SIDES, UP, Subject, lateral, unit
from hmocap_sim.gesture_ik import PoseSpec, Task
from hmocap_sim.gesture_kinds import NEGATIVE_KINDS
from hmocap_sim.gesture_pose import (
    PoseContext,
    arm_dofs,
    arm_prior,
    elbow_hint,
    set_dofs,
    set_hand,
    start_pose,
)


def _idle(c: PoseContext) -> list:
    """Standing; sometimes with the hands behind the back."""
    pt, u = c.pt, c.rng.uniform
    stages = []
    if c.rng.random() < 0.3:
        for side_ in SIDES:
            stages.append((arm_dofs(side_), [Task("point", f"{side_}_palm", pt("pelvis") - FORWARD * 0.17
                                                   + UP * u(-0.05, 0.05) + lateral(side_) * 0.05),
                                              elbow_hint(pt, side_, 0.9, -0.4, 0.3)], arm_prior(side_)))
    return stages


def _walk(c: PoseContext) -> list:
    """The standing pose that the walking cycle is laid over, head looking ahead."""
    set_dofs(c.model, c.params, {"neck_twist": c.rng.uniform(-10, 10), "head_twist": 0.0})
    return []


def _random_arms(c: PoseContext) -> list:
    """One or both arms anywhere in their range, with a random hand shape."""
    model, p, rng, u = c.model, c.params, c.rng, c.rng.uniform
    for side_ in SIDES if rng.random() < 0.5 else (c.side,):
        set_dofs(model, p, {f"{side_}_shoulder_flex": u(-20, 110), f"{side_}_shoulder_abd": u(-45, 70),
                            f"{side_}_shoulder_twist": u(-40, 50), f"{side_}_elbow_flex": u(-40, 100),
                            f"{side_}_elbow_twist": u(-40, 60), f"{side_}_wrist_flex": u(-30, 50),
                            f"{side_}_clavicle_elev": u(-5, 15)})
        set_hand(model, p, side_, str(rng.choice(["relaxed", "fist", "flat", "cupped"])), rng, 8.0)
    return []


def _fold_arms(c: PoseContext) -> list:
    """Arms folded over the stomach (near miss of cross: the forearms are level)."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s, o = c.side, c.other
    low, high = (s, o) if rng.random() < 0.5 else (o, s)
    centre = pt("sternum") + FORWARD * u(0.1, 0.14) + UP * u(-0.2, -0.1)
    stages = []
    for side_, dy in ((low, -0.035), (high, 0.035)):
        set_hand(model, p, side_, "relaxed", rng)
        stages.append((arm_dofs(side_), [
            Task("point", f"{side_}_wrist", centre + UP * dy - lateral(side_) * u(0.12, 0.18)),
            Task("point", f"{side_}_elbow", centre + UP * dy + lateral(side_) * u(0.14, 0.2), weight=0.5),
            Task("axis", f"{side_}_volar", -FORWARD, weight=0.05)], arm_prior(side_)))
    return stages


def _chin(c: PoseContext) -> list:
    """A fist under the chin (near miss of silence)."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s = c.side
    set_hand(model, p, s, "fist", rng)
    head_fwd = unit(pt("mouth") - 0.5 * (pt("l_ear") + pt("r_ear")))
    target = pt("mouth") - UP * u(0.06, 0.09) + head_fwd * u(0.0, 0.03)
    return [(arm_dofs(s), [Task("point", f"{s}_palm", target),
                           Task("axis", f"{s}_d", unit(UP + head_fwd), weight=0.1),
                           elbow_hint(pt, s, 0.9, 0.5, 0.0, 0.2)], arm_prior(s))]


def _phone(c: PoseContext) -> list:
    """A fist held at the ear like a phone, palm inwards (near miss of volume up)."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s, lat, med = c.side, c.lateral, c.medial
    set_hand(model, p, s, "fist", rng)
    target = pt(f"{s}_ear") + lat * u(0.04, 0.06) + UP * u(-0.06, -0.02) + FORWARD * u(0.0, 0.04)
    return [(arm_dofs(s), [Task("point", f"{s}_palm", target),
                           Task("axis", f"{s}_volar", med, weight=0.15),
                           elbow_hint(pt, s, 0.7, 0.6, 0.3, 0.2)], arm_prior(s))]


def _point(c: PoseContext) -> list:
    """Pointing with the index finger forwards and to the side."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s, lat = c.side, c.lateral
    set_hand(model, p, s, "point", rng, 3.0)
    direction = unit(FORWARD * u(0.2, 1.0) + lat * u(0.2, 1.0) + UP * u(-0.2, 0.4))
    target = pt(f"{s}_shoulder") + direction * u(0.5, 0.6)
    return [(arm_dofs(s), [Task("point", f"{s}_index_tip", target, weight=2.0),
                           Task("axis", f"{s}_d", direction, weight=0.2)], arm_prior(s))]


def _scratch_head(c: PoseContext) -> list:
    """A relaxed hand on the top of the head."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s, lat = c.side, c.lateral
    set_hand(model, p, s, "relaxed", rng)
    top = pt("head_top")
    target = top + lat * u(0.02, 0.07) - UP * u(0.0, 0.03) + FORWARD * u(-0.04, 0.03)
    return [(arm_dofs(s), [Task("point", f"{s}_palm", target),
                           Task("axis", f"{s}_volar", -UP, weight=0.1),
                           elbow_hint(pt, s, -0.3, 0.4, 1.0, 0.2)], arm_prior(s))]


def _hips(c: PoseContext) -> list:
    """One or both hands flat on the hips, fingers down."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    stages = []
    for side_ in SIDES if rng.random() < 0.7 else (c.side,):
        set_hand(model, p, side_, "flat", rng)
        hip = pt(f"{side_}_hip")
        stages.append((arm_dofs(side_), [
            Task("point", f"{side_}_palm", hip + lateral(side_) * u(0.05, 0.09) + UP * u(0.07, 0.14)),
            Task("axis", f"{side_}_volar", -lateral(side_), weight=0.1),
            Task("axis", f"{side_}_d", -UP, weight=0.05),
            elbow_hint(pt, side_, 0.6, -0.3, 1.0, 0.3)], arm_prior(side_)))
    return stages


def _clasp(c: PoseContext) -> list:
    """Cupped hands clasped in front of the stomach."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s, o, lat, med = c.side, c.other, c.lateral, c.medial
    for side_ in SIDES:
        set_hand(model, p, side_, "cupped", rng)
    centre = pt("spine") + FORWARD * u(0.17, 0.25) + UP * u(0.02, 0.18)
    return [(arm_dofs(s) + arm_dofs(o), [
        Task("point", f"{s}_palm", centre + lat * 0.025),
        Task("touch", f"{s}_palm", b=f"{o}_palm", target=med * 0.05, weight=1.0),
        Task("axis", f"{s}_volar", med, weight=0.1), Task("axis", f"{o}_volar", lat, weight=0.1),
        elbow_hint(pt, s, 1.0, 0.2, 0.2), elbow_hint(pt, o, 1.0, 0.2, 0.2)],
        {**arm_prior(s), **arm_prior(o)})]


def _wave_side(c: PoseContext) -> list:
    """A hand raised to the side with the palm towards the midline or the floor, never the
    camera (near miss of pause)."""
    model, p, pt, rng, u = c.model, c.params, c.pt, c.rng, c.rng.uniform
    s, lat, med = c.side, c.lateral, c.medial
    set_hand(model, p, s, str(rng.choice(["flat", "spread", "relaxed"])), rng, 4.0)
    target = pt(f"{s}_shoulder") + lat * u(0.15, 0.35) + UP * u(0.05, 0.3) + FORWARD * u(0.0, 0.2)
    volar = unit(med + (-UP if rng.random() < 0.5 else -FORWARD) * u(0.0, 0.6))
    return [(arm_dofs(s), [Task("point", f"{s}_palm", target),
                           Task("axis", f"{s}_volar", volar, weight=0.25),
                           elbow_hint(pt, s, u(0.0, 0.5), u(0.0, 0.3), 1.0, 0.2)],
             arm_prior(s))]


#: Builders of the negative kinds, in the order of :data:`NEGATIVE_KINDS`.
NEGATIVE_BUILDERS = {
    "idle": _idle,
    "walk": _walk,
    "random_arms": _random_arms,
    "fold_arms": _fold_arms,
    "chin": _chin,
    "phone": _phone,
    "point": _point,
    "scratch_head": _scratch_head,
    "hips": _hips,
    "clasp": _clasp,
    "wave_side": _wave_side,
}


def negative_spec(model, subject: Subject, kind: str, rng: np.random.Generator, *,
                  camera_body=None, side: str | None = None) -> PoseSpec:
    """A random non-gesture pose of ``kind`` (:data:`NEGATIVE_BUILDERS`); ``camera_body``
    and ``side`` as for :func:`~hmocap_sim.gesture_specs.gesture_spec`."""
    if kind not in NEGATIVE_KINDS:
        raise ValueError(f"unknown negative kind {kind!r}; choose one of {NEGATIVE_KINDS}")
    c = start_pose(model, subject, rng, camera_body, side)
    return PoseSpec(kind, c.side, c.params, NEGATIVE_BUILDERS[kind](c))
