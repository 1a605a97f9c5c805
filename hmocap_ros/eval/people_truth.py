"""The ground truth of several people in a bag: whose topics, whose joints, seen by which views.

A bag's ground truth (:mod:`hmocap_ros.io.topics`) describes the subject, person 0, with body
id ``body_0``; each further person ``k`` has the same topics under ``/ground_truth/body_<k>/``
(:func:`person_topic`; ``hmocap sim mocap --people N`` writes them). :func:`read_people` reads
every person's skeletons; :class:`PersonViews` counts, per frame set, the cameras that see each
person: a camera sees a person when at least half of their limb joints
(:data:`~hmocap_ros.eval.metrics.LIMB_JOINTS`; all joints if the skeleton has none of them)
project onto that person's own ground-truth silhouette in its image, so a person hidden behind
another, or outside the image, is not seen.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["GT_PREFIX", "PeopleTruth", "PersonViews", "person_body_id", "person_topic",
           "read_people"]

#: the prefix of the ground-truth topics; person k >= 1's are under ``GT_PREFIX body_<k>/``
GT_PREFIX = "/ground_truth/"


def person_body_id(person: int) -> str:
    """The body id of person ``person`` in the ground truth: ``body_<person>``."""
    return f"body_{int(person)}"


def person_topic(topic: str, person: int) -> str:
    """A ground-truth topic of :mod:`hmocap_ros.io.topics` for person ``person``: the topic
    itself for the subject (0), the same topic under ``/ground_truth/body_<person>/`` for the
    others (``/ground_truth/skeleton`` -> ``/ground_truth/body_1/skeleton``,
    ``/ground_truth/cam_1/silhouette`` -> ``/ground_truth/body_1/cam_1/silhouette``)."""
    if not topic.startswith(GT_PREFIX):
        raise ValueError(f"{topic} is not a ground-truth topic")
    if person == 0:
        return topic
    return f"{GT_PREFIX}{person_body_id(person)}/{topic[len(GT_PREFIX):]}"


@dataclass(frozen=True)
class PeopleTruth:
    """Every person's ground-truth skeletons: ``ids`` (the messages' body ids, the subject
    first), ``by_stamp`` (per person, stamp -> (J, 3) metres) and the joint names."""

    ids: tuple
    by_stamp: tuple
    joint_names: tuple

    def row(self, stamp: int) -> np.ndarray:
        """(P, J, 3) joints of every person at ``stamp``, NaN for a person without truth."""
        blank = np.full((len(self.joint_names), 3), np.nan)
        return np.stack([people.get(stamp, blank) for people in self.by_stamp])


def read_people(reader, available) -> PeopleTruth:
    """The skeletons of person 0, 1, ... as long as the bag has their skeleton topic (person 0:
    ``/ground_truth/skeleton``, which the bag must have); joints matched by name to the
    subject's."""
    from hmocap_ros.eval.metrics import match_joints
    from hmocap_ros.io import topics
    from hmocap_ros.io.msg_factory import stamp_to_ns

    ids, by_stamp = [], []
    names: tuple = ()
    person = 0
    while person_topic(topics.GT_SKELETON, person) in available:
        body_id, joints = person_body_id(person), {}
        for item in reader.messages([person_topic(topics.GT_SKELETON, person)]):
            msg = item.msg
            msg_names = tuple(str(n) for n in msg.joint_names)
            names = names or msg_names
            points = np.array([[p.x, p.y, p.z] for p in msg.positions], dtype=np.float64)
            mine, theirs = match_joints(names, msg_names)
            row = np.full((len(names), 3), np.nan)
            row[mine] = points[theirs]
            joints[stamp_to_ns(msg.header.stamp)] = row
            body_id = str(msg.body_id) or body_id
        ids.append(body_id)
        by_stamp.append(joints)
        person += 1
    return PeopleTruth(tuple(ids), tuple(by_stamp), names)


class PersonViews:
    """The cameras that see each person in a frame set (module docstring).

    rig: the bag's cameras; joint_names: the truth's joints; n_people: persons in the truth;
    available: the bag's topics. ``topics`` lists the silhouette topics to read;
    :attr:`known` is False when the bag lacks some person's silhouettes in every view.
    """

    def __init__(self, rig, joint_names: Sequence[str], n_people: int, available):
        from hmocap_ros.eval.metrics import LIMB_JOINTS
        from hmocap_ros.io import topics

        self.rig = rig
        names = list(joint_names)
        limbs = [names.index(j) for j in LIMB_JOINTS if j in names]
        self.joints = np.asarray(limbs if limbs else range(len(names)), dtype=np.intp)
        self.silhouettes = [[person_topic(topics.gt_silhouette(cam), p) for cam in rig.names]
                            for p in range(n_people)]
        self.known = all(any(t in available for t in row) for row in self.silhouettes)
        self.topics = [t for row in self.silhouettes for t in row if t in available]

    def count(self, truth: np.ndarray, msgs: dict) -> np.ndarray:
        """(P,) number of cameras that see each person of ``truth`` (P, J, 3) in a frame set
        whose messages by topic are ``msgs``; 0 for a person without truth."""
        from hmocap_ros.geometry import project_points
        from hmocap_ros.io.image_codec import decoded_image

        out = np.zeros(len(truth), dtype=np.int64)
        for p, joints in enumerate(truth):
            points = joints[self.joints]
            if not np.isfinite(points).all():
                continue
            proj = project_points(self.rig.cameras, points)
            for k, topic in enumerate(self.silhouettes[p]):
                msg = msgs.get(topic)
                if msg is None:
                    continue
                mask = decoded_image(msg)
                mask = mask[..., 0] if mask.ndim == 3 else mask
                h, w = mask.shape[:2]
                uv = np.rint(proj.pixels[k]).astype(np.int64)
                inside = (proj.visible[k] & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0)
                          & (uv[:, 1] < h))
                on = mask[uv[inside, 1], uv[inside, 0]] > 0
                out[p] += int(2 * np.count_nonzero(on) >= len(points))
        return out
