"""Scores of every person with ground truth against the tracked bodies (``hmocap eval mocap``).

In each frame set the people with truth are matched to the bodies with a pose by the Hungarian
method on the mean joint distance, a pair farther apart than
:data:`~hmocap_ros.eval.metrics.MATCH_GATE_MM` left unmatched
(:func:`~hmocap_ros.eval.metrics.match_people`). Per person: the error figures of
:func:`~hmocap_ros.eval.metrics.summarize_errors` over the frame sets where the person has
truth (a frame set without a matched body counts as one without a pose), the mean over the 12
limb joints and over the wrists, the frame sets where the person is seen (by at least
:data:`MIN_VIEWS` cameras when the bag's silhouettes tell, else wherever the person has truth)
and how many of those the person is matched in, and the id switches (the body matched to the
person changes, counted against the last matched one).

:func:`score_tracks` scores the tracked bodies of a bag's frame sets, whoever tracked them (the
evaluation's own trackers, or the bodies of a bag that ``hmocap track`` wrote): the subject on
the body nearest it in each frame set (:func:`nearest_bodies`), and every person as above.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hmocap_ros.eval.metrics import (
    LIMB_JOINTS,
    MATCH_GATE_MM,
    id_switches,
    joint_errors,
    joints_mean_mm,
    match_people,
    summarize_errors,
)

if TYPE_CHECKING:
    from hmocap_ros.eval.mocap_frames import BagFrames

__all__ = ["MIN_VIEWS", "TrackScores", "match_frames", "nearest_bodies", "score_people",
           "score_tracks"]

#: a person counts as seen in a frame set when at least this many cameras see them
MIN_VIEWS = 2


def match_frames(truth: np.ndarray, estimates: np.ndarray,
                 gate_mm: float = MATCH_GATE_MM) -> np.ndarray:
    """(P, F) the body matched to each person in each frame set (index into the bodies, -1 for
    none): ``truth`` (P, F, J, 3), ``estimates`` (F, T, J, 3), NaN where absent."""
    truth = np.asarray(truth, dtype=np.float64)
    estimates = np.asarray(estimates, dtype=np.float64)
    matched = np.full(truth.shape[:2], -1, dtype=np.intp)
    for k in range(truth.shape[1]):
        matched[:, k] = match_people(truth[:, k], estimates[k], gate_mm)
    return matched


def score_people(truth: np.ndarray, estimates: np.ndarray, joint_names: Sequence[str], *,
                 person_ids: Sequence[str], body_ids: Sequence[str],
                 views: np.ndarray | None = None, gate_mm: float = MATCH_GATE_MM) -> list[dict]:
    """One report entry per person (module docstring).

    truth: (P, F, J, 3) metres, NaN where a person has no truth; estimates: (F, T, J, 3) the
    tracked bodies' joints (the same J joints, ``joint_names``), NaN where a body has no pose;
    person_ids / body_ids: names of the P persons and the T bodies; views: (P, F) cameras that
    see each person, or None.
    """
    truth = np.asarray(truth, dtype=np.float64)
    estimates = np.asarray(estimates, dtype=np.float64)
    matched = match_frames(truth, estimates, gate_mm)
    out = []
    for p, person_id in enumerate(person_ids):
        present = np.isfinite(truth[p]).all(axis=(1, 2))
        rows = np.flatnonzero(matched[p] >= 0)
        mine = np.full(truth.shape[1:], np.nan)
        mine[rows] = estimates[rows, matched[p, rows]]
        summary = summarize_errors(joint_errors(mine[present], truth[p][present]), joint_names)
        seen = present & (views[p] >= MIN_VIEWS) if views is not None else present
        tracked = seen & (matched[p] >= 0)
        ids, counts = np.unique(matched[p, rows], return_counts=True)
        out.append({
            "person_id": str(person_id),
            **summary,
            "limb_joints_mm": joints_mean_mm(summary["per_joint"], LIMB_JOINTS),
            "wrists_mm": joints_mean_mm(summary["per_joint"], ("l_wrist", "r_wrist")),
            "seen_by": f">= {MIN_VIEWS} cameras" if views is not None else "truth",
            "frames_seen": int(seen.sum()),
            "frames_tracked": int(tracked.sum()),
            "tracked_share": float(tracked.sum() / seen.sum()) if seen.any() else float("nan"),
            "id_switches": id_switches(matched[p][present]),
            "body_frames": {str(body_ids[i]): int(c) for i, c in zip(ids, counts)},
        })
    return out


def nearest_bodies(roots: np.ndarray, truth_roots: np.ndarray) -> np.ndarray:
    """(F,) the body that follows the subject in each frame set: of the bodies with a pose, the
    one whose root joint stands nearest the subject's true root on the floor (x, z), as
    multi-person benchmarks match estimates to people; the first body with a pose where the
    subject has no truth; -1 where no body has a pose.

    roots: (F, T, 3) the bodies' root joints, NaN for a body without a pose; truth_roots:
    (F, 3) the subject's, NaN where it has no truth.
    """
    roots = np.asarray(roots, dtype=np.float64)
    truth_roots = np.asarray(truth_roots, dtype=np.float64)
    posed = np.isfinite(roots).all(axis=-1)  # (F, T)
    if not roots.shape[1]:
        return np.full(len(roots), -1, dtype=np.intp)
    gaps = np.linalg.norm((roots - truth_roots[:, None])[..., [0, 2]], axis=-1)
    gaps = np.where(posed, np.nan_to_num(gaps, nan=0.0), np.inf)
    out = np.argmin(gaps, axis=1)  # ties (no truth: all 0) go to the first posed body
    out[~posed.any(axis=1)] = -1
    return out


@dataclass
class TrackScores:
    """Scores of tracked bodies on a bag (:func:`score_tracks`).

    summary: the subject's figures (:func:`~hmocap_ros.eval.metrics.summarize_errors`) on the
    body nearest it, with ``track_switches`` (changes of that body between frame sets with
    truth); persons: :func:`score_people`'s entries; subject_bodies: (F,) the subject's body per
    frame set (-1: none with a pose); subject_body: the body that followed it most often.
    """

    summary: dict
    persons: list
    subject_bodies: np.ndarray
    subject_body: int


def score_tracks(frames: BagFrames, bodies: np.ndarray, joint_names: Sequence[str],
                 true_idx: np.ndarray, body_ids: Sequence[str]) -> TrackScores:
    """Score the tracked ``bodies`` (F, T, J, 3) of ``frames``' frame sets (NaN for a body
    without a pose; joint ``j`` is the truth's joint ``true_idx[j]``, named ``joint_names[j]``,
    the first one the root) against the truth: the subject on its nearest body
    (:func:`nearest_bodies`), every person as :func:`score_people` does (the subject alone
    where the frames hold no other person's truth)."""
    bodies = np.asarray(bodies, dtype=np.float64)
    truth = frames.truth[:, true_idx]
    slots = nearest_bodies(bodies[:, :, 0], truth[:, 0])
    estimates = np.full(truth.shape, np.nan)
    posed = slots >= 0
    estimates[posed] = bodies[np.flatnonzero(posed), slots[posed]]
    has_truth = frames.has_truth
    summary = summarize_errors(joint_errors(estimates[has_truth], truth[has_truth]), joint_names)
    tracks = slots[has_truth & posed]
    summary["track_switches"] = int(np.count_nonzero(np.diff(tracks)))
    if frames.people_truth is None:
        persons = score_people(truth[None], bodies, joint_names,
                               person_ids=frames.person_ids[:1] or ("body_0",), body_ids=body_ids)
    else:
        persons = score_people(frames.people_truth[:, :, true_idx], bodies, joint_names,
                               person_ids=frames.person_ids, body_ids=body_ids,
                               views=frames.people_views)
    return TrackScores(summary=summary, persons=persons, subject_bodies=slots,
                       subject_body=int(np.bincount(tracks).argmax()) if len(tracks) else 0)
