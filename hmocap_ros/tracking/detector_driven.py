"""Detector-driven propagation (thesis sec. 2.5): 3D detections drive the limbs.

Per tracked frame, the extremity detector's detections of that frame set
(:class:`~hmocap_ros.detection.detections.Detections`, from the ``extremity_detection`` node
or the same code in the evaluator) are assigned to the body around the predicted pose
(:mod:`.detection_assignment`: skin candidates by eq. 2.19 and re-acquisition, keypoints by
label); IK particles put the arms where the hands are (:mod:`.ik_proposals`); the final layer
weighs the distance of the particles' hands to the detections (eq. 2.20) into the refinement
layer (eq. 2.21).

A keypoint detector's labelled hands and head are assigned by their labels; its other
joints serve the keypoint-first method (:mod:`.keypoint_first`), not this one.
"""
from __future__ import annotations

import logging

import numpy as np

from hmocap_ros.detection.detections import Detections
from hmocap_ros.detection.detectors import carries_labels
from hmocap_ros.detection.greedy_assignment import classify
from hmocap_ros.tracking.detection_assignment import (
    EFFECTOR_LABELS,
    HEAD_EXCLUSION,
    MAX_DISTANCE,
    Assigned,
    detection_cost,
    reacquire_hands,
)
from hmocap_ros.tracking.ik_proposals import IKProposer

__all__ = ["REFINE_KAPPA", "DetectorDriven"]

log = logging.getLogger(__name__)

#: Weight kappa (per metre) of the detection cost of eq. 2.20 in the refinement layer
#: (eq. 2.21): two metres of hand distance weigh as much as a whole-image silhouette XOR
#: of 1 (the costs' scale, eq. 2.8), so a hand a few cm off outweighs a few pixels.
REFINE_KAPPA = 2.0


class DetectorDriven:
    """The detections and IK particles of one tracker (see the module docstring).

    model: the tracking body; layer_blocks: per weighting of the schedule, the blocks it
    concentrates on (the final layer's is empty).
    """

    def __init__(self, model, layer_blocks):
        self.ik = IKProposer(model)
        names = list(model.joint_names)
        self.n_joints = len(names)
        self.n_weightings = len(layer_blocks)
        #: per side, (shoulder, elbow, wrist) joint indices: the arm's reach
        self._arms = np.array([[names.index(f"{s}_{n}") for n in ("shoulder", "elbow", "wrist")]
                               for s in "lr"])

    def reset(self) -> None:
        self.ik.reset()

    def assign(self, detections: Detections, joints: np.ndarray, targets: np.ndarray
               ) -> Assigned:
        """The detections assigned around the predicted pose: ``joints`` (J, 3) and its
        end-effectors ``targets`` (5, 3) (module docstring)."""
        if not carries_labels(detections):  # candidates by eq. 2.19 and re-acquisition
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
        return Assigned(detections.positions, assigned)

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
        or None: on the final layer, eq. 2.20's hand term (the refinement layer, eq. 2.21).
        None when nothing was detected."""
        if assigned is None or not len(assigned.detections):
            return None
        kappa, ik = REFINE_KAPPA, self.ik
        detected = assigned.assigned

        def refinement(particles: np.ndarray, joints: np.ndarray) -> np.ndarray:
            return kappa * detection_cost(detected, ik.end_effectors(particles, rest))

        return [None] * (self.n_weightings - 1) + [refinement]

    def learn(self, res, assigned: Assigned | None, rest) -> None:
        """After the filter: adapt the IK particles' share to how well they did."""
        if assigned is not None:
            self.ik.update_fraction(res.weighted_particles, res.weights, assigned.assigned, rest)
