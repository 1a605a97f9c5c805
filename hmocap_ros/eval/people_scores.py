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
"""
from __future__ import annotations

from collections.abc import Sequence

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

__all__ = ["MIN_VIEWS", "match_frames", "score_people"]

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
