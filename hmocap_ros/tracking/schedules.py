"""The layer schedule of a method name and a budget (:func:`make_schedule`), or of a
tracker's settings (:func:`schedule_for`): the motion std and the kernel of
:mod:`.body_layers` handed to the method's own schedule (:mod:`.methods`)."""
from __future__ import annotations

import numpy as np

from hmocap_ros.body.skeleton import Skeleton
from hmocap_ros.tracking.body_layers import (
    JUMP_FRACTION,
    JUMP_SCALE,
    REFINE_NU,
    RESEED_FRACTION,
    SURVIVAL_RATE,
    BodySchedule,
    body_sigma0,
    pose_kernel,
    root_room_limits,
)
from hmocap_ros.tracking.methods import TrackingMethod, get_method

__all__ = ["make_schedule", "schedule_for"]


def make_schedule(method: str | TrackingMethod, skel: Skeleton, *,
                  n_particles: int | None = None, n_layers: int | None = None,
                  sigma_scale: float = 1.0, survival_rate: float = 0.5, apf_alpha: float = 0.7,
                  refine_nu: float = 0.25, jump_fraction: float = 0.0, jump_scale: float = 4.0,
                  reseed_fraction: float = 0.0, room_lo: np.ndarray | None = None,
                  room_hi: np.ndarray | None = None, sweeps: int = 1) -> BodySchedule:
    """The layer schedule of ``method`` (a name of :data:`~.methods.METHODS` or the method
    itself); see :mod:`.body_layers`.

    n_particles / n_layers: None gives the method's budget. ``n_layers`` only applies to the
    APF (the hierarchical schedules have one layer per body block and sweep).
    sweeps: hierarchical schedules weigh the blocks this many times over the kinematic tree
    per frame (alg. 5 with each partition repeated; later sweeps diffuse a block with
    :data:`~.body_layers.SWEEP_DECAY` times the std of the sweep before); with
    ``n_particles`` None the particles per layer shrink so the evaluations per frame stay
    those of one sweep.
    """
    method = get_method(method)
    if sweeps < 1:
        raise ValueError("sweeps must be >= 1")
    n = int(n_particles or method.layer_particles(sweeps))
    if n < 2:
        raise ValueError("need at least 2 particles")
    sigma0 = body_sigma0(skel, sigma_scale)
    lo: np.ndarray | None = None
    hi: np.ndarray | None = None
    if room_lo is not None:
        assert room_hi is not None  # the room box comes as both of its corners
        lo, hi = root_room_limits(room_lo, room_hi)
    kernel = pose_kernel(skel, lo, hi, jump_fraction, jump_scale, reseed_fraction)
    return method.schedule(skel, n, n_layers, sigma0, kernel, survival_rate=survival_rate,
                           apf_alpha=apf_alpha, refine_nu=refine_nu, sweeps=sweeps)


def schedule_for(params, skel: Skeleton, room_lo: np.ndarray | None = None,
                 room_hi: np.ndarray | None = None) -> BodySchedule:
    """The schedule of a tracker's settings (:class:`~.params.TrackerParams`), with the
    tracker's annealing and kernel (:mod:`.body_layers`' constants)."""
    f = params.filter
    return make_schedule(params.tracking_method, skel, n_particles=f.particles or None,
                         n_layers=f.layers or None, survival_rate=SURVIVAL_RATE,
                         refine_nu=REFINE_NU, jump_fraction=JUMP_FRACTION,
                         jump_scale=JUMP_SCALE, reseed_fraction=RESEED_FRACTION,
                         room_lo=room_lo, room_hi=room_hi, sweeps=f.sweeps)
