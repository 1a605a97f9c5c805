"""Detector-driven propagation (thesis sec. 2.5): hands located in 3D drive the arms.

Per tracked frame, around the predicted pose: the extremity detector locates the hands (and
head) in 3D from the per-view detector maps and assigns them to the body's end effectors
(eq. 2.16-2.19, :mod:`.extremity_detection`); IK particles put the arms where the hands are
(:mod:`.ik_proposals`); the final layer weighs the distance of the particles' hands to the
detections (eq. 2.20) into the refinement layer (eq. 2.21). Only the hands are searched, as
with the thesis' skin detector; a hand that eq. 2.19 leaves unassigned (the arm lost by more
than its gate) may take a skin cluster within its arm's reach on its own side, so that IK
particles can draw a lost arm back.
"""
from __future__ import annotations

import logging

import numpy as np

from hmocap_ros.tracking.extremity_detection import (Extremities, ExtremityDetector,
                                                     ExtremityParams, detection_cost)
from hmocap_ros.tracking.ik_proposals import IKProposer

__all__ = ["DetectorDriven"]

log = logging.getLogger(__name__)


class DetectorDriven:
    """The detections and IK particles of one tracker (see the module docstring)."""

    def __init__(self, model, cameras):
        self.cameras = tuple(cameras)
        self.detector = ExtremityDetector(self.cameras, ExtremityParams(feet=False,
                                                                        reacquire=True))
        self.ik = IKProposer(model)
        names = list(model.joint_names)
        #: per side, (shoulder, elbow, wrist) joint indices: the arm's reach
        self._arms = np.array([[names.index(f"{s}_{n}") for n in ("shoulder", "elbow", "wrist")]
                               for s in "lr"])

    def reset(self) -> None:
        self.ik.reset()

    def detect(self, fitness, rest, masks, detector_maps, reference: np.ndarray,
               particles: np.ndarray, rng: np.random.Generator) -> Extremities:
        """Sec. 2.5.1 around the predicted pose ``reference``, then IK particles for the
        detected hands (``particles`` changed in place)."""
        maps = list(detector_maps)
        if len(maps) != len(self.cameras):
            log.error("expected %d detector maps, got %d: none used", len(self.cameras), len(maps))
            maps = [None] * len(self.cameras)
        _, joints = fitness.pose(reference[None], rest)
        targets = self.ik.end_effectors(reference[None], rest)[0]
        ok_masks = [m if m is not None and np.shape(m) == (c.height, c.width) else None
                    for m, c in zip(masks, self.cameras)]
        j = np.asarray(joints[0])
        chain = np.concatenate([j[self._arms], targets[:2, None]], axis=1)  # (2, 4, 3)
        shoulders = chain[:, 0]
        reach = np.linalg.norm(np.diff(chain, axis=1), axis=2).sum(axis=1) + 0.05
        extremities = self.detector.detect(ok_masks, maps, j, targets, shoulders=shoulders,
                                           reach=reach)
        self.ik.apply(particles, extremities.assigned, reference, rest, rng)
        return extremities

    def refinement(self, extremities: Extremities | None, kappa: float, rest):
        """``(kappa, cost_fn)`` of the refinement layer (eq. 2.21) when a hand was
        detected, else None."""
        if extremities is None or len(extremities.detections) == 0 or kappa <= 0:
            return None
        return kappa, lambda particles: detection_cost(extremities.assigned,
                                                       self.ik.end_effectors(particles, rest))

    def learn(self, res, extremities: Extremities | None, rest) -> None:
        """After the filter: adapt the IK particles' share to how well they did."""
        if extremities is not None:
            self.ik.update_fraction(res.weighted_particles, res.weights, extremities.assigned,
                                    rest)
