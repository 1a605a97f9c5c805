"""Temporal smoothing of the triangulated keypoints: a one-euro filter per label (no rclpy).

The one-euro filter (Casiez, Roussel and Vogel, CHI 2012) is a first-order low-pass filter whose
cutoff rises with the speed, per coordinate: ``x_hat_t = x_hat_{t-1} + a(f_c) (x_t -
x_hat_{t-1})`` with ``a(f) = 1 / (1 + 1 / (2 pi f dt))`` and ``f_c = min_cutoff + beta
|v_hat_t|``, where ``v_hat`` is the raw speed ``(x_t - x_{t-1}) / dt`` low-passed at
``derivative_cutoff`` (MediaPipe's ``OneEuroFilter``). A still joint is
smoothed hard (its jitter goes), a moving one hardly at all (no lag). MediaPipe's pose pipeline
filters its landmarks this way (``LandmarksSmoothingCalculator``, ``one_euro_filter {min_cutoff:
0.05 beta: 80 derivate_cutoff: 1}``, values in units of the body's size): here the keypoints are
filtered in 3D, the speed in body sizes per second (:data:`BODY_SIZE_M`), with the same
settings, each label on its own clock (the frame sets' stamps: a live node skips sets).

A label's filter starts over when it was missing for more than ``max_gap_s`` or its stamp does
not advance.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BODY_SIZE_M", "KeypointSmoother", "SmoothingParams"]

#: Metres of the body-size unit the speed is measured in (MediaPipe normalises by its ROI).
BODY_SIZE_M = 1.7


@dataclass(frozen=True)
class SmoothingParams:
    min_cutoff_hz: float = 0.05
    beta: float = 80.0
    derivative_cutoff_hz: float = 1.0
    max_gap_s: float = 0.5


def _alpha(cutoff_hz, dt):
    return 1.0 / (1.0 + 1.0 / (2.0 * np.pi * cutoff_hz * dt))


class KeypointSmoother:
    """One-euro filters of ``labels`` (module docstring); :meth:`filter` takes one frame set."""

    def __init__(self, labels, params: SmoothingParams | None = None):
        self.labels = tuple(labels)
        self.params = params or SmoothingParams()
        n = len(self.labels)
        self._index = {label: k for k, label in enumerate(self.labels)}
        self._value = np.full((n, 3), np.nan)
        self._raw = np.full((n, 3), np.nan)
        self._speed = np.zeros((n, 3))
        self._stamp = np.full(n, -1, dtype=np.int64)

    def reset(self) -> None:
        self._value[:] = np.nan
        self._raw[:] = np.nan
        self._speed[:] = 0.0
        self._stamp[:] = -1

    def filter(self, labels, positions: np.ndarray, stamp_ns: int) -> np.ndarray:
        """The smoothed ``positions (K, 3)`` of ``labels`` at ``stamp_ns``."""
        p = self.params
        rows = np.array([self._index[label] for label in labels], dtype=np.intp)
        positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        if rows.size == 0:
            return positions.copy()
        dt = (stamp_ns - self._stamp[rows]) * 1e-9
        fresh = ((self._stamp[rows] < 0) | (dt <= 0) | (dt > p.max_gap_s)
                 | ~np.isfinite(self._value[rows]).all(axis=1))
        dt = np.where(fresh, 1.0, dt)[:, None]
        previous = np.where(fresh[:, None], positions, self._value[rows])
        speed = (positions - np.where(fresh[:, None], positions, self._raw[rows])) / (dt * BODY_SIZE_M)
        speed = np.where(fresh[:, None], 0.0,
                         self._speed[rows] + _alpha(p.derivative_cutoff_hz, dt)
                         * (speed - self._speed[rows]))
        cutoff = p.min_cutoff_hz + p.beta * np.abs(speed)
        out = np.where(fresh[:, None], positions,
                       previous + _alpha(cutoff, dt) * (positions - previous))
        self._value[rows], self._raw[rows] = out, positions
        self._speed[rows], self._stamp[rows] = speed, stamp_ns
        return out
