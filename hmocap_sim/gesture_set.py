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
 7    thumbs_up    a fist in front of the body, palm towards the midline,      palm centre
                   the thumb pointing up
 8    raised_fist  a fist raised above the shoulder, forearm upright           palm centre
====  ===========  ==========================================================  ===========================

Classes 7 and 8 (:data:`NEW_GESTURES`) are gestures to teach: they are rendered only when a bag
or the simulated teacher asks for them, never in a default bag, so the shipped forest (trained
on the six) has never seen them.

Tee is the hand "time out" T of the thesis' dataset (fig. 3.3), not arms spread in a T:
its annotation is the point where the fingertips of the vertical hand meet the palm of the
horizontal one.  The reference point is a body point (rigidly attached to a joint, so it
moves with the pose); the simulator projects it to get the pixel (u, v) and takes the 3D
position from the rendered surface at that pixel (``gesture_dataset``).

Negative (non-gesture) poses, :data:`NEGATIVE_KINDS`: idle standing, walking, random arm
poses and everyday poses close to the gestures (arms folded, chin on the fist, phone at the
ear, pointing, scratching the head, hands on the hips, hands clasped, waving with the hand
sideways). Near misses, :data:`NEAR_MISSES` (``gesture_near_misses``): each gesture done
slightly wrong (a finger bent, the ring open, the hand turned, the arm half raised), also
background.

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

This module gathers the gesture set's public names; the code lives in ``gesture_kinds``
(names, class ids), ``gesture_body`` (subjects, kinematics), ``gesture_ik`` (tasks, solver,
:class:`PoseSpec`), ``gesture_pose`` (base pose, hand presets, placement), ``gesture_specs``
(:data:`GESTURES`: the classes' builders and reference points), ``gesture_negatives``
(:data:`NEGATIVE_BUILDERS`) and ``gesture_near_misses`` (:data:`NEAR_MISS_BUILDERS`).

Frames are the body model's (``skeleton.py``): metres, +Y up, the body faces +Z, +X is the
person's left; sides are ``"l"`` and ``"r"`` (the person's left and right).
"""
from __future__ import annotations

import numpy as np

from hmocap_ros.gestures.classes import (
    ALL_GESTURES,
    GESTURE_CLASSES,
    NEW_GESTURES,
    REFERENCE_POINTS,
    class_id,
)
from hmocap_sim.gesture_body import (
    FINGER_NAMES,
    FORWARD,
    LEFT,
    SIDES,
    SUBJECT_STREAM,
    UP,
    Kinematics,
    Subject,
    hand_axes,
    hand_joints,
    kinematics,
    lateral,
    make_subject,
    other,
    posed_vertices,
)
from hmocap_sim.gesture_ik import (
    RESTART_ERROR_M,
    RESTARTS,
    TASK_RESIDUALS,
    PoseSpec,
    Task,
    ground,
    jitter_spec,
    solve_ik,
    solve_spec,
)
from hmocap_sim.gesture_kinds import (
    NEAR_MISS_KINDS,
    NEAR_MISSES,
    NEGATIVE_KINDS,
    NEGATIVE_WEIGHTS,
    near_misses_of,
)
from hmocap_sim.gesture_near_misses import NEAR_MISS_BUILDERS, near_miss_spec
from hmocap_sim.gesture_negatives import NEGATIVE_BUILDERS, negative_spec
from hmocap_sim.gesture_pose import (
    ARM_DOFS,
    ARM_PRIOR,
    HAND_PRESETS,
    PoseContext,
    arm_dofs,
    arm_prior,
    base_pose,
    body_to_world,
    place,
    set_hand,
    start_pose,
    walk_params,
    world_to_body,
)
from hmocap_sim.gesture_specs import (
    GESTURES,
    GestureKind,
    closest_on_segments,
    forearm_crossing,
    gesture_spec,
    reference_parts,
    reference_point,
)

__all__ = [
    "ALL_GESTURES",
    "ARM_DOFS",
    "ARM_PRIOR",
    "FINGER_NAMES",
    "FORWARD",
    "GESTURES",
    "GESTURE_CLASSES",
    "HAND_PRESETS",
    "LEFT",
    "NEAR_MISSES",
    "NEAR_MISS_BUILDERS",
    "NEAR_MISS_KINDS",
    "NEGATIVE_BUILDERS",
    "NEGATIVE_KINDS",
    "NEGATIVE_WEIGHTS",
    "NEW_GESTURES",
    "REFERENCE_POINTS",
    "RESTARTS",
    "RESTART_ERROR_M",
    "SIDES",
    "SUBJECT_STREAM",
    "TASK_RESIDUALS",
    "UP",
    "GestureKind",
    "Kinematics",
    "PoseContext",
    "PoseSpec",
    "Subject",
    "Task",
    "arm_dofs",
    "arm_prior",
    "base_pose",
    "body_to_world",
    "class_id",
    "closest_on_segments",
    "forearm_crossing",
    "gesture_spec",
    "ground",
    "hand_axes",
    "hand_joints",
    "jitter_spec",
    "kinematics",
    "lateral",
    "make_subject",
    "near_miss_spec",
    "near_misses_of",
    "negative_spec",
    "other",
    "place",
    "pose_spec",
    "posed_vertices",
    "reference_parts",
    "reference_point",
    "set_hand",
    "solve_ik",
    "solve_spec",
    "start_pose",
    "walk_params",
    "world_to_body",
]


def pose_spec(model, subject: Subject, kind: str, rng: np.random.Generator, **kwargs) -> PoseSpec:
    """:func:`gesture_spec` for a gesture, :func:`near_miss_spec` for a near miss,
    :func:`negative_spec` otherwise."""
    if kind in ALL_GESTURES:
        return gesture_spec(model, subject, kind, rng, **kwargs)
    if kind in NEAR_MISSES:
        return near_miss_spec(model, subject, kind, rng, **kwargs)
    return negative_spec(model, subject, kind, rng, **kwargs)
