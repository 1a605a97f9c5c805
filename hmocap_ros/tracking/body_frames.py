"""A tracked body's coordinate frames (tf2, REP-155) and per-joint confidence, without rclpy.

``body_tracker`` fills ``/tf`` and ``Skeleton.confidence`` from these functions; the maths
lives here so that tests and offline tools get the same numbers.

Frames (REP-155, "Body frames")
-------------------------------
Per tracked body with id ``<id>`` (the ``body_id`` of the Skeleton message, ``b0`` for the
first body by default):

- ``<room> -> body_<id>``: the body frame, at the pelvis joint, the root of the tracking
  skeleton (REP-155 puts it at the mid point of the hips; the tracking body's pelvis joint
  lies 2.4 cm above that point);
- ``<parent frame> -> <frame>_<id>`` for each other joint of the tracking skeleton, along its
  kinematic tree: the joints whose parent is the pelvis (``spine``, ``l_hip``, ``r_hip``)
  hang from ``body_<id>``, every other joint from its parent joint's frame.

Frame names (:func:`rep155_frame_name`): a joint with a counterpart in REP-155's human model
(ros4hri/human_description: ``body``, ``waist``, ``head``, ``l_shoulder`` ... ``r_ankle``)
takes that link's name, the others keep the tracking skeleton's, all suffixed with the body
id as REP-155 asks:

=================  ====================  =============================================
tracking joint     frame                 REP-155 counterpart
=================  ====================  =============================================
``pelvis``         ``body_<id>``         ``body`` (the root)
``spine``          ``waist_<id>``        ``waist`` (the lower trunk's bending joint)
``head``           ``head_<id>``         ``head``
``l_shoulder``,    ``l_shoulder_<id>``,  the same names: shoulders, elbows, wrists,
... ``r_ankle``    ...                   hips, knees, ankles of both sides
``chest``,         ``chest_<id>``,       none: REP-155's trunk is one link (``torso``,
``neck``,          ``neck_<id>``,        fixed at shoulder height) and its arms hang from
``l_clavicle``,    ``l_clavicle_<id>``,  it; the tracking skeleton bends at the chest
``r_clavicle``     ``r_clavicle_<id>``   and the neck and moves the clavicles
=================  ====================  =============================================

The Skeleton message keeps the tracking skeleton's joint names (``pelvis``, ``spine``, ...),
and ``humans/bodies/<id>/joint_states`` carries the tracker's degrees of freedom by name: the
human_description URDF parametrises the body with other joints (``l_y_shoulder``,
``l_p_shoulder``, ...), so its joint names would not describe these angles.

Orientation follows REP-155 and REP-103: x forward (out of the body), y to the person's
left, z up (towards the head) for a person standing in the rest pose. The body model's own
axes are x left, y up, z forward (:mod:`hmocap_ros.body.skeleton`), so a joint's frame is
its global rotation from the forward kinematics (eq. 2.11, ``G_j``) times the constant axis
change :data:`REP155_AXES`: in the rest pose all frames are parallel to the body frame, and
each frame turns with the bone that starts at its joint (``l_elbow_<id>`` with the
forearm). A frame's origin is its joint's centre, so composing the transforms from the room
to ``<joint>_<id>`` gives the joint position of the Skeleton message.

Confidence (``Skeleton.confidence``)
------------------------------------
The particle filter's final layer weighs a set of poses; where they agree on a joint, the
joint is well determined by the images. :func:`joint_spread` measures, per joint, the
weighted root-mean-square distance of the joint's position over the particles from its
weighted mean (metres; the three axes together), on the :data:`SPREAD_PARTICLES` heaviest
particles. :func:`joint_confidence` maps it to [0, 1] with ``exp(-spread / SPREAD_SCALE)``
(:data:`SPREAD_SCALE` = 5 cm: 1 where all particles agree, 0.37 at a 5 cm spread, 0.14 at
10 cm). A labelled detection of the joint (the keypoint detector's joints that the tracker
assigned, ``Assigned.joints`` with ``joint_scores``) raises the confidence where it agrees
with the estimate: ``a = score * exp(-d^2 / (2 AGREEMENT_SCALE^2))`` with ``d`` the distance
from the estimated joint to the detection (:data:`AGREEMENT_SCALE` = 5 cm), combined as
``1 - (1 - c)(1 - a)``: either source being sure is enough, and a detection never lowers
the confidence (one far from the estimate means one of the two is wrong, which the spread
already weighs).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from hmocap_ros.body.kinematics import forward_kinematics
from hmocap_ros.body.skeleton import pose_to_local_rotations
from hmocap_ros.io.tf import FrameTransform, rotations_to_quaternions

__all__ = ["AGREEMENT_SCALE", "REP155_AXES", "REP155_NAMES", "SPREAD_PARTICLES", "SPREAD_SCALE",
           "body_frame", "body_transforms", "joint_confidence", "joint_frame", "joint_spread",
           "joint_transforms", "rep155_frame_name"]

#: Columns: the REP-155 body axes x (forward), y (left), z (up) in the body model's frame
#: (x left, y up, z forward). ``R_room_frame = G_joint @ REP155_AXES``.
REP155_AXES = np.array([[0.0, 1.0, 0.0],
                        [0.0, 0.0, 1.0],
                        [1.0, 0.0, 0.0]])
#: Spread (m) at which the confidence falls to 1/e.
SPREAD_SCALE = 0.05
#: Distance (m) between an estimated joint and its detection at which the agreement falls to
#: exp(-1/2) of the detection's score.
AGREEMENT_SCALE = 0.05
#: The spread is taken over at most this many particles, the heaviest (forward kinematics
#: only; docs/development.md, "Costs the code is shaped by").
SPREAD_PARTICLES = 256


#: Tracking joints whose REP-155 link has another name (the rest keep theirs; module docstring).
REP155_NAMES = {"pelvis": "body", "spine": "waist"}


def rep155_frame_name(joint: str) -> str:
    """The REP-155 link name of a tracking joint (before the body id): ``pelvis`` -> ``body``,
    ``spine`` -> ``waist``, every other joint its own name."""
    return REP155_NAMES.get(joint, joint)


def body_frame(body_id: str) -> str:
    """REP-155's body frame of ``body_id``: ``body_<id>``."""
    return f"body_{body_id}"


