"""Pose-error metrics (vectorised): 3D joint errors and their summaries (thesis tables 2.3, 2.4).

The thesis reports "means (and standard deviations) of the 3D tracking errors (in
millimetres)" per sequence: the error of a frame is the mean Euclidean distance over the joints
(MPJPE), and the table gives the mean and the standard deviation of that per-frame error over
the sequence. Frames without an estimate are NaN rows and are left out of the statistics
(their number is reported separately).

Several people: in each frame the people with truth are matched to the tracked bodies by the
Hungarian method (:func:`match_people`, Kuhn 1955, via ``scipy.optimize.linear_sum_assignment``)
on the mean joint distance, with a gate; :func:`id_switches` counts the changes of a person's
matched body (the identity switches of the CLEAR MOT metrics, Bernardin and Stiefelhagen 2008).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["LIMB_JOINTS", "MATCH_GATE_MM", "id_switches", "joint_errors", "joints_mean_mm",
           "match_joints", "match_people", "mpjpe", "summarize_errors"]

#: the 12 limb joints: shoulders, elbows, wrists, hips, knees, ankles
LIMB_JOINTS = ("l_shoulder", "r_shoulder", "l_elbow", "r_elbow", "l_wrist", "r_wrist",
               "l_hip", "r_hip", "l_knee", "r_knee", "l_ankle", "r_ankle")

#: (mm) a person and a tracked body farther apart than this (mean joint distance) are no match
MATCH_GATE_MM = 500.0


def match_joints(names: Sequence[str], reference: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(i, j)`` such that ``names[i[k]] == reference[j[k]]`` for the common names,
    in the order of ``names``."""
    ref = {str(n): k for k, n in enumerate(reference)}
    pairs = [(i, ref[str(n)]) for i, n in enumerate(names) if str(n) in ref]
    if not pairs:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    a, b = zip(*pairs)
    return np.asarray(a, dtype=np.intp), np.asarray(b, dtype=np.intp)


def joint_errors(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Euclidean error per frame and joint, in millimetres: (F, J) from (F, J, 3) in metres.

    NaN estimates (frames without a pose) give NaN errors.
    """
    est = np.asarray(estimate, dtype=np.float64)
    true = np.asarray(truth, dtype=np.float64)
    if est.shape != true.shape or est.shape[-1] != 3:
        raise ValueError(f"estimate {est.shape} and truth {true.shape} must both be (..., J, 3)")
    return 1000.0 * np.linalg.norm(est - true, axis=-1)


def mpjpe(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Mean per-joint position error of each frame (mm), (F,); NaN for frames without pose."""
    return joint_errors(estimate, truth).mean(axis=-1)


def summarize_errors(errors: np.ndarray, joint_names: Sequence[str] | None = None) -> dict:
    """Statistics of per-frame, per-joint errors (F, J) in mm (NaN rows: no estimate).

    Returns ``mean_mm`` and ``std_mm`` of the per-frame MPJPE over the frames with an estimate,
    ``median_mm``, ``per_joint`` ``{name: {"mean_mm", "std_mm"}}`` (over frames),
    ``per_frame_mm`` (list, None where missing), ``frames`` and ``frames_with_pose``.
    """
    e = np.asarray(errors, dtype=np.float64)
    if e.ndim != 2:
        raise ValueError(f"errors must be (frames, joints), got {e.shape}")
    names = list(joint_names) if joint_names is not None else [str(k) for k in range(e.shape[1])]
    valid = np.isfinite(e).all(axis=1)
    per_frame = e.mean(axis=1)
    ok = e[valid]
    out = {
        "frames": int(e.shape[0]),
        "frames_with_pose": int(valid.sum()),
        "mean_mm": float(per_frame[valid].mean()) if valid.any() else float("nan"),
        "std_mm": float(per_frame[valid].std()) if valid.any() else float("nan"),
        "median_mm": float(np.median(per_frame[valid])) if valid.any() else float("nan"),
        "per_joint": {
            n: {"mean_mm": float(ok[:, k].mean()) if len(ok) else float("nan"),
                "std_mm": float(ok[:, k].std()) if len(ok) else float("nan")}
            for k, n in enumerate(names)
        },
        "per_frame_mm": [float(v) if np.isfinite(v) else None for v in per_frame],
    }
    return out


def joints_mean_mm(per_joint: dict, joints: Sequence[str] = LIMB_JOINTS) -> float:
    """Mean of ``per_joint[name]["mean_mm"]`` (:func:`summarize_errors`) over ``joints``; NaN
    unless every one of them has a finite mean."""
    values = [per_joint[j]["mean_mm"] for j in joints if j in per_joint]
    if len(values) != len(joints) or not all(v is not None and np.isfinite(v) for v in values):
        return float("nan")
    return float(np.mean(values))


def match_people(truth: np.ndarray, estimates: np.ndarray,
                 gate_mm: float = MATCH_GATE_MM) -> np.ndarray:
    """The tracked body of each person in one frame: ``(P,)`` index into ``estimates``, -1 for
    none.

    truth: (P, J, 3) metres, NaN for a person without truth in the frame; estimates: (T, J, 3),
    NaN for a body without a pose (the same joints in the same order). The assignment
    minimises the summed mean joint distance (Hungarian method); a pair farther apart than
    ``gate_mm`` stays unmatched.
    """
    true = np.asarray(truth, dtype=np.float64)
    est = np.asarray(estimates, dtype=np.float64)
    out = np.full(len(true), -1, dtype=np.intp)
    if not len(true) or not len(est):
        return out
    cost = 1000.0 * np.linalg.norm(true[:, None] - est[None], axis=-1).mean(axis=-1)  # (P, T)
    ok = np.isfinite(cost) & (cost <= gate_mm)
    if not ok.any():
        return out
    from scipy.optimize import linear_sum_assignment

    # pairs outside the gate cost more than any assignment of pairs inside it
    rows, cols = linear_sum_assignment(np.where(ok, cost, 2.0 * gate_mm * (len(true) + 1)))
    keep = ok[rows, cols]
    out[rows[keep]] = cols[keep]
    return out


def id_switches(matched: np.ndarray) -> int:
    """Changes of the matched body over the frames of one person: ``matched`` (F,) body indices
    in frame order, -1 where unmatched; a change counts against the last matched body, across
    unmatched frames in between."""
    ids = np.asarray(matched)
    ids = ids[ids >= 0]
    return int(np.count_nonzero(np.diff(ids))) if len(ids) > 1 else 0
