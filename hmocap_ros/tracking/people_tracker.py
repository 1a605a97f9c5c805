"""Several people in one room: one :class:`~.body_tracker.BodyTracker` per person.

A smart room often holds more than its user. :class:`PeopleTracker` runs up to
``max_people`` trackers on the same frame sets, each following a person of its own:

- with keypoints that tell people apart (the keypoint stage with ``max_people`` > 1:
  :attr:`~hmocap_ros.detection.detections.Detections.persons`), each slot takes the keypoints
  of its own body id, and the people no body follows yet go, best agreeing first, to the slots
  that follow nobody; a slot that loses its person forgets its shape (its next start may be
  anyone); each slot is fitted to the foreground without the other bodies that stand in front
  of it (:mod:`.other_bodies`);
- otherwise slot 0 is exactly a single tracker (the same random draws, so with
  ``max_people = 1`` or nobody else in the room its output is bit for bit the same) and takes
  labelled keypoints; unlabelled skin candidates go to every slot;
- every other slot starts only on a person standing farther than
  :data:`~.startup.SAME_PERSON_RADIUS` (on the floor) from the people the other slots
  follow (``exclude``), so two slots never start on the same person;
- if two slots nevertheless end up on one person (a track that lost its person and drifted
  onto another), the one with the worse fit (higher ``fit_cost``) is reset and searches again;
- each slot draws from its own generator (slot 0 from the one passed in, the others spawned
  from it), so runs repeat bit for bit.

Each track has a body id (``body_ids``, one per slot). The cost grows with the number of
people followed (one filter run each); a slot that follows nobody only carves the coarse
visual hull of the frame to look for a new person.
"""
from __future__ import annotations

import re
from typing import Sequence

import numpy as np

from hmocap_ros.body.anthropometry import BodyShape
from hmocap_ros.detection.detections import Detections
from hmocap_ros.detection.detectors import carries_labels
from hmocap_ros.geometry.pinhole_camera import PinholeCamera
from hmocap_ros.geometry.rig import Rig
from hmocap_ros.tracking.body_tracker import BodyTracker
from hmocap_ros.tracking.other_bodies import masks_without_others, render_bodies
from hmocap_ros.tracking.params import TrackerParams
from hmocap_ros.tracking.result import TrackerState, TrackResult
from hmocap_ros.tracking.startup import SAME_PERSON_RADIUS

__all__ = ["DEFAULT_BODY_ID", "PeopleTracker", "body_ids"]

#: The first body's id: REP-155 names its frame ``body_<id>`` (``body_b0``) and its topics
#: ``humans/bodies/<id>/...``; a ROS name token cannot start with a digit, hence the letter.
DEFAULT_BODY_ID = "b0"


def body_ids(first: str, n: int) -> tuple[str, ...]:
    """Ids of ``n`` slots: ``first``, then numbered on from its trailing number (``b0`` -> ``b1``,
    ``body_0`` -> ``body_1``), or with ``_1``, ``_2``... appended when it has none."""
    match = re.fullmatch(r"(.*?)(\d+)", first)
    if match is None:
        return (first,) + tuple(f"{first}_{k}" for k in range(1, n))
    stem, number = match.group(1), int(match.group(2))
    return (first,) + tuple(f"{stem}{number + k}" for k in range(1, n))