def joint_frame(joint: str, body_id: str) -> str:
    """The frame of tracking joint ``joint`` of body ``body_id``: ``<REP-155 name>_<id>``
    (:func:`rep155_frame_name`)."""
    return f"{rep155_frame_name(joint)}_{body_id}"


def joint_transforms(model, params: np.ndarray, rest_joints: np.ndarray) -> np.ndarray:
    """Global joint transforms of poses: (J, 4, 4) for one pose (D,), (N, J, 4, 4) for (N, D).

    Rotation block: joint frame (body model axes) -> room; translation: the joint's centre in
    the room. ``rest_joints``: the shaped rest joints (J, 3) (``apply_shape(model,
    shape).joints``; the tracker's ``fitness.rest(shape).joints``).
    """
    params = np.asarray(params, dtype=np.float64)
    rot, root = pose_to_local_rotations(model.skeleton, np.atleast_2d(params))
    transforms, _ = forward_kinematics(rot, root, rest_joints, model.parents)
    return transforms[0] if params.ndim == 1 else transforms


def body_transforms(joint_names: Sequence[str], parents: Sequence[int], transforms: np.ndarray,
                    body_id: str, parent_frame: str) -> list[FrameTransform]:
    """The tf2 frames of one body (module docstring): ``parent_frame`` -> ``body_<id>`` first,
    then each other joint's frame from its parent's, in joint order.

    transforms: (J, 4, 4) global joint transforms in ``parent_frame`` (:func:`joint_transforms`);
    joint_names, parents: the skeleton's (the root's parent is -1). ValueError for transforms
    that are not finite rigid motions.
    """
    transforms = np.asarray(transforms, dtype=np.float64)
    parent_index = np.asarray(parents, dtype=np.intp)
    n = len(joint_names)
    if transforms.shape != (n, 4, 4) or parent_index.shape != (n,):
        raise ValueError(f"need (J, 4, 4) transforms and (J,) parents for {n} joints, got "
                         f"{transforms.shape} and {parent_index.shape}")
    world = transforms[:, :3, :3] @ REP155_AXES                  # (J, 3, 3) frame -> room
    position = transforms[:, :3, 3]
    roots = parent_index < 0
    up = np.where(roots, 0, parent_index)
    # child pose in its parent's frame: R_p^T R_c, R_p^T (p_c - p_p); roots stay in the room
    local = np.where(roots[:, None, None], world,
                     np.einsum("jki,jkl->jil", world[up], world))
    offset = np.where(roots[:, None], position,
                      np.einsum("jki,jk->ji", world[up], position - position[up]))
    quaternions = rotations_to_quaternions(local)
    names = [body_frame(body_id) if root else joint_frame(name, body_id)
             for name, root in zip(joint_names, roots)]
    out = []
    for j in np.argsort(~roots, kind="stable"):  # the root(s) first
        parent = parent_frame if roots[j] else names[parent_index[j]]
        out.append(FrameTransform(parent, names[j], tuple(offset[j]), tuple(quaternions[j])))
    return out


