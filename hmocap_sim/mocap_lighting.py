"""Light levels of a simulated recording, per frame: daylight, exposure, the lamp.

Every recording has small smooth drifts of the daylight and of the cameras' exposure, and a
fixed colour response (white balance and gain) per camera; ``--lighting-changes`` adds sudden
events (``lighting_events``). :class:`hmocap_sim.mocap_render.MocapRenderer` folds them
into the light intensities.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["camera_gains", "light_levels", "lighting_events"]


def _smooth_noise(rng, t: np.ndarray, amplitude: float, periods=(3.0, 9.0)) -> np.ndarray:
    """A sum of a few random sinusoids with periods in ``periods`` (seconds), peak ~amplitude."""
    out = np.zeros_like(t, dtype=float)
    for _ in range(3):
        period = rng.uniform(*periods)
        out += math.sqrt(2.0 / 3.0) * np.sin(2 * math.pi * t / period + rng.uniform(0, 2 * math.pi))
    return amplitude * out / 1.5


def lighting_events(rng, t: np.ndarray, t_motion: float, t_end: float):
    """Lamp gain, exposure factor and window factor per frame for ``--lighting-changes``.

    The lamp dims to ~30 % over 0.1 s at 20-30 % of the motion and comes back at 60-70 %; the
    auto-exposure follows the lamp with a 0.4 s lag and compensates part of it; a cloud takes
    ~35 % of the window light for about a second around the middle of the motion.
    """
    dur = max(t_end - t_motion, 1e-6)
    t_off = t_motion + rng.uniform(0.2, 0.3) * dur
    t_on = t_motion + rng.uniform(0.6, 0.7) * dur
    low = rng.uniform(0.25, 0.35)
    ramp = 0.1
    down = np.clip((t - t_off) / ramp, 0.0, 1.0)
    up = np.clip((t - t_on) / ramp, 0.0, 1.0)
    lamp = 1.0 - (1.0 - low) * (down - up)
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.04
    alpha = 1.0 - math.exp(-dt / 0.4)
    seen = np.empty_like(lamp)
    acc = 1.0
    for i, g in enumerate(lamp):  # first-order lag of the auto-exposure
        acc += alpha * (g - acc)
        seen[i] = acc
    exposure = 1.0 + 0.3 * (1.0 - seen)
    t_cloud = t_motion + rng.uniform(0.4, 0.55) * dur
    window = 1.0 - 0.35 * np.exp(-0.5 * ((t - t_cloud) / 0.35) ** 2)
    return lamp, exposure, window


def light_levels(rng_light, rng_events, t: np.ndarray, t_motion: float, t_end: float,
                 changes: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Window gain, exposure and lamp gain per frame (times ``t``): smooth drifts drawn from
    ``rng_light``, and with ``changes`` the events of ``lighting_events`` from ``rng_events``."""
    window_gain = 1.0 + _smooth_noise(rng_light, t, 0.12)
    exposure = 1.0 + _smooth_noise(rng_light, t, 0.03, periods=(5.0, 12.0))
    lamp_gain = np.ones(len(t))
    if changes:
        lamp_gain, exposure_step, window_step = lighting_events(rng_events, t, t_motion, t_end)
        exposure = exposure * exposure_step
        window_gain = window_gain * window_step
    return window_gain, exposure, lamp_gain


def camera_gains(rng, n_cameras: int) -> np.ndarray:
    """(M, 3) colour response per camera: a gain (4 %) times a white balance (2.5 % per channel)."""
    return ((1.0 + 0.04 * rng.standard_normal((n_cameras, 1)))
            * (1.0 + 0.025 * rng.standard_normal((n_cameras, 3))))
