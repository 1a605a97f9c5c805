"""Pose-error metrics (vectorised): 3D joint errors and their summaries (thesis tables 2.3, 2.4).

The thesis reports "means (and standard deviations) of the 3D tracking errors (in
millimetres)" per sequence: the error of a frame is the mean Euclidean distance over the joints
(MPJPE), and the table gives the mean and the standard deviation of that per-frame error over
the sequence. Frames without an estimate are NaN rows and are left out of the statistics
(their number is reported separately).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["joint_errors", "match_joints", "mpjpe", "summarize_errors"]


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
