"""Near misses: each gesture done slightly wrong, labelled as background (a detector must refuse
them). :data:`NEAR_MISS_BUILDERS` maps each kind of
:data:`~hmocap_sim.gesture_kinds.NEAR_MISSES` to a builder of a
:class:`~hmocap_sim.gesture_pose.PoseContext`.

A near miss is its gesture's builder (:data:`~hmocap_sim.gesture_specs.GESTURES`) run on
the same context, then one thing changed beyond the gesture's own variation (the kinds of the
issue a real room showed: a finger bent or missing, fingers together where they should be
apart, the hand rotated or tilted beyond the gesture's tolerance, the arm half raised):

==================  ===========  ==============================================================
kind                misses       what is wrong
==================  ===========  ==============================================================
tee_apart           tee          the top hand 9-15 cm above the stem's fingertips, not on them
tee_fist            tee          the top hand a fist
pause_curled        pause        the four fingers bent (knuckles 60-90 deg, middle joints 40-70), not open
pause_one_bent      pause        one of the four fingers bent to the palm (a finger missing from the open hand)
pause_together      pause        the fingers together (a flat hand, no spread) where pause spreads them
pause_tilted        pause        the palm tilted 45-75 deg up or down about the forearm's lateral axis
pause_sideways      pause        the open hand turned 65-110 deg in its plane (fingers sideways)
pause_half          pause        the arm half raised: the palm 30-45 cm lower, below the shoulder
silence_cheek       silence      the finger on the cheek, 4-7 cm beside the mouth
silence_bent        silence      the index finger curled: a fist at the lips
cross_apart         cross        the forearms raised, each wrist 20-30 cm out: not crossing
cross_one           cross        one forearm across the chest, the other arm hanging
ok_open             ok           the ring open: thumb tip 3.5-6 cm from the index tip
ok_closed           ok           the other three fingers curled (a closed "O")
volume_low          volume_up    the cupped hand at the jaw, 9-14 cm below the ear
volume_flat         volume_up    the hand flat over the ear, palm on the head
thumbs_sideways     thumbs_up    the thumb pointing forwards or sideways, not up
thumbs_tucked       thumbs_up    the thumb tucked: a plain fist
raised_fist_half    raised_fist  the fist at chest height, forearm level
raised_open         raised_fist  a relaxed open hand raised instead of a fist
==================  ===========  ==============================================================

The tolerances the near misses lie beyond are those of the gesture builders (e.g. pause's
fingers are within about 30 deg of vertical, ok's thumb tip within 3 cm of the index tip,
silence's finger within 1 cm of the mouth's midline).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from hmocap_sim.gesture_body import FORWARD, UP, Subject, lateral, unit
from hmocap_sim.gesture_ik import PoseSpec
from hmocap_sim.gesture_kinds import NEAR_MISSES
from hmocap_sim.gesture_pose import PoseContext, rotate_towards, set_hand, start_pose
from hmocap_sim.gesture_specs import GESTURES

__all__ = ["NEAR_MISS_BUILDERS", "near_miss_spec"]


def _map_tasks(stages: list, fn) -> list:
    """``stages`` with every task replaced by ``fn(task)`` (None drops it)."""
    out = []
    for dofs, tasks, prior in stages:
        new = [t2 for t2 in (fn(t) for t in tasks) if t2 is not None]
        out.append((dofs, new, prior))
    return out


def _moved(stages: list, a: str, offset) -> list:
    """The "point" task of body point ``a`` moved by ``offset`` (metres, body frame)."""
    return _map_tasks(stages, lambda t: replace(t, target=t.target + offset) if t.kind == "point" and t.a == a else t)


def _spin(axis_target, normal, angle_deg: float):
    """``axis_target`` rotated by ``angle_deg`` about ``normal`` (Rodrigues)."""
    k = unit(np.asarray(normal, np.float64))
    v = np.asarray(axis_target, np.float64)
    a = np.deg2rad(angle_deg)
    return v * np.cos(a) + np.cross(k, v) * np.sin(a) + k * (k @ v) * (1 - np.cos(a))


def _tee_apart(c: PoseContext) -> list:
    lift = UP * c.rng.uniform(0.09, 0.15)
    return _map_tasks(GESTURES["tee"].build(c),
                      lambda t: replace(t, target=t.target + lift) if t.kind == "touch" else t)


def _tee_fist(c: PoseContext) -> list:
    stages = GESTURES["tee"].build(c)
    set_hand(c.model, c.params, c.other, "fist", c.rng)
    return stages


def _pause_curled(c: PoseContext) -> list:
    stages = GESTURES["pause"].build(c)
    m = c.model.skeleton
    for f in ("index", "middle", "ring", "pinky"):
        c.params[m.dof_index(f"{c.side}_{f}1_flex")] = np.deg2rad(c.rng.uniform(60, 90))
        c.params[m.dof_index(f"{c.side}_{f}2_flex")] = np.deg2rad(c.rng.uniform(40, 70))
    return stages


def _pause_one_bent(c: PoseContext) -> list:
    stages = GESTURES["pause"].build(c)
    m = c.model.skeleton
    f = ("index", "middle", "ring", "pinky")[int(c.rng.integers(4))]
    for k, (lo, hi) in zip((1, 2, 3), ((75, 95), (85, 105), (45, 65))):
        c.params[m.dof_index(f"{c.side}_{f}{k}_flex")] = np.deg2rad(c.rng.uniform(lo, hi))
    return stages


def _pause_together(c: PoseContext) -> list:
    stages = GESTURES["pause"].build(c)
    set_hand(c.model, c.params, c.side, "flat", c.rng, 3.0)
    return stages


def _pause_tilted(c: PoseContext) -> list:
    stages = GESTURES["pause"].build(c)
    angle = c.rng.uniform(45, 75) * (1 if c.rng.random() < 0.5 else -1)
    # the palm's normal and the fingers turn together about the body's lateral axis
    return _map_tasks(stages, lambda t: replace(t, target=_spin(t.target, c.lateral, angle), weight=0.3)
                      if t.kind == "axis" and t.a in (f"{c.side}_volar", f"{c.side}_d") else t)


def _pause_sideways(c: PoseContext) -> list:
    stages = GESTURES["pause"].build(c)
    s = c.side
    volar = next(t.target for _, tasks, _ in stages for t in tasks if t.kind == "axis" and t.a == f"{s}_volar")
    angle = c.rng.uniform(65, 110) * (1 if c.rng.random() < 0.5 else -1)
    return _map_tasks(stages, lambda t: replace(t, target=_spin(t.target, volar, angle), weight=0.3)
                      if t.kind == "axis" and t.a == f"{s}_d" else t)


def _pause_half(c: PoseContext) -> list:
    stages = GESTURES["pause"].build(c)
    drop = -UP * c.rng.uniform(0.30, 0.45) + FORWARD * c.rng.uniform(0.0, 0.1)
    return _map_tasks(_moved(stages, f"{c.side}_palm", drop),
                      lambda t: None if t.kind == "point" and t.a == f"{c.side}_elbow" else t)


def _silence_cheek(c: PoseContext) -> list:
    side_shift = c.lateral * c.rng.uniform(0.04, 0.07) - FORWARD * 0.01
    return _moved(GESTURES["silence"].build(c), f"{c.side}_index_tip", side_shift)


def _silence_bent(c: PoseContext) -> list:
    stages = GESTURES["silence"].build(c)
    set_hand(c.model, c.params, c.side, "fist", c.rng)
    # the curled index cannot point up: keep only where the finger tip goes
    return _map_tasks(_moved(stages, f"{c.side}_index_tip", FORWARD * 0.01),
                      lambda t: None if t.kind == "dir" else t)


def _cross_apart(c: PoseContext) -> list:
    half = c.rng.uniform(0.10, 0.15)
    stages = GESTURES["cross"].build(c)
    for s in ("l", "r"):
        # each forearm's points moved to its own side: the X opens into a V with a gap
        stages = _moved(_moved(stages, f"{s}_wrist", lateral(s) * 2 * half), f"{s}_elbow", lateral(s) * 0.5 * half)
    return stages


def _cross_one(c: PoseContext) -> list:
    stages = GESTURES["cross"].build(c)
    o = c.other
    return [(tuple(d for d in dofs if not d.startswith(f"{o}_")),
             [t for t in tasks if not t.a.startswith(f"{o}_")],
             {k: v for k, v in prior.items() if not k.startswith(f"{o}_")}) for dofs, tasks, prior in stages]


def _ok_open(c: PoseContext) -> list:
    stages = GESTURES["ok"].build(c)
    gap = c.rng.uniform(0.035, 0.06)
    direction = unit(UP + c.rng.normal(0.0, 0.3, 3))
    return _map_tasks(stages, lambda t: replace(t, target=direction * gap) if t.kind == "touch" else t)


def _ok_closed(c: PoseContext) -> list:
    stages = GESTURES["ok"].build(c)
    m = c.model.skeleton
    for f in ("middle", "ring", "pinky"):
        for k, (lo, hi) in zip((1, 2, 3), ((75, 95), (85, 105), (45, 65))):
            c.params[m.dof_index(f"{c.side}_{f}{k}_flex")] = np.deg2rad(c.rng.uniform(lo, hi))
    return stages


def _volume_low(c: PoseContext) -> list:
    drop = -UP * c.rng.uniform(0.09, 0.14) + FORWARD * c.rng.uniform(0.02, 0.05)
    return _moved(GESTURES["volume_up"].build(c), f"{c.side}_palm", drop)


def _volume_flat(c: PoseContext) -> list:
    stages = GESTURES["volume_up"].build(c)
    s = c.side
    set_hand(c.model, c.params, s, "flat", c.rng)
    inward = c.medial
    return _map_tasks(_moved(stages, f"{s}_palm", c.medial * 0.03),
                      lambda t: replace(t, target=inward, weight=0.3) if t.kind == "axis" and t.a == f"{s}_volar"
                      else (None if t.kind == "axis" else t))


def _thumbs_sideways(c: PoseContext) -> list:
    stages = GESTURES["thumbs_up"].build(c)
    way = unit(rotate_towards(UP, c.medial if c.rng.random() < 0.5 else FORWARD, c.rng.uniform(70, 100)))
    return _map_tasks(stages, lambda t: replace(t, target=way) if t.kind == "dir" else t)


def _thumbs_tucked(c: PoseContext) -> list:
    stages = GESTURES["thumbs_up"].build(c)
    set_hand(c.model, c.params, c.side, "fist", c.rng)
    return _map_tasks(stages, lambda t: None if t.kind == "dir" else t)


def _raised_fist_half(c: PoseContext) -> list:
    stages = GESTURES["raised_fist"].build(c)
    s = c.side
    drop = -UP * c.rng.uniform(0.45, 0.6) + FORWARD * c.rng.uniform(0.15, 0.3)
    level = unit(FORWARD + c.medial * c.rng.uniform(0.0, 0.6))
    return _map_tasks(_moved(stages, f"{s}_palm", drop),
                      lambda t: replace(t, target=level) if t.kind == "axis" and t.a == f"{s}_d"
                      else (None if t.kind == "point" and t.a == f"{s}_elbow" or t.kind == "axis" else t))


def _raised_open(c: PoseContext) -> list:
    stages = GESTURES["raised_fist"].build(c)
    set_hand(c.model, c.params, c.side, "relaxed", c.rng, 6.0)
    return stages


#: Builders of the near-miss kinds, in the order of :data:`~hmocap_sim.gesture_kinds.NEAR_MISSES`.
NEAR_MISS_BUILDERS = {
    "tee_apart": _tee_apart, "tee_fist": _tee_fist,
    "pause_curled": _pause_curled, "pause_one_bent": _pause_one_bent, "pause_together": _pause_together,
    "pause_tilted": _pause_tilted, "pause_sideways": _pause_sideways, "pause_half": _pause_half,
    "silence_cheek": _silence_cheek, "silence_bent": _silence_bent,
    "cross_apart": _cross_apart, "cross_one": _cross_one,
    "ok_open": _ok_open, "ok_closed": _ok_closed,
    "volume_low": _volume_low, "volume_flat": _volume_flat,
    "thumbs_sideways": _thumbs_sideways, "thumbs_tucked": _thumbs_tucked,
    "raised_fist_half": _raised_fist_half, "raised_open": _raised_open,
}


def near_miss_spec(model, subject: Subject, kind: str, rng: np.random.Generator, *,
                   camera_body=None, side: str | None = None) -> PoseSpec:
    """A random near miss of ``kind`` (:data:`NEAR_MISS_BUILDERS`); ``camera_body`` and ``side``
    as for :func:`~hmocap_sim.gesture_specs.gesture_spec`. Its class is background."""
    if kind not in NEAR_MISSES:
        raise ValueError(f"unknown near miss {kind!r}; choose one of {tuple(NEAR_MISSES)}")
    c = start_pose(model, subject, rng, camera_body, side)
    return PoseSpec(kind, c.side, c.params, NEAR_MISS_BUILDERS[kind](c))


