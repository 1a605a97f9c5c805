"""Detector-driven propagation (thesis sec. 2.5): 3D detections drive the limbs.

Per tracked frame, the extremity detector's detections of that frame set
(:class:`~hmocap_ros.detection.detections.Detections`, from the ``extremity_detection`` node
or the same code in the evaluator) are assigned to the body around the predicted pose
(:mod:`.detection_assignment`: skin candidates by eq. 2.19 and re-acquisition, keypoints by
label); IK particles put the arms where the hands are (:mod:`.ik_proposals`); the final layer
weighs the distance of the particles' hands to the detections (eq. 2.20) into the refinement
layer (eq. 2.21).

Beyond the thesis' skin detector, a keypoint detector also labels shoulders, elbows, wrists,
hips, knees and ankles. Each layer of the hierarchical schedule then adds to its silhouette
cost ``kappa_j`` times the score-weighted mean distance of the joints its block moves to their
detections, each distance capped at ``joint_cap`` (an outlier detection costs a bounded
amount and the silhouettes decide); the final layer takes every labelled joint. This is
eq. 2.21's refinement applied per partition, with the partition's own joints as ``C_t``.

=====================  =============================================================
block (layer)          joints weighed against their detections
=====================  =============================================================
torso                  shoulders, hips
left / right leg       knee, ankle
left / right shoulder  elbow, wrist (the shoulder layer samples the elbow too)
left / right elbow     wrist
final                  all of the above
=====================  =============================================================
"""
from __future__ import annotations

import logging

import numpy as np

from hmocap_ros.detection.detections import MODEL_JOINT, Detections
from hmocap_ros.tracking.detection_assignment import (EFFECTOR_LABELS, HEAD_EXCLUSION,
                                                      MAX_DISTANCE, Assigned, classify,
                                                      detection_cost, reacquire_hands)
from hmocap_ros.tracking.ik_proposals import IKProposer

__all__ = ["BLOCK_JOINTS", "DetectorDriven"]

log = logging.getLogger(__name__)

#: per body block (``body_layers.BODY_BLOCKS``) the model joints whose detections weigh it
BLOCK_JOINTS = {
    "torso": ("l_shoulder", "r_shoulder", "l_hip", "r_hip"),
    "l_leg": ("l_knee", "l_ankle"), "r_leg": ("r_knee", "r_ankle"),
    "l_shoulder": ("l_elbow", "l_wrist"), "r_shoulder": ("r_elbow", "r_wrist"),
    "l_elbow": ("l_wrist",), "r_elbow": ("r_wrist",),
}


