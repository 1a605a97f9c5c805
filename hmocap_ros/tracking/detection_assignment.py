"""The tracker's side of detector-driven propagation: detections assigned to its body (sec. 2.5).

An extremity detector (:mod:`hmocap_ros.detection`) publishes 3D detections of one frame set;
the tracker decides which of its end-effectors each one is:

* **Skin candidates** (unlabelled surface clusters) are classified by eq. 2.19 against the
  tracker's own predicted pose: repeatedly the closest (end-effector, candidate) pair within the
  maximum distances ``Upsilon`` (35 cm hands, 25 cm head), the thesis' greedy solution.
* **Re-acquisition** (beyond the thesis): a hand eq. 2.19 leaves unassigned (the tracked arm is
  lost, farther than Upsilon from its hand) takes the closest remaining candidate within arm's
  reach of its shoulder (the reference pose's arm length + 5 cm) that is not near the predicted
  head (30 cm) and lies nearer its own shoulder than the other shoulder (so that the other hand
  is not taken), so that IK particles can draw a lost arm back.
* **Labelled detections** (a keypoint detector says which hand it saw) are taken by label.

:func:`detection_cost` is eq. 2.20: the mean distance of the detections to the nearest model
end-effector, the cost the refinement layer adds (eq. 2.21).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hmocap_ros.detection.greedy_assignment import greedy_pairs

__all__ = ["END_EFFECTORS", "EFFECTOR_LABELS", "MAX_DISTANCE", "HEAD_EXCLUSION", "Assigned",
           "detection_cost", "reacquire_hands"]

#: End-effectors the detections are assigned to (thesis: hands and head; feet from keypoints).
END_EFFECTORS = ("l_hand", "r_hand", "head", "l_foot", "r_foot")
#: the detection label of each end-effector (hmocap_interfaces/Extremities labels)
EFFECTOR_LABELS = ("left_hand", "right_hand", "head", "left_foot", "right_foot")
#: [Upsilon] eq. 2.19, per END_EFFECTORS (m)
MAX_DISTANCE = (0.35, 0.35, 0.25, 0.35, 0.35)
#: m, re-acquisition ignores candidates this near the predicted head
HEAD_EXCLUSION = 0.30
#: the end-effectors a detection of each kind may be explained by (eq. 2.20's "nearest")
_UPPER, _FEET = (0, 1, 2), (3, 4)


@dataclass(frozen=True, eq=False)
class Assigned:
    """One frame set's detections as the tracker uses them.

    candidates: (E, 3) the detections considered; assigned: (5, 3) per :data:`END_EFFECTORS`
    the detection assigned to it (NaN rows: none); joints: (J, 3) labelled detections of the
    body model's joints by joint index (NaN rows: none), with joint_scores (J,) in [0, 1].
    """

    candidates: np.ndarray
    assigned: np.ndarray
    joints: np.ndarray | None = None
    joint_scores: np.ndarray | None = None

    @property
    def found(self) -> np.ndarray:
        """(5,) bool: which end-effectors got a detection."""
        return np.isfinite(self.assigned).all(axis=1)

    @property
    def detections(self) -> np.ndarray:
        """(U, 3) the set C_t of eq. 2.20: the assigned hands and feet (not the head, see
        ``ik_proposals``)."""
        use = self.found.copy()
        use[2] = False
        return self.assigned[use]


def detection_cost(assigned: np.ndarray, effectors: np.ndarray) -> np.ndarray:
    """Eq. 2.20 for a batch of poses: (N,) mean over the detections C_t of the distance to the
    nearest model end-effector.

    assigned: (5, 3) detections per :data:`END_EFFECTORS` (NaN: none; the head is left out, see
    ``ik_proposals``); effectors: (N, 5, 3) the poses' end-effectors. "Nearest" ranges over the
    end-effectors of the detection's own kind (hands with hands and head, feet with feet), so a
    hand seen where a wrong particle has a foot is not explained by it.
    """
    cost = np.zeros(effectors.shape[0])
    count = 0
    for kind in (_UPPER, _FEET):
        rows = [i for i in kind if i != 2 and np.isfinite(assigned[i]).all()]
        if not rows:
            continue
        d = np.linalg.norm(assigned[rows][None, :, None] - effectors[:, None, list(kind)], axis=3)
        cost += d.min(axis=2).sum(axis=1)
        count += len(rows)
    return cost / max(count, 1)


def reacquire_hands(candidates: np.ndarray, assigned: np.ndarray, shoulders: np.ndarray,
                    reach: np.ndarray, head: np.ndarray, head_exclusion: float) -> np.ndarray:
    """Second pass for hands eq. 2.19 left unassigned: (2, 3) hands (module docstring).

    assigned: (3, 3) left hand, right hand, head after eq. 2.19 (NaN: none). Candidates
    already used, within ``head_exclusion`` of the predicted ``head``, or not nearer the hand's
    own shoulder than the other one, are not taken; the closest (candidate, shoulder) pair
    within that arm's ``reach`` goes first.
    """
    hands = np.array(assigned[:2], dtype=np.float64)
    if len(candidates) == 0 or np.isfinite(hands).all():
        return hands
    used = np.zeros(len(candidates), bool)
    for row in assigned:
        if np.isfinite(row).all():
            used |= np.all(np.isclose(candidates, row), axis=1)
    if np.isfinite(head).all():
        used |= np.linalg.norm(candidates - head, axis=1) <= head_exclusion
    d = np.linalg.norm(shoulders[:, None] - candidates[None], axis=2)  # (2, E)
    d[d >= d[::-1]] = np.inf  # each hand keeps to its own side
    d[:, used] = np.inf
    d[d > np.asarray(reach, dtype=np.float64)[:, None]] = np.inf
    d[np.isfinite(hands).all(axis=1)] = np.inf
    for i, e in greedy_pairs(d):
        hands[i] = candidates[e]
    return hands
