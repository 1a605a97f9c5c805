"""Layer schedules of the body tracker: APF, HPF, HPF with approximate partitioning, DD-HPF.

Four schedules of the layered particle filter (:mod:`hmocap_ros.lpf.layered_filter`, alg. 5) over the
30-DoF "tracking" parameterisation of the body (:mod:`hmocap_ros.body.skeleton`), at about
the same number of weight evaluations per frame (the comparison of thesis sec. 2.4.2 and
2.5.2, where the APF runs 14 layers x 250 particles and the HPF 7 layers x 500):

=========  ==========================================================  ==========================
method     layers                                                      evaluations per frame
=========  ==========================================================  ==========================
apf        14 annealing layers over all 30 DoF (the last is the final   14 x 250 = 3500
           run with the inter-frame kernel), beta per layer for a
           survival rate, diffusion decaying by eq. 2.10
hpf        7 layers along the kinematic tree: torso and head (root 6    7 x 500 = 3500
           DoF, spine, neck), left leg, right leg, left shoulder,
           right shoulder, left elbow, right elbow (the skeleton's DoF
           groups); every layer weighs the whole images (eq. 2.8)
hpf-apo    the same 7 layers, each weighing only inside the boxes of    8 x 438 = 3504
           its body parts (eq. 2.15, :mod:`.observation_boxes`), plus
           the final whole-body re-weighting layer (eq. 2.8)
dd-hpf     the hpf-apo schedule; the tracker adds IK particles from     8 x 438 = 3504
           detected hands and makes the final layer the refinement
           layer of eq. 2.21 (sec. 2.5.2, :mod:`.ik_proposals`)
=========  ==========================================================  ==========================

This module holds what the schedules share (the blocks, ``sigma0``, the kernel within the
joint limits, :class:`BodySchedule`); each method builds its own schedule
(:mod:`hmocap_ros.tracking.methods`), and :func:`~.schedules.make_schedule` makes the
schedule of a method name.

Each shoulder layer samples its elbow too (the elbow layer then refines it). The table is
one sweep (``sweeps=1``). With ``sweeps=2`` the hierarchical schedules weigh
the seven blocks twice per frame, torso to right elbow and again (sec. 2.2.4: a layered
filter is several filtering runs over sub-state spaces, and nothing asks each partition to
come once; the thesis' shape estimation repeats its first layers as an annealing scheme,
table 2.2), the second sweep diffusing each block at :data:`SWEEP_DECAY` times its std,
with fewer particles per layer for the same evaluations (hpf 14 x 250, hpf-apo and dd-hpf
15 x 234). A block's first weighing sees the blocks after it at their predicted pose; the
second sees them filtered, so a torso pulled aside by a wrongly predicted leg is weighed
again once the leg is in place.

Choices where the thesis is vague:

* Kernels follow partitioned sampling (sec. 2.2.3, condition 1): the dynamics of a partition
  are applied just before the layer that weighs it. With alg. 1's order (weigh, resample,
  propagate), the kernel of layer ``l`` therefore diffuses ``Psi_{l+1}`` (std ``sigma0``)
  and the inter-frame kernel ``K_t`` of the final run diffuses ``Psi_0`` (the torso), so each
  block is diffused once per frame, by its own motion std, right before its own weighting.
  Alg. 3's re-diffusion of the blocks already filtered is kept with a small ``nu``
  (:data:`REFINE_NU` = 0.25): a slight local refinement of the parents,
  which every later whole-image layer keeps measuring.
* ``sigma0`` (``DEFAULT_SIGMA0``): the root-mean-square frame-to-frame change of each DoF at
  25 fps over motion-capture clips that are not used for any evaluation (CMU 13_29 jumping
  jacks / twists / squats, 01_01 jumps and turns, 02_05 punches, 14_27 sit and stand, from the
  project's shared CMU clips, retargeted onto the body), left and right sides pooled, times
  ``SIGMA0_FACTOR`` = 1.5 (a Gaussian with the RMS as std covers too few of the fast frames).
  Schedules take a ``sigma_scale`` on top.
* Joint limits: the kernel clips every DoF to the skeleton's limits and shortens ball-joint
  swing vectors (:func:`clip_pose` without the yaw wrap: the root yaw is left continuous so
  that weighted means never straddle +-pi); the root position is kept inside the room.
* The APF's first layer weighs the particles diffused by the inter-frame kernel (sigma0); its
  own kernel std decays by ``alpha`` in variance per layer (eq. 2.10).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from hmocap_ros.body.skeleton import SWING_NORM_MAX, Skeleton
from hmocap_ros.lpf.kernels import gaussian_kernel
from hmocap_ros.lpf.layered_filter import LayeredFilter

if TYPE_CHECKING:
    from hmocap_ros.tracking.methods.protocol import TrackingMethod

__all__ = [
    "BODY_BLOCKS", "DEFAULT_SIGMA0", "JUMP_FRACTION", "JUMP_SCALE", "REFINE_NU", "RESEED_FRACTION",
    "SIGMA0_FACTOR", "SURVIVAL_RATE", "SWEEP_DECAY", "BodySchedule", "block_dims",
    "body_sigma0", "clip_body_pose", "pose_kernel", "root_room_limits",
]

#: DoF groups of the tracking skeleton in kinematic-tree order (sec. 2.5.2).
BODY_BLOCKS = ("torso", "l_leg", "r_leg", "l_shoulder", "r_shoulder", "l_elbow", "r_elbow")
SIGMA0_FACTOR = 1.5
#: Hierarchical schedules with several sweeps: std factor of a block's kernel per sweep after
#: the first (the second sweep searches at half the first one's std).
SWEEP_DECAY = 0.5
#: The tracker's particle survival rate, which sets each layer's annealing exponent beta
#: (eq. 2.9): the share of the particles a layer keeps, a property of the method (how sharply
#: a layer concentrates on its best fits), not of a room.
SURVIVAL_RATE = 0.3
#: The tracker's decay of alg. 3's re-diffusion of the blocks already filtered (module
#: docstring): a slight local refinement of the parents.
REFINE_NU = 0.25
#: The tracker's kernel (:func:`pose_kernel`): the share of the particles diffused with
#: JUMP_SCALE times the std, and the share whose limb DoFs are drawn anew within the joint
#: limits, so that a limb can leave a wrong mode of the silhouette cost (sec. 2.4: the
#: silhouette cost of a limb has a narrow basin, and an arm against the torso is a local
#: minimum).
JUMP_FRACTION, JUMP_SCALE, RESEED_FRACTION = 0.1, 4.0, 0.1

#: RMS frame-to-frame change per DoF at 25 fps (metres, degrees) on the clips of the module
#: docstring (sides pooled, rounded; the
#: horizontal root translation pools x and z, which the clips' travel directions make unequal).
MOTION_RMS = {
    "root_tx": 0.011, "root_ty": 0.016, "root_tz": 0.011,
    "root_yaw": 2.0, "root_pitch": 1.1, "root_roll": 0.8,
    "spine_flex": 1.3, "spine_bend": 0.7, "spine_twist": 1.0,
    "neck_flex": 1.2, "neck_bend": 0.6, "neck_twist": 1.0,
    "shoulder_flex": 3.0, "shoulder_abd": 3.0, "shoulder_twist": 3.3, "elbow_flex": 4.0,
    "hip_flex": 2.8, "hip_abd": 1.2, "hip_twist": 1.5, "knee_flex": 3.5, "ankle_flex": 3.2,
}


def _sigma0_table() -> dict:
    out = {}
    for name, v in MOTION_RMS.items():
        value = v if name.startswith("root_t") else np.deg2rad(v)
        out[name] = SIGMA0_FACTOR * value
    return out


DEFAULT_SIGMA0 = _sigma0_table()


def _generic(dof: str) -> str:
    return dof[2:] if dof[:2] in ("l_", "r_") else dof


def body_sigma0(skel: Skeleton, scale: float = 1.0) -> np.ndarray:
    """Inter-frame std ``sigma0`` (D,) of each DoF (metres / radians) times ``scale``."""
    return scale * np.array([DEFAULT_SIGMA0[_generic(n)] for n in skel.dof_names])


# ----------------------------------------------------------------------------- limits


def clip_body_pose(skel: Skeleton, particles: np.ndarray, room_lo: np.ndarray | None = None,
                   room_hi: np.ndarray | None = None) -> np.ndarray:
    """Clip particles (N, D) in place to the joint limits (yaw left free) and the room."""
    lower = np.array(skel.lower, dtype=np.float64)
    upper = np.array(skel.upper, dtype=np.float64)
    lower[skel.wrap_dofs] = -np.inf
    upper[skel.wrap_dofs] = np.inf
    if room_lo is not None:
        lower[skel.translation_dofs] = room_lo
        upper[skel.translation_dofs] = room_hi
    np.clip(particles, lower, upper, out=particles)
    for kind, dofs in zip(skel.joint_kind, skel.joint_dofs):
        if kind == "swing_twist":
            sw = particles[:, list(dofs[:2])]
            norm = np.linalg.norm(sw, axis=1, keepdims=True)
            particles[:, list(dofs[:2])] = sw * np.minimum(1.0, SWING_NORM_MAX / np.maximum(norm, 1e-12))
    return particles


def _limited_gaussian(particles, std, rng, *, skel, room_lo, room_hi, jump_fraction,
                      jump_scale, reseed_fraction, reseed_mask):
    n = particles.shape[0]
    active = np.flatnonzero(std > 0)
    if active.size:
        if jump_fraction > 0.0:
            scale = np.where(rng.random(n) < jump_fraction, jump_scale, 1.0)[:, None]
            particles[:, active] += (rng.standard_normal((n, active.size)) * std[active]) * scale
        else:
            gaussian_kernel(particles, std, rng)
        dims = active[reseed_mask[active]] if reseed_fraction > 0.0 else active[:0]
        if dims.size:
            rows = np.flatnonzero(rng.random(n) < reseed_fraction)
            lo, hi = skel.lower[dims], skel.upper[dims]
            particles[np.ix_(rows, dims)] = lo + (hi - lo) * rng.random((rows.size, dims.size))
    return clip_body_pose(skel, particles, room_lo, room_hi)


def pose_kernel(skel: Skeleton, room_lo: np.ndarray | None = None,
                room_hi: np.ndarray | None = None, jump_fraction: float = 0.0,
                jump_scale: float = 4.0, reseed_fraction: float = 0.0):
    """Gaussian kernel within the joint limits (:func:`clip_body_pose`), a
    :data:`~.kernels.Kernel`.

    Silhouette costs of a limb have a narrow basin: an arm that is 20 degrees off overlaps
    nothing of the true arm, and an arm hidden against the torso is a local minimum (it costs
    only the unexplained true arm). Two optional mixture components let particles leave such
    a state; the weighting keeps them only when they fit better:

    - ``jump_fraction``: that fraction of the particles (drawn anew each call) diffuses with
      ``jump_scale`` times the std;
    - ``reseed_fraction``: that fraction of the particles gets the limb DoFs being diffused
      (all but the torso block's) drawn uniformly within the joint limits.
    """
    reseed_mask = np.array([g != "torso" for g in skel.dof_groups])
    return partial(_limited_gaussian, skel=skel, room_lo=room_lo, room_hi=room_hi,
                   jump_fraction=float(jump_fraction), jump_scale=float(jump_scale),
                   reseed_fraction=float(reseed_fraction), reseed_mask=reseed_mask)


def root_room_limits(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Limits of the pelvis position inside the room box: above 0.3 m, below 1.6 m."""
    return (np.array([lo[0], 0.3, lo[2]], dtype=np.float64),
            np.array([hi[0], 1.6, hi[2]], dtype=np.float64))


# ----------------------------------------------------------------------------- schedules


@dataclass(frozen=True, eq=False)
class BodySchedule:
    """A method's layer schedule plus what the weighting function needs to know per layer.

    method: the :class:`~hmocap_ros.tracking.methods.TrackingMethod` it implements.
    filter: the :class:`LayeredFilter` (alg. 5).
    layer_blocks: per weighting (L + 1 entries) the body block names it concentrates on, or
        () for a weighting over the whole body (APF layers, the final layers).
    boxed: per weighting, whether it measures inside the block's observation boxes (eq. 2.15)
        rather than the whole images (eq. 2.8).
    """

    method: TrackingMethod
    filter: LayeredFilter
    layer_blocks: tuple
    boxed: tuple

    @property
    def n_particles(self) -> int:
        first = self.filter.layers[0] if self.filter.layers else self.filter.final
        assert first.n_particles is not None  # a body schedule sets every layer's count
        return int(first.n_particles)

    @property
    def n_weightings(self) -> int:
        return self.filter.n_layers

    @property
    def evaluations_per_frame(self) -> int:
        steps = self.filter.layers + (self.filter.final,)
        return int(sum(s.n_particles or self.n_particles for s in steps))


def block_dims(skel: Skeleton) -> list[np.ndarray]:
    """DoF indices of each layer: a shoulder layer also samples its elbow."""
    dims = [skel.group_dofs(b) for b in BODY_BLOCKS]
    for side in ("l", "r"):
        s = BODY_BLOCKS.index(f"{side}_shoulder")
        e = BODY_BLOCKS.index(f"{side}_elbow")
        dims[s] = np.union1d(dims[s], dims[e])
    return dims
