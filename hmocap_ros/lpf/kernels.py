"""Transition kernels K_t^l for the layered particle filter (thesis sec. 2.2.1, 2.2.4).

A kernel is any callable ``kernel(particles, std, rng) -> particles``:

- ``particles`` (N, D) float64, a fresh array owned by the filter: the kernel may change it
  in place, and returns the propagated set (N, D) (the same array or a new one).
- ``std`` (D,) the per-dimension diffusion standard deviation the filter computed for this
  layer (alg. 3, eq. 2.10 or an explicit override); 0 marks a dimension the layer must leave
  untouched (partitioned sampling condition 1, sec. 2.2.3).
- ``rng`` the run's ``numpy.random.Generator``: the only source of randomness.

Custom kernels (rejection sampling against an anthropometric prior, eq. 2.13; detector-driven
IK particles, sec. 2.5.2) bind their extra data with a closure or ``functools.partial`` and
keep this signature.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

Kernel = Callable[[np.ndarray, np.ndarray, np.random.Generator], np.ndarray]


def gaussian_kernel(particles: np.ndarray, std: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Baseline Gaussian kernel K(x) = x + N(0, diag(std^2)) (sec. 2.2.1).

    Noise is drawn only for the dimensions with ``std > 0``, (N, n_active) numbers in one
    call, so a layer over a few dimensions costs little and consumes little randomness.
    """
    active = np.flatnonzero(std > 0.0)
    if active.size == particles.shape[1]:
        particles += rng.standard_normal(particles.shape) * std
    elif active.size:
        particles[:, active] += rng.standard_normal((particles.shape[0], active.size)) * std[active]
    return particles


def identity_kernel(particles: np.ndarray, std: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """No propagation, e.g. the refinement layer of sec. 2.5.2 or a static final layer."""
    return particles


def clip_to_bounds(particles: np.ndarray, lower: np.ndarray | None,
                   upper: np.ndarray | None) -> np.ndarray:
    """Clip particles (N, D) in place to box limits (joint limits); None means unbounded."""
    if lower is not None or upper is not None:
        np.clip(particles, lower, upper, out=particles)
    return particles


def rejection_kernel(particles: np.ndarray, std: np.ndarray, rng: np.random.Generator, *,
                     log_prior: Callable[[np.ndarray], np.ndarray], tau: float = 0.7,
                     max_trials: int = 10, prior_dims: np.ndarray | None = None) -> np.ndarray:
    """Gaussian kernel with rejection sampling against a prior, thesis sec. 2.3.3 (eq. 2.13).

    For every particle: draw a candidate ``x + N(0, diag(std^2))`` and accept it when
    ``P(candidate) >= tau * P(x)``, i.e. ``log_prior(candidate) >= log(tau) + log_prior(x)``
    (eq. 2.13 is the product of Gaussian entity-size terms; the thesis' acceptance test
    "P(x) > tau P(x)" compares the candidate with the current particle, tau = 0.7). Rejected
    particles draw again, all of them in one vectorised step, for at most ``max_trials``
    rounds; a particle still rejected then keeps its current values in ``prior_dims`` (the
    dimensions the prior constrains, default all) and its last candidate elsewhere.

    ``log_prior(particles (n, D)) -> (n,)``; bind it (and tau, max_trials) with
    ``functools.partial`` to obtain a :data:`Kernel`.
    """
    if not 0.0 < tau <= 1.0:
        raise ValueError(f"tau must lie in (0, 1], got {tau}")
    current = particles.copy()
    threshold = np.log(tau) + np.asarray(log_prior(current), dtype=np.float64)
    out = particles
    pending = np.arange(particles.shape[0])
    for _ in range(max(int(max_trials), 1)):
        cand = gaussian_kernel(current[pending].copy(), std, rng)
        ok = np.asarray(log_prior(cand), dtype=np.float64) >= threshold[pending]
        out[pending] = cand
        pending = pending[~ok]
        if pending.size == 0:
            break
    if pending.size:
        dims = slice(None) if prior_dims is None else prior_dims
        rows = out[pending]
        rows[:, dims] = current[pending][:, dims]
        out[pending] = rows
    return out
