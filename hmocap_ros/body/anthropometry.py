"""Anthropometric shapes of the body model: sizes, priors and random subjects (thesis sec. 2.3.2-2.3.3).

A :class:`BodyShape` holds per-entity bone and radial scale factors and a global scale; the
entities are :mod:`hmocap_ros.body.entities` (table 2.1, plus a few needed to generate whole
subjects) and the deformation they drive, linear blend skinning of per-vertex translations
(eq. 2.12), is :mod:`hmocap_ros.body.shape_deformation` (:func:`apply_shape`).

Priors: table 2.1 gives mean M_k (cm) and variance sigma_k^2 (cm^2) per entity size.  The
MakeHuman body is not the thesis' mean subject (e.g. its shoulder-to-wrist length is 45 cm,
not 55.5), so priors are used **relative to the model**: mean = the model's own size,
std = sqrt(sigma_k^2) / M_k times that size.  Entities without a table entry carry their own
relative std (``Entity.rel_std``).  ``shape_log_prior`` is the log of eq. 2.13's product.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from .dof_table import FINGERS
from .entities import ENTITIES, ENTITY_NAMES, LEG_BONES, TABLE_2_1, TORSO_BONES, Entity
from .model import load_body_model
from .shape_deformation import ShapeBasis, ShapedRest, apply_shape, shape_basis

__all__ = [
    "ENTITIES", "ENTITY_NAMES", "FINGERS", "GLOBAL_STD", "LEG_BONES", "RADIAL_STD", "TABLE_2_1",
    "TORSO_BONES", "TRUNCATE", "BodyShape", "Entity", "ShapeBasis", "ShapedRest", "apply_shape",
    "entity_priors", "entity_sizes", "sample_shape", "shape_basis", "shape_log_prior",
]

RADIAL_STD = 0.06  # relative std of radial (girth) factors in ``sample_shape``
GLOBAL_STD = 0.03  # relative std of the global scale in ``sample_shape``
TRUNCATE = 2.5  # samples are truncated to +- this many std


@dataclass(frozen=True, eq=False)
class BodyShape:
    """Per-entity bone and radial scale factors (1 = model proportions) and a global scale.

    Arrays are (E,) for one subject or (B, E) for a batch (e.g. particles); global_scale
    is a float or (B,).  gamma = bone_scale - 1 and beta = radial_scale - 1 in the
    thesis' notation.
    """

    bone_scale: np.ndarray
    radial_scale: np.ndarray
    global_scale: float | np.ndarray = 1.0
    entity_names: tuple = field(default=ENTITY_NAMES)

    def __post_init__(self):
        b = np.asarray(self.bone_scale, dtype=np.float64)
        r = np.asarray(self.radial_scale, dtype=np.float64)
        if b.shape != r.shape or b.shape[-1] != len(self.entity_names):
            raise ValueError(f"bone/radial scales must be (..., {len(self.entity_names)})")
        if np.any(b <= 0) or np.any(r <= 0) or np.any(np.asarray(self.global_scale) <= 0):
            raise ValueError("scale factors must be positive")
        object.__setattr__(self, "bone_scale", b)
        object.__setattr__(self, "radial_scale", r)
        object.__setattr__(self, "global_scale", np.asarray(self.global_scale, dtype=np.float64))

    @classmethod
    def neutral(cls, n: int | None = None) -> "BodyShape":
        shape = (len(ENTITY_NAMES),) if n is None else (n, len(ENTITY_NAMES))
        return cls(np.ones(shape), np.ones(shape), 1.0 if n is None else np.ones(n))

    @classmethod
    def from_named(cls, names, bone_scale, radial_scale, global_scale=1.0) -> "BodyShape":
        """A shape from scales given per named entity (a BodyShape message's fields); the
        entities not named keep scale 1. ValueError on an unknown name or unequal lengths."""
        names = [str(n) for n in names]
        bone_scale, radial_scale = np.asarray(bone_scale), np.asarray(radial_scale)
        if not len(names) == len(bone_scale) == len(radial_scale):
            raise ValueError(f"{len(names)} entity names for {len(bone_scale)} bone and "
                             f"{len(radial_scale)} radial scales")
        unknown = [n for n in names if n not in ENTITY_NAMES]
        if unknown:
            raise ValueError(f"unknown body entities {', '.join(unknown)} (the model has "
                             f"{', '.join(ENTITY_NAMES)})")
        index = [ENTITY_NAMES.index(n) for n in names]
        bone, radial = np.ones(len(ENTITY_NAMES)), np.ones(len(ENTITY_NAMES))
        bone[index], radial[index] = bone_scale, radial_scale
        return cls(bone, radial, float(global_scale))

    @property
    def batched(self) -> bool:
        return self.bone_scale.ndim == 2

    def entity(self, name: str) -> tuple:
        """(bone_scale, radial_scale) of one entity."""
        i = self.entity_names.index(name)
        return self.bone_scale[..., i], self.radial_scale[..., i]

    def with_entity(self, name: str, bone: float | None = None, radial: float | None = None) -> "BodyShape":
        i = self.entity_names.index(name)
        b, r = self.bone_scale.copy(), self.radial_scale.copy()
        if bone is not None:
            b[..., i] = bone
        if radial is not None:
            r[..., i] = radial
        return BodyShape(b, r, self.global_scale, self.entity_names)

    def to_vector(self) -> np.ndarray:
        """Flat state (..., 2E+1): bone scales, radial scales, global scale."""
        g = np.broadcast_to(self.global_scale, self.bone_scale.shape[:-1])[..., None]
        return np.concatenate([self.bone_scale, self.radial_scale, g], -1)

    @classmethod
    def from_vector(cls, vec: np.ndarray) -> "BodyShape":
        vec = np.asarray(vec, dtype=np.float64)
        e = len(ENTITY_NAMES)
        return cls(vec[..., :e], vec[..., e:2 * e], vec[..., 2 * e])

    def height(self, model=None):
        """Standing height (m) of the shaped rest mesh: top vertex minus lowest vertex."""
        if model is None:
            model = load_body_model("tracking")
        verts = apply_shape(model, self).vertices
        return verts[..., 1].max(-1) - verts[..., 1].min(-1)


def _joint(model, name):
    return list(map(str, model.joint_names)).index(name)


def _end(model, name):
    return list(map(str, model.end_site_names)).index(name)


@lru_cache(maxsize=8)
def _size_vertices(model) -> tuple:
    """Vertices the entity sizes read: the torso (width, depth) and the soles (the lowest
    vertex grounds the body), as (subset indices, torso mask within the subset)."""
    verts = np.asarray(model.vertices, dtype=np.float64)
    torso = np.isin(np.asarray(model.vertex_part), [_joint(model, n) for n in ("spine", "chest")])
    soles = verts[:, 1] < verts[:, 1].min() + 0.04
    subset = np.flatnonzero(torso | soles)
    return subset, torso[subset]


def entity_sizes(model, shape: BodyShape | None = None) -> np.ndarray:
    """Size S_k (metres) of every entity of ``ENTITIES`` -> (E,) or (B, E)."""
    subset, torso_mask = _size_vertices(model)
    rest = apply_shape(model, shape, vertex_subset=subset)
    j = np.asarray(rest.joints)[None] if np.ndim(rest.joints) == 2 else rest.joints
    e = np.asarray(rest.end_sites)[None] if np.ndim(rest.end_sites) == 2 else rest.end_sites
    v = np.asarray(rest.vertices)[None] if np.ndim(rest.vertices) == 2 else rest.vertices

    def jp(name):
        return j[:, _joint(model, name)]

    def ep(name):
        return e[:, _end(model, name)]

    def dist(a, b):
        return np.linalg.norm(a - b, axis=-1)

    def both(fn):
        return 0.5 * (fn("l") + fn("r"))

    tv = v[:, torso_mask]
    sizes = {
        "shoulder_height": both(lambda s: jp(f"{s}_shoulder")[:, 1] - v[..., 1].min(-1)),
        "head": dist(jp("head"), jp("neck")) + dist(ep("head_top"), jp("head")),
        "clavicles": dist(jp("l_shoulder"), jp("r_shoulder")),
        "arms": both(lambda s: dist(jp(f"{s}_elbow"), jp(f"{s}_shoulder"))
                     + dist(jp(f"{s}_wrist"), jp(f"{s}_elbow"))),
        "upperarms": both(lambda s: dist(jp(f"{s}_elbow"), jp(f"{s}_shoulder"))),
        "lowerarms": both(lambda s: dist(jp(f"{s}_wrist"), jp(f"{s}_elbow"))),
        "legs": both(lambda s: dist(jp(f"{s}_knee"), jp(f"{s}_hip"))
                     + dist(jp(f"{s}_ankle"), jp(f"{s}_knee"))),
        "torso": dist(jp("spine"), jp("pelvis")) + dist(jp("chest"), jp("spine"))
                 + dist(jp("neck"), jp("chest")),
        "lowerlegs": both(lambda s: dist(jp(f"{s}_ankle"), jp(f"{s}_knee"))),
        "hip_width": dist(jp("l_hip"), jp("r_hip")),
        "torso_width": tv[..., 0].max(-1) - tv[..., 0].min(-1),
        "torso_depth": tv[..., 2].max(-1) - tv[..., 2].min(-1),
        "hands": both(lambda s: dist(ep(f"{s}_hand_tip"), jp(f"{s}_wrist"))),
        "feet": both(lambda s: dist(ep(f"{s}_toe"), jp(f"{s}_ankle"))),
    }
    out = np.stack([sizes[n] for n in ENTITY_NAMES], -1)
    return out if (shape is not None and shape.batched) else out[0]


@lru_cache(maxsize=8)
def _rel_std() -> np.ndarray:
    return np.array([np.sqrt(e.prior_cm[1]) / e.prior_cm[0] if e.prior_cm else e.rel_std
                     for e in ENTITIES])


def entity_priors(model) -> tuple:
    """Model-relative priors (mean, std) in metres per entity (see module docstring)."""
    mean = entity_sizes(model, None)
    return mean, _rel_std() * mean


def shape_log_prior(model, shape: BodyShape) -> np.ndarray:
    """log of eq. 2.13: sum_k -(S_k - M_k)^2 / (2 sigma_k^2) with the model-relative priors."""
    mean, std = entity_priors(model)
    s = entity_sizes(model, shape)
    return -0.5 * (((s - mean) / std) ** 2).sum(-1)


def sample_shape(rng: np.random.Generator, n: int | None = None, global_std: float = GLOBAL_STD,
                 radial_std: float = RADIAL_STD) -> BodyShape:
    """Random subjects from the table 2.1 priors (relative to the model's proportions).

    Entities with ``sampled=True`` get bone factors ~ N(1, rel_std) (table 2.1:
    sqrt(sigma_k^2)/M_k), radial factors ~ N(1, radial_std) where they thicken segments;
    aggregate entities (shoulder height, arms) stay at 1 so that the sizes they measure
    spread like their table entries.  All draws are truncated to +-2.5 std.
    """
    m = 1 if n is None else n
    e = len(ENTITIES)

    def draw(std, size):
        z = rng.standard_normal(size)
        return 1.0 + np.clip(z, -TRUNCATE, TRUNCATE) * std

    sampled = np.array([ent.sampled for ent in ENTITIES])
    has_bones = np.array([len(ent.bones) > 0 for ent in ENTITIES])
    has_radial = np.array([len(ent.radial) > 0 for ent in ENTITIES])
    directional = np.array([ent.radial_mode != "iso" for ent in ENTITIES])
    bone = np.where(sampled & has_bones, draw(_rel_std(), (m, e)), 1.0)
    radial_sd = np.where(directional, _rel_std(), radial_std)
    radial = np.where(sampled & has_radial, draw(radial_sd, (m, e)), 1.0)
    glob = draw(global_std, (m,))
    if n is None:
        return BodyShape(bone[0], radial[0], float(glob[0]))
    return BodyShape(bone, radial, glob)