class DetectorDriven:
    """The detections and IK particles of one tracker (see the module docstring).

    model: the tracking body; layer_blocks: per weighting of the schedule, the blocks it
    concentrates on (the final layer's is empty); params: the tracker's ``detector`` group.
    """

    def __init__(self, model, layer_blocks, params):
        self.params = params
        self.ik = IKProposer(model)
        names = list(model.joint_names)
        self.n_joints = len(names)
        #: per side, (shoulder, elbow, wrist) joint indices: the arm's reach
        self._arms = np.array([[names.index(f"{s}_{n}") for n in ("shoulder", "elbow", "wrist")]
                               for s in "lr"])
        self._joint_of = {label: names.index(joint) for label, joint in MODEL_JOINT.items()}
        every = sorted({names.index(j) for js in BLOCK_JOINTS.values() for j in js})
        self._layer_joints = [
            np.array(sorted({names.index(j) for b in blocks for j in BLOCK_JOINTS.get(b, ())})
                     if blocks else every, dtype=np.intp)
            for blocks in layer_blocks]

    def reset(self) -> None:
        self.ik.reset()

    def assign(self, detections: Detections, joints: np.ndarray, targets: np.ndarray
               ) -> Assigned:
        """The detections assigned around the predicted pose: ``joints`` (J, 3) and its
        end-effectors ``targets`` (5, 3) (module docstring)."""
        if detections.detector == "skin":
            cand = detections.positions
            assigned = np.full((len(EFFECTOR_LABELS), 3), np.nan)
            upsilon = np.asarray(MAX_DISTANCE)
            assigned[:3] = classify(cand, targets[:3], upsilon[:3])
            chain = np.concatenate([joints[self._arms], targets[:2, None]], axis=1)  # (2, 4, 3)
            reach = np.linalg.norm(np.diff(chain, axis=1), axis=2).sum(axis=1) + 0.05
            assigned[:2] = reacquire_hands(cand, assigned[:3], chain[:, 0], reach,
                                           targets[2], HEAD_EXCLUSION)
            return Assigned(cand, assigned)
        assigned = np.full((len(EFFECTOR_LABELS), 3), np.nan)
        for e, label in enumerate(EFFECTOR_LABELS[:3]):  # hands and head; legs by their joints
            pos = detections.position(label)
            if pos is not None:
                assigned[e] = pos
        joint_pos = np.full((self.n_joints, 3), np.nan)
        joint_scores = np.zeros(self.n_joints)
        for label, pos, score in zip(detections.labels, detections.positions, detections.scores):
            j = self._joint_of.get(label)
            if j is not None and score > joint_scores[j]:
                joint_pos[j], joint_scores[j] = pos, score
        return Assigned(detections.positions, assigned, joint_pos, joint_scores)

    def detect(self, fitness, rest, detections: Detections, reference: np.ndarray,
               particles: np.ndarray, rng: np.random.Generator) -> Assigned:
        """Assign ``detections`` around the predicted pose ``reference``, then IK particles
        for the detected hands (``particles`` changed in place)."""
        _, joints = fitness.pose(reference[None], rest)
        targets = self.ik.end_effectors(reference[None], rest)[0]
        assigned = self.assign(detections, np.asarray(joints[0]), targets)
        self.ik.apply(particles, assigned.assigned, reference, rest, rng)
        return assigned

    def layer_terms(self, assigned: Assigned | None, rest) -> list | None:
        """Per weighting, ``cost_fn(particles, joints) -> (N,)`` added to its silhouette cost,
        or None: the joint term of each block (module docstring) and, on the final layer,
        eq. 2.20's hand term (eq. 2.21). None when nothing was detected."""
        if assigned is None:
            return None
        p = self.params
        hands = (p.refine_kappa > 0 and len(assigned.detections) > 0)
        have = (assigned.joint_scores > 0 if assigned.joint_scores is not None
                else np.zeros(self.n_joints, bool))
        if not hands and not (p.joint_kappa > 0 and have.any()):
            return None
        terms = []
        last = len(self._layer_joints) - 1
        for layer, idx in enumerate(self._layer_joints):
            idx = idx[have[idx]] if p.joint_kappa > 0 else idx[:0]
            terms.append(_term(idx, assigned, p, self.ik, rest, hands and layer == last))
        return terms

    def learn(self, res, assigned: Assigned | None, rest) -> None:
        """After the filter: adapt the IK particles' share to how well they did."""
        if assigned is not None:
            self.ik.update_fraction(res.weighted_particles, res.weights, assigned.assigned, rest)


def _term(idx: np.ndarray, assigned: Assigned, p, ik: IKProposer, rest, hands: bool):
    """One weighting's detection term (see :meth:`DetectorDriven.layer_terms`), or None."""
    if len(idx) == 0 and not hands:
        return None
    target = assigned.joints[idx] if len(idx) else None
    w = assigned.joint_scores[idx] / max(float(assigned.joint_scores[idx].sum()), 1e-9) \
        if len(idx) else None

    def cost(particles: np.ndarray, joints: np.ndarray) -> np.ndarray:
        out = np.zeros(len(particles))
        if target is not None:
            d = np.linalg.norm(joints[:, idx] - target[None], axis=2)
            out += p.joint_kappa * (np.minimum(d, p.joint_cap) @ w)
        if hands:
            out += p.refine_kappa * detection_cost(assigned.assigned,
                                                   ik.end_effectors(particles, rest))
        return out

    return cost
