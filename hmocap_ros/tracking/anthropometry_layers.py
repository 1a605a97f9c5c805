"""The layering of the anthropometry estimation (thesis sec. 2.3.3, table 2.2).

Table 2.2 partitions ``X = Phi u Theta`` (:mod:`.anthropometry_state`) following the kinematic
tree from the root, so that no layer's scaling moves a scale filtered before it: four
annealing layers over head, upper arms, shoulder height and the whole pose (annealing rates
0.1, 0.3, 0.8, 1.0), then head and root, upper arms, lower arms, legs length and upper legs,
lower legs, torso / legs / hip width; :func:`startup_filters` adds a final layer over
everything (alg. 5's ``w_t^L``).

Choices where the thesis is vague:

* Annealing rates: table 2.2's rates are read as the exponents ``beta`` of eq. 2.9 *relative*
  to the exponent that keeps the target share of the particles (``rate * beta_alpha``, see
  :class:`~.anthropometry_estimation.AnthropometryEstimator`): the thesis' XOR cost and ours
  differ in scale, and a rate of 1 then means a normal selective layer.
* Kernel order: as in :mod:`.body_layers`, the kernel of layer ``l`` diffuses the sub-state
  of layer ``l + 1`` (partitioned sampling, sec. 2.2.3), with the annealing layers' std
  decaying by ``sqrt(anneal_alpha)`` per layer (eq. 2.10); over the start-up frames the
  diffusion decays by ``frame_decay`` per frame.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from hmocap_ros.lpf.kernels import Kernel
from hmocap_ros.lpf.layered_filter import Layer, LayeredFilter
from hmocap_ros.tracking.anthropometry_state import ROOT_DOFS, SHAPE_KEYS, SHAPE_PARAMS
from hmocap_ros.tracking.body_layers import body_sigma0

if TYPE_CHECKING:
    from hmocap_ros.tracking.params import EstimationParams

__all__ = ["INIT_SPREAD", "TABLE_2_2", "init_spread", "layer_dims", "pose_index", "shape_std",
           "startup_filters"]

#: Table 2.2: (label, shape parameters, pose DoF groups or DoF names, annealing rate).
#: "all" = every pose DoF (Theta); "root" = xi_0 (the root's 6 DoF).
_ANNEALED = ("head:bone", "upperarms:bone", "shoulder_height:bone")
TABLE_2_2 = (
    ("Psi_0 head, upper arms, shoulder height and Theta", _ANNEALED, "all", 0.1),
    ("Psi_1 (annealing)", _ANNEALED, "all", 0.3),
    ("Psi_2 (annealing)", _ANNEALED, "all", 0.8),
    ("Psi_3 (annealing)", _ANNEALED, "all", 1.0),
    ("Psi_4 head and xi_0", ("head:bone", "head:radial"), ("root",), 1.0),
    ("Psi_5 upper arms anthropometry and pose", ("upperarms:bone", "upperarms:radial",
                                                 "clavicles:bone"),
     ("l_shoulder", "r_shoulder", "l_elbow", "r_elbow"), 1.0),
    ("Psi_6 lower arms anthropometry and pose", ("lowerarms:bone", "lowerarms:radial"),
     ("l_elbow", "r_elbow"), 1.0),
    ("Psi_7 legs length and upper legs pose", ("legs:bone",),
     ("l_hip_flex", "l_hip_abd", "l_hip_twist", "r_hip_flex", "r_hip_abd", "r_hip_twist"), 1.0),
    ("Psi_8 lower legs anthropometry and pose", ("lowerlegs:bone",),
     ("l_knee_flex", "l_ankle_flex", "r_knee_flex", "r_ankle_flex"), 1.0),
    ("Psi_9 torso, legs and hip width", ("torso:bone", "hip_width:bone", "torso_width:radial",
                                         "torso_depth:radial", "legs:radial"),
     ("spine_flex", "spine_bend", "spine_twist", "neck_flex", "neck_bend", "neck_twist"), 1.0),
)

#: Initial pose spread (metres / degrees) around the Powell fit, per generic DoF.
INIT_SPREAD = {
    "root_tx": 0.04, "root_ty": 0.03, "root_tz": 0.04, "root_yaw": 10.0, "root_pitch": 4.0,
    "root_roll": 4.0, "spine_flex": 6.0, "spine_bend": 4.0, "spine_twist": 6.0,
    "neck_flex": 8.0, "neck_bend": 5.0, "neck_twist": 10.0, "shoulder_flex": 20.0,
    "shoulder_abd": 15.0, "shoulder_twist": 20.0, "elbow_flex": 20.0, "hip_flex": 12.0,
    "hip_abd": 6.0, "hip_twist": 10.0, "knee_flex": 15.0, "ankle_flex": 8.0,
}


def init_spread(skel, scale: float = 1.0) -> np.ndarray:
    """Per pose DoF (D,) the spread of :data:`INIT_SPREAD` (metres, radians) times ``scale``."""
    return np.array([
        INIT_SPREAD[n[2:] if n[:2] in ("l_", "r_") else n]
        * (1.0 if n.startswith("root_t") else np.pi / 180)
        for n in skel.dof_names]) * scale


def shape_std(params: EstimationParams) -> np.ndarray:
    """Per shape-state entry (S,) the diffusion std: global, bone length or girth factor."""
    return np.array([params.global_std if k == "" else
                     params.shape_bone_std if k == "bone" else
                     params.shape_radial_std for _, k in SHAPE_PARAMS])


def pose_index(skel, spec) -> np.ndarray:
    """Pose DoF indices of a table 2.2 pose entry: "all", or DoF groups / names / "root"."""
    n_pose = skel.n_dofs
    if spec == "all":
        return np.arange(n_pose)
    out = []
    for item in spec:
        if item == "root":
            out += [skel.dof_index(n) for n in ROOT_DOFS]
        elif item in skel.dof_names:
            out.append(skel.dof_index(item))
        else:
            out += list(skel.group_dofs(item))
    return np.array(sorted(set(out)), dtype=np.intp)


def layer_dims(skel, estimate_shape: bool) -> list[np.ndarray]:
    """State dimensions of each table 2.2 layer (pose only when the shape is not estimated)."""
    n_pose = skel.n_dofs
    dims = []
    for _, shape_keys, pose_spec, _ in TABLE_2_2:
        pose = pose_index(skel, pose_spec)
        if estimate_shape:
            shape = np.array([n_pose + SHAPE_KEYS.index(k) for k in shape_keys], dtype=np.intp)
            dims.append(np.concatenate([pose, shape]))
        else:
            dims.append(pose)
    return dims


def _layer_std(layer: int, dims: list, base: np.ndarray, n_pose: int, n_anneal: int,
               frame_scale: float, params: EstimationParams) -> np.ndarray:
    """Std of the kernel of ``layer``: it diffuses the next layer's dimensions (none for the
    last table 2.2 layer)."""
    std = np.zeros(len(base))
    nxt = layer + 1
    if nxt < len(TABLE_2_2):
        d = dims[nxt]
        if nxt < n_anneal:
            factor = np.sqrt(params.anneal_alpha) ** nxt
            std[d] = base[d] * frame_scale * factor
            std[:n_pose] *= params.anneal_scale
        else:
            std[d] = base[d] * frame_scale
            std[:n_pose] *= params.part_scale
    return std


def startup_filters(skel, params: EstimationParams, estimate_shape: bool,
                    spread: np.ndarray, shape_stds: np.ndarray,
                    kernel: Kernel) -> list[LayeredFilter]:
    """One LayeredFilter per start-up frame (the diffusion decays from frame to frame).

    The annealing layers (every pose DoF at once) diffuse the pose by ``anneal_scale *
    spread`` (:func:`init_spread`), decaying by ``sqrt(anneal_alpha)`` per layer (eq. 2.10);
    the per-part layers (a few DoF each) by ``part_scale * spread``; shape dimensions by
    ``shape_stds`` (:func:`shape_std`), with the same decays. The final layer diffuses the
    pose by :func:`~.body_layers.body_sigma0` and the shape by ``shape_stds`` decayed one frame
    more. Every layer draws with ``kernel``.
    """
    n_pose = skel.n_dofs
    dims = layer_dims(skel, estimate_shape)
    base = np.concatenate([spread, shape_stds])
    if not estimate_shape:
        base[n_pose:] = 0.0
    n_anneal = sum(1 for row in TABLE_2_2 if row[2] == "all")
    out = []
    for f in range(max(params.frames, 1)):
        scale = params.frame_decay ** f
        layers = [Layer(dims=dims[layer], beta=1.0, n_particles=params.n_particles,
                        std=_layer_std(layer, dims, base, n_pose, n_anneal, scale, params),
                        kernel=kernel)
                  for layer in range(len(TABLE_2_2))]
        final_std = np.zeros(len(base))
        final_std[:n_pose] = body_sigma0(skel)
        if estimate_shape:
            final_std[n_pose:] = shape_stds * scale * params.frame_decay
        final = Layer(beta=1.0, n_particles=params.n_particles, std=final_std, kernel=kernel)
        out.append(LayeredFilter(layers=tuple(layers), sigma0=base, final=final))
    return out
