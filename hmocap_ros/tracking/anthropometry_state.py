"""The start-up's state vector ``X = Phi u Theta`` (thesis sec. 2.3.3): pose, then shape.

A start-up particle is ``[pose (D,) | shape (S,)]``: the D pose DoFs of the tracking skeleton,
then the shape state of :data:`SHAPE_PARAMS`, the global scale and the factors of the
anthropometric entities of table 2.1 (:mod:`hmocap_ros.body.anthropometry`) that a silhouette
can see at the working resolution: bone length and girth of the head, arms and legs, the
shoulder height, torso and hip width. Hands and feet stay at the model's proportions.
Aggregates (shoulder height) and their parts (torso, legs) are separate factors multiplied
together, as in :mod:`hmocap_ros.body.anthropometry`.
"""
from __future__ import annotations

import numpy as np

from hmocap_ros.body.anthropometry import ENTITY_NAMES, BodyShape, entity_sizes

__all__ = ["ROOT_DOFS", "SHAPE_KEYS", "SHAPE_PARAMS", "entity_size_errors", "shape_from_state",
           "shape_key", "shape_to_state"]

#: Shape state: ("global", "") or (entity, "bone" | "radial").
SHAPE_PARAMS = (
    ("global", ""), ("shoulder_height", "bone"), ("head", "bone"), ("head", "radial"),
    ("clavicles", "bone"), ("upperarms", "bone"), ("upperarms", "radial"),
    ("lowerarms", "bone"), ("lowerarms", "radial"), ("legs", "bone"), ("legs", "radial"),
    ("lowerlegs", "bone"), ("torso", "bone"), ("hip_width", "bone"),
    ("torso_width", "radial"), ("torso_depth", "radial"),
)

#: The root's 6 DoF, xi_0 of table 2.2.
ROOT_DOFS = ("root_tx", "root_ty", "root_tz", "root_yaw", "root_pitch", "root_roll")


def shape_key(entity: str, kind: str) -> str:
    """Name of one shape-state entry: ``"entity:kind"``, or ``"global"``."""
    return f"{entity}:{kind}" if kind else entity


#: Names of the shape-state entries, in :data:`SHAPE_PARAMS` order ("global", "head:bone", ...).
SHAPE_KEYS = tuple(shape_key(e, k) for e, k in SHAPE_PARAMS)


def shape_from_state(state: np.ndarray) -> BodyShape:
    """BodyShape of shape-state vectors (S,) or (N, S) (see :data:`SHAPE_PARAMS`)."""
    s = np.asarray(state, dtype=np.float64)
    batch = s.shape[:-1]
    e = len(ENTITY_NAMES)
    bone = np.ones(batch + (e,))
    radial = np.ones(batch + (e,))
    glob: float | np.ndarray = np.ones(batch)
    for k, (entity, kind) in enumerate(SHAPE_PARAMS):
        if kind == "":
            glob = s[..., k]
        elif kind == "bone":
            bone[..., ENTITY_NAMES.index(entity)] = s[..., k]
        else:
            radial[..., ENTITY_NAMES.index(entity)] = s[..., k]
    glob = float(glob) if np.ndim(glob) == 0 else glob
    return BodyShape(bone, radial, glob)


def shape_to_state(shape: BodyShape) -> np.ndarray:
    """Shape-state vector (S,) of a single BodyShape (other entities are dropped)."""
    out = np.empty(len(SHAPE_PARAMS))
    for k, (entity, kind) in enumerate(SHAPE_PARAMS):
        if kind == "":
            out[k] = float(shape.global_scale)
        else:
            b, r = shape.entity(entity)
            out[k] = float(b if kind == "bone" else r)
    return out


def entity_size_errors(model, estimate: BodyShape | None, truth: BodyShape) -> dict:
    """Per-entity size error (metres, estimate - truth) via :func:`entity_sizes`."""
    est = entity_sizes(model, estimate)
    true = entity_sizes(model, truth)
    return {n: float(a - b) for n, a, b in zip(ENTITY_NAMES, est, true)}
