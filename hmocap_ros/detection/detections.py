"""One frame set's 3D detections, as ``extremity_detection`` publishes them (hmocap_interfaces/Extremities).

Labels are the message's: the extremities ``head``, ``left_hand``, ``right_hand``, ``left_foot``,
``right_foot``; the keypoint detector's other joints ``left_shoulder`` ... ``right_ankle``; and
``unknown`` for a skin candidate not assigned to a body part (eq. 2.19 needs a body to assign
to). :data:`MODEL_JOINT` maps the joint labels to the body model's joints;
:func:`detections_from_msg` and :func:`fill_msg` convert to and from the message (rclpy messages
and rosbags dataclasses alike).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["UNKNOWN", "EXTREMITY_LABELS", "JOINT_LABELS", "MODEL_JOINT", "Detections",
           "detections_from_msg", "fill_msg"]

UNKNOWN = "unknown"
EXTREMITY_LABELS = ("head", "left_hand", "right_hand", "left_foot", "right_foot")
#: labelled joints of the keypoint detector -> the body model's joint of the same place
MODEL_JOINT = {f"{side}_{part}": f"{side[0]}_{part}"
               for side in ("left", "right")
               for part in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle")}
JOINT_LABELS = tuple(MODEL_JOINT)


@dataclass(frozen=True, eq=False)
class Detections:
    """Labelled 3D detections of one frame set (room frame, metres).

    detector: the detector that made them (``skin`` or ``keypoints``); labels (D,); positions
    (D, 3); scores (D,) in [0, 1] for keypoints, the summed probability of eq. 2.18 for skin;
    normals (D, 3) mean outward surface normals (NaN where the detector has none); points (P, 3)
    and probability (P,): the oriented surface points with their extremity probability
    (eq. 2.16-2.18; empty for keypoints).
    """

    detector: str
    labels: tuple
    positions: np.ndarray
    scores: np.ndarray
    normals: np.ndarray | None = None
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    probability: np.ndarray = field(default_factory=lambda: np.zeros(0))
    persons: np.ndarray | None = None
    person_ids: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "positions", np.asarray(self.positions, float).reshape(-1, 3))
        object.__setattr__(self, "scores", np.asarray(self.scores, float).reshape(-1))
        if self.normals is None:
            object.__setattr__(self, "normals", np.full(self.positions.shape, np.nan))
        if not (len(self.labels) == len(self.positions) == len(self.scores)
                == len(self.normals)):
            raise ValueError("labels, positions, scores and normals must have one row each")
        if self.persons is not None:
            persons = np.asarray(self.persons, dtype=np.int64).reshape(-1)
            object.__setattr__(self, "persons", persons)
            if len(persons) != len(self.labels) or (
                    len(persons) and (persons.min() < 0 or persons.max() >= len(self.person_ids))):
                raise ValueError("persons must give one index into person_ids per detection")

    def person(self, index: int) -> "Detections":
        """The detections of one person (``persons == index``), without the person split."""
        if self.persons is None:
            raise ValueError("these detections do not tell people apart")
        keep = self.persons == index
        return Detections(self.detector, tuple(np.asarray(self.labels, dtype=object)[keep]),
                          self.positions[keep], self.scores[keep], self.normals[keep]
                          if self.normals is not None else None)

    @staticmethod
    def of_people(detector: str, people: list) -> "Detections":
        """One frame set's detections from ``[(body id, labels, positions, scores)]``, one
        entry per person."""
        labels: list = []
        positions, scores, persons = [np.zeros((0, 3))], [np.zeros(0)], [np.zeros(0, int)]
        for k, (_, person_labels, person_positions, person_scores) in enumerate(people):
            labels.extend(person_labels)
            positions.append(np.asarray(person_positions, float).reshape(-1, 3))
            scores.append(np.asarray(person_scores, float).reshape(-1))
            persons.append(np.full(len(person_labels), k, dtype=int))
        return Detections(detector, tuple(labels), np.concatenate(positions),
                          np.concatenate(scores), persons=np.concatenate(persons),
                          person_ids=tuple(str(p[0]) for p in people))

    def __len__(self) -> int:
        return len(self.labels)

    @staticmethod
    def empty(detector: str) -> "Detections":
        return Detections(detector, (), np.zeros((0, 3)), np.zeros(0))

    def position(self, label: str) -> np.ndarray | None:
        """The (3,) position labelled ``label`` (the best scored), or None."""
        rows = [i for i, lab in enumerate(self.labels) if lab == label]
        if not rows:
            return None
        return self.positions[max(rows, key=lambda i: self.scores[i])]

    def as_dict(self) -> dict:
        """label -> (3,) position (unknown detections left out)."""
        return {lab: self.position(lab) for lab in set(self.labels) if lab != UNKNOWN}


def detections_from_msg(msg) -> Detections:
    """An Extremities message (rclpy or rosbags) as :class:`Detections`; ValueError when its
    arrays disagree in length."""
    positions = np.array([[p.x, p.y, p.z] for p in msg.positions], float).reshape(-1, 3)
    normals = np.array([[n.x, n.y, n.z] for n in msg.normals], float).reshape(-1, 3)
    persons = np.asarray(getattr(msg, "persons", []), dtype=np.int64)
    return Detections(str(msg.detector) or "skin", tuple(str(s) for s in msg.labels), positions,
                      np.asarray(msg.scores, float),
                      normals if len(normals) == len(positions) else None,
                      persons=persons if len(persons) == len(positions) and len(persons) else None,
                      person_ids=tuple(str(s) for s in getattr(msg, "person_ids", [])))


def fill_msg(msg, det: Detections, point_cls, vector_cls):
    """Fill an Extremities message ``msg`` from ``det`` (the header is the caller's)."""
    normals = det.normals
    assert normals is not None  # Detections fills absent normals with NaN
    msg.detector = det.detector
    msg.labels = list(det.labels)
    msg.positions = [point_cls(x=float(x), y=float(y), z=float(z)) for x, y, z in det.positions]
    msg.normals = [vector_cls(x=float(x), y=float(y), z=float(z))
                   for x, y, z in np.nan_to_num(normals)]
    msg.scores = [float(s) for s in det.scores]
    msg.persons = [] if det.persons is None else [int(k) for k in det.persons]
    msg.person_ids = list(det.person_ids) if det.persons is not None else []
    return msg
