"""What the body tracker reports: its state machine's states and one frame set's result."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from hmocap_ros.body.anthropometry import BodyShape
from hmocap_ros.tracking.body_frames import joint_confidence
from hmocap_ros.tracking.detection_assignment import Assigned

__all__ = ["STATES", "TrackResult", "TrackerState", "stage_timings"]


class TrackerState(StrEnum):
    """States of :class:`~hmocap_ros.tracking.body_tracker.BodyTracker` (values are what
    diagnostics and reports show)."""

    #: no person: too little foreground in too few views, or no visual hull; no pose
    SEARCHING = "searching"
    #: a person appeared: visual hull, pose and anthropometry estimation (sec. 2.3)
    INITIALISING = "initialising"
    #: layered particle filtering per frame (sec. 2.4-2.5)
    TRACKING = "tracking"
    #: the fit stayed bad for ``lost.frames`` frames; the next frame starts from the hull
    LOST = "lost"

    @property
    def follows_person(self) -> bool:
        return self in (TrackerState.INITIALISING, TrackerState.TRACKING)

    @property
    def looking(self) -> bool:
        return self in (TrackerState.SEARCHING, TrackerState.LOST)


STATES = tuple(s.value for s in TrackerState)


@dataclass(frozen=True, eq=False)
class TrackResult:
    """What one ``update`` produced.

    state: the :class:`TrackerState` after this frame.
    params: (D,) pose parameters (tracking DoF set) or None; joints: (J, 3) joint positions in
    metres in the room frame or None; joint_names: their names; shape: the body shape used.
    transforms: (J, 4, 4) the joints' global transforms (rotation: joint frame in the body
    model's axes -> room; translation: ``joints``), or None without pose; the tf2 frames of
    :mod:`.body_frames` are made from them.
    joint_spread: (J,) metres, per joint the weighted RMS distance of its position over the
    final layer's particles (:func:`.body_frames.joint_spread`); None where no filter ran
    (start-up frames, no pose).
    fit_cost: eq. 2.8 cost of the estimate divided by the number of views (NaN without pose).
    views: rig indices used; dropped: rig indices whose mask was missing or invalid.
    layers: per-layer diagnostics (ESS, beta, times) of the filter run, if one ran.
    timings: seconds per stage ("total", "observe", "hull", "init", "filter", "skinning",
    "projection", "xor", "detection", "proposals", "research") and "evaluations".
    extremities: dd-hpf's hand and head detections of this frame (None otherwise).
    """

    stamp_ns: int
    state: TrackerState
    params: np.ndarray | None = None
    joints: np.ndarray | None = None
    joint_names: tuple = ()
    shape: BodyShape | None = None
    fit_cost: float = float("nan")
    views: tuple = ()
    dropped: tuple = ()
    layers: tuple = ()
    timings: dict = field(default_factory=dict)
    extremities: Assigned | None = None
    transforms: np.ndarray | None = None
    joint_spread: np.ndarray | None = None

    @property
    def has_pose(self) -> bool:
        return self.joints is not None

    @property
    def confidence(self) -> np.ndarray | None:
        """(J,) per-joint confidence in [0, 1] (:func:`.body_frames.joint_confidence`: the
        spread, raised where a labelled detection agrees), or None when the spread is unknown."""
        if self.joint_spread is None or self.joints is None:
            return None
        ext = self.extremities
        detected = ext.joints if ext is not None else None
        scores = ext.joint_scores if ext is not None else None
        return joint_confidence(self.joint_spread, self.joints, detected, scores)

    @property
    def ess(self) -> tuple:
        return tuple(d.ess for d in self.layers)


def stage_timings(timings: dict, t_start: float, times, extra=None) -> dict:
    """A frame's ``TrackResult.timings``: the tracker's own stages, the weighting's stages
    (``times``: the fitness' stage times, ``extra``: the start-up fitness', or None), the
    evaluations and the total since ``t_start`` (``time.perf_counter``)."""
    out = dict(timings)
    out["skinning"] = times.skinning + (extra.skinning if extra else 0.0)
    out["projection"] = times.projection + (extra.projection if extra else 0.0)
    out["xor"] = times.xor + (extra.xor if extra else 0.0)
    out["evaluations"] = times.evaluations + (extra.evaluations if extra else 0)
    out["total"] = time.perf_counter() - t_start
    return out
