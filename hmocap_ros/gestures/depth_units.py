"""Is a depth image in the unit it is read with? A check of the median depth of a room camera.

A depth camera in a room sees its scene between a fraction of a metre and a few metres; a median
far outside that says the unit is wrong (raw 1/8 mm values of an SR300/SR305 published as 16UC1
read 8 times too far). ``gesture_detection`` warns once per stream with :func:`implausible_depth`,
and ``hmocap eval gestures`` reports it for a bag.
"""
from __future__ import annotations

import numpy as np

from hmocap_ros.gestures.params import DepthFormat

__all__ = ["PLAUSIBLE_DEPTH_M", "implausible_depth"]

#: Median valid depth (metres) of a depth camera in a room: outside it, the unit is wrong.
PLAUSIBLE_DEPTH_M = (0.2, 8.0)
#: Units offered when the median is implausible: mm (REP 118), 1/8 mm (raw SR300/SR305
#: values), 0.1 mm, metres.
_CANDIDATE_UNITS_M = (0.001, 0.000125, 0.0001, 1.0)


def implausible_depth(depth: np.ndarray, fmt: DepthFormat, step: int = 4) -> str:
    """Why a raw depth image read with ``fmt`` (its ``unit_m``, 0 = REP 118) looks like the wrong
    unit, or "" when it looks right.

    The median of the valid pixels (finite, above zero, not ``invalid_value``; every ``step``-th
    pixel of every ``step``-th row) in metres must lie in :data:`PLAUSIBLE_DEPTH_M`: raw 1/8 mm
    values of an SR300/SR305 read as millimetres come out 8 times too far, metres read as
    millimetres 1000 times too near. An image with valid depth on less than 1 % of its pixels
    says nothing. The text names a unit that would put the median at 0.5 to 5 m when one does.
    """
    raw = np.asarray(depth)
    if raw.ndim != 2 or raw.size == 0:
        return ""
    sample = raw[::step, ::step].astype(np.float64)
    valid = np.isfinite(sample) & (sample > 0)
    if np.isfinite(fmt.invalid_value):
        valid &= sample != fmt.invalid_value
    if valid.sum() < max(1, 0.01 * sample.size):
        return ""
    unit = fmt.unit_for(raw.dtype)
    median_raw = float(np.median(sample[valid]))
    median = median_raw * unit
    low, high = PLAUSIBLE_DEPTH_M
    if low <= median <= high:
        return ""
    better = [u for u in _CANDIDATE_UNITS_M if u != unit and 0.5 <= median_raw * u <= 5.0]
    hint = (f"; depth_unit_m {better[0]:g} would put it at {median_raw * better[0]:.2f} m" if better else "")
    return (f"median valid depth {median:.3g} m ({raw.dtype} read at {unit:g} m per unit) is outside the "
            f"{low:g} to {high:g} m of a depth camera in a room: check depth_unit_m (0 = REP 118: 16UC1 "
            f"in mm, 32FC1 in m; raw SR300/SR305 values are 1/8 mm, 0.000125){hint}")