def joint_spread(model, particles: np.ndarray, weights: np.ndarray,
                 rest_joints: np.ndarray) -> np.ndarray:
    """Per joint, the weighted RMS distance (m) of its position over weighted particles from
    its weighted mean: (J,).

    particles: (N, D) poses, weights: (N,) non-negative (normalised here); only the
    :data:`SPREAD_PARTICLES` heaviest count. ``rest_joints`` as :func:`joint_transforms`.
    """
    particles = np.asarray(particles, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    if particles.ndim != 2 or weights.shape != (len(particles),) or len(particles) == 0:
        raise ValueError(f"need (N, D) particles and (N,) weights, got {particles.shape} and "
                         f"{weights.shape}")
    if len(weights) > SPREAD_PARTICLES:
        keep = np.argpartition(weights, -SPREAD_PARTICLES)[-SPREAD_PARTICLES:]
        particles, weights = particles[keep], weights[keep]
    weights = np.where(np.isfinite(weights) & (weights > 0), weights, 0.0)
    total = weights.sum()
    if total <= 0:
        weights = np.full(len(weights), 1.0 / len(weights))
    else:
        weights = weights / total
    positions = joint_transforms(model, particles, rest_joints)[..., :3, 3]  # (N, J, 3)
    mean = np.einsum("n,njk->jk", weights, positions)
    squared = np.sum((positions - mean) ** 2, axis=-1)                       # (N, J)
    return np.sqrt(np.maximum(weights @ squared, 0.0))


def joint_confidence(spread: np.ndarray, joints: np.ndarray | None = None,
                     detected: np.ndarray | None = None,
                     scores: np.ndarray | None = None) -> np.ndarray:
    """Confidence in [0, 1] per joint (module docstring): ``exp(-spread / SPREAD_SCALE)``,
    raised where a labelled detection agrees with the estimate.

    spread: (J,) metres (:func:`joint_spread`); joints: (J, 3) the estimated joints;
    detected: (J, 3) a labelled detection per joint (NaN rows: none) and scores (J,) in
    [0, 1]. Non-finite spreads give 0.
    """
    spread = np.asarray(spread, dtype=np.float64)
    confidence = np.where(np.isfinite(spread), np.exp(-np.maximum(spread, 0.0) / SPREAD_SCALE), 0.0)
    if joints is not None and detected is not None and scores is not None:
        detected = np.asarray(detected, dtype=np.float64)
        distance = np.linalg.norm(np.asarray(joints, dtype=np.float64) - detected, axis=-1)
        score = np.clip(np.nan_to_num(np.asarray(scores, dtype=np.float64)), 0.0, 1.0)
        agreement = np.where(np.isfinite(distance),
                             score * np.exp(-0.5 * (np.nan_to_num(distance) / AGREEMENT_SCALE) ** 2),
                             0.0)
        confidence = 1.0 - (1.0 - confidence) * (1.0 - agreement)
    return np.clip(confidence, 0.0, 1.0)
