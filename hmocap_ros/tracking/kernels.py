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