class PeopleTracker:
    """Up to ``max_people`` body trackers on one rig (see the module docstring).

    model, rig, params, shape: as :class:`BodyTracker` (``shape`` is given to slot 0 only: a
    known shape is that of the room's user). rng: slot 0's generator; the other slots' are
    spawned from it. ids: the body id of each slot (default ``body_0``, ``body_1``, ...).
    """

    def __init__(self, model, rig: Rig | Sequence[PinholeCamera], params: TrackerParams | None = None,
                 rng: np.random.Generator | None = None, shape: BodyShape | None = None,
                 max_people: int = 1, ids: Sequence[str] | None = None):
        if max_people < 1:
            raise ValueError("max_people must be >= 1")
        rng = rng if rng is not None else np.random.default_rng()
        rngs = [rng] + list(rng.spawn(max_people - 1))
        self.trackers = tuple(BodyTracker(model, rig, params, g, shape=shape if k == 0 else None)
                              for k, g in enumerate(rngs))
        self.ids = tuple(ids) if ids is not None else body_ids(DEFAULT_BODY_ID, max_people)
        if len(self.ids) != max_people or len(set(self.ids)) != max_people:
            raise ValueError(f"need {max_people} distinct body ids, got {self.ids}")

    @property
    def max_people(self) -> int:
        return len(self.trackers)

    def warm_up(self) -> float:
        """Compile the weighting kernels (once: the slots share them); seconds taken."""
        return self.trackers[0].warm_up()

    def reset(self, forget_shape: bool = True) -> None:
        for tracker in self.trackers:
            tracker.reset(forget_shape)

    def saw(self, stamps_ns: Sequence[int]) -> None:
        """Frame sets that came but are not processed (skipped to keep up): their stamps
        still measure the frame period of every slot (:meth:`BodyTracker.saw`)."""
        for stamp in stamps_ns:
            for tracker in self.trackers:
                tracker.saw(stamp)

    def update(self, masks: Sequence[np.ndarray | None], stamp_ns: int,
               detections: Detections | None = None,
               budget_s: float | None = None) -> list[TrackResult]:
        """One frame set through every slot, in slot order; one result per slot.

        detections: the frame set's 3D detections. Unlabelled skin candidates go to every
        slot (each assigns them to its own body, eq. 2.19). Labelled joints that tell people
        apart (:attr:`~hmocap_ros.detection.detections.Detections.persons`) go by body id:
        a slot takes the person its body's crops found, and the people no body follows yet
        go, best agreeing first, to the slots that follow nobody (:meth:`_people_per_slot`);
        labelled joints of one person are the first slot's. budget_s: seconds each slot may
        take (:meth:`BodyTracker.update`)."""
        per_slot = self._people_per_slot(detections)
        rendered = None
        if per_slot is not None and sum(t.position is not None for t in self.trackers) > 0:
            bodies: list[tuple[np.ndarray, np.ndarray] | None] = []
            for t in self.trackers:
                mesh, pelvis = t.mesh(), t.position
                bodies.append(None if mesh is None or pelvis is None else (mesh, pelvis))
            rendered = render_bodies(self.trackers[0].cameras, masks, bodies,
                                     self.trackers[0].model.faces)
        results = []
        for k, tracker in enumerate(self.trackers):
            positions = [t.position for j, t in enumerate(self.trackers) if j != k]
            others = np.array([p for p in positions if p is not None]).reshape(-1, 3)
            if per_slot is not None:
                mine = per_slot[k]
            else:
                mine = detections if (k == 0 or detections is None
                                      or not carries_labels(detections)) else None
            mine_masks = list(masks) if rendered is None else masks_without_others(masks, rendered, k)
            results.append(tracker.update(mine_masks, stamp_ns, mine,
                                          exclude=others if len(others) else None,
                                          budget_s=budget_s))
        self._drop_duplicates(results)
        if per_slot is not None:
            # the next start of a slot that lost its person may be anyone: not their shape
            for tracker in self.trackers:
                if tracker.state == TrackerState.LOST:
                    tracker.reset(forget_shape=True)
        return results

    def _people_per_slot(self, detections: Detections | None) -> list | None:
        """Per slot, its detections when they tell people apart (None otherwise): the person
        whose ``person_ids`` entry is the slot's body id, else, for a slot that follows
        nobody, the next person no body follows (``""``), else none (an empty set: the slot's
        body was not found in this frame set)."""
        if detections is None or detections.persons is None:
            return None
        ids = list(detections.person_ids)
        new = [k for k, body in enumerate(ids) if body == ""]
        out = []
        for slot, tracker in zip(self.ids, self.trackers):
            if slot in ids:
                out.append(detections.person(ids.index(slot)))
            elif tracker.position is None and new:
                out.append(detections.person(new.pop(0)))
            else:
                out.append(Detections.empty(detections.detector))
        return out

    def _drop_duplicates(self, results: list[TrackResult]) -> None:
        """Two slots on one person: reset the worse fit (its result keeps this frame's pose)."""
        for a in range(len(self.trackers)):
            for b in range(a + 1, len(self.trackers)):
                pa, pb = self.trackers[a].position, self.trackers[b].position
                if pa is None or pb is None:
                    continue
                if np.linalg.norm((pa - pb)[[0, 2]]) > SAME_PERSON_RADIUS:
                    continue
                ca, cb = (r.fit_cost if np.isfinite(r.fit_cost) else np.inf
                          for r in (results[a], results[b]))
                worse = a if ca > cb else b
                self.trackers[worse].reset(forget_shape=True)
