"""Anthropometric entities and skeleton-based shape deformation (thesis sec. 2.3.2-2.3.3).

Two deformations per bone (sec. 2.3.2), both written as LBS of per-vertex translations
(eq. 2.12) and both linear in their coefficients, so a batch of shapes is one matrix
product with a precomputed basis:

* **bone scale** gamma_b: bone b (parent joint -> child joint or end site) gets length
  (1 + gamma_b) S; its child subtree is translated by gamma_b times the bone vector, and
  the vertices of the segment that the bone spans are stretched along it (the thesis
  translates the segment rigidly; stretching by the vertex's position along the bone,
  clamped to [0, 1], avoids the tear that a rigid shift leaves in the middle of a limb);
* **radial scale** beta_j: the offset of each vertex from the axis of segment j (the
  line through joint j along its bone) grows by beta_j, weighted by the skinning weight;
  the torso has directional variants (x = width, z = depth: only the offset component
  along that axis is scaled, as the thesis describes for torso width/depth).

Parameters are grouped in **anthropometric entities** (table 2.1, plus a few needed to
generate whole subjects).  An entity has a bone scale and a radial scale factor (1 =
the model's own proportions); a bone or segment that belongs to several entities gets
the product of their factors, e.g. the thesis' "shoulder height" scales all torso and leg
bones together while "legs" and "torso" refine them separately.

After deformation the body is put back on the floor (its lowest vertex keeps its rest
height) and scaled about the origin by the global scale.

Priors: table 2.1 gives mean M_k (cm) and variance sigma_k^2 (cm^2) per entity size.  The
MakeHuman body is not the thesis' mean subject (e.g. its shoulder-to-wrist length is 45 cm,
not 55.5), so priors are used **relative to the model**: mean = the model's own size,
std = sqrt(sigma_k^2) / M_k times that size.  Extra entities carry a relative std chosen
here (``Entity.rel_std``).  ``shape_log_prior`` is the log of eq. 2.13's product.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

FINGERS = ("thumb", "index", "middle", "ring", "pinky")
RADIAL_STD = 0.06  # relative std of radial (girth) factors in ``sample_shape``
GLOBAL_STD = 0.03  # relative std of the global scale in ``sample_shape``
TRUNCATE = 2.5  # samples are truncated to +- this many std


@dataclass(frozen=True)
class Entity:
    """One anthropometric entity: the bones it scales, the segments it thickens, its size.

    bones: child names (joint or end site) of the bones; "hands" in a name list expands
    to all hand/finger bones of the model.  radial_mode: "iso", "x" or "z".
    prior_cm = (M_k, sigma_k^2) from thesis table 2.1, or None (then rel_std applies).
    sampled: whether ``sample_shape`` draws it (aggregates are left at 1 so that sampled
    sizes follow the table's spreads).
    """

    name: str
    bones: tuple
    radial: tuple
    size: str
    prior_cm: tuple | None = None
    rel_std: float = 0.05
    radial_mode: str = "iso"
    sampled: bool = True


TORSO_BONES = ("spine", "chest", "neck", "l_clavicle", "r_clavicle")
LEG_BONES = ("l_knee", "l_ankle", "r_knee", "r_ankle")

ENTITIES = (
    Entity("shoulder_height", TORSO_BONES + LEG_BONES, (), "shoulder_height", (140.0, 17.0),
           sampled=False),
    Entity("head", ("head", "head_top"), ("head",), "head", (25.0, 5.0)),
    Entity("clavicles", ("l_shoulder", "r_shoulder"), (), "clavicles", (35.0, 7.0)),
    Entity("arms", ("l_elbow", "l_wrist", "r_elbow", "r_wrist"),
           ("l_shoulder", "l_elbow", "r_shoulder", "r_elbow"), "arms", (55.5, 10.0), sampled=False),
    Entity("upperarms", ("l_elbow", "r_elbow"), ("l_shoulder", "r_shoulder"), "upperarms", (25.5, 4.0)),
    Entity("lowerarms", ("l_wrist", "r_wrist"), ("l_elbow", "r_elbow"), "lowerarms", (30.5, 10.0)),
    Entity("legs", LEG_BONES, ("l_hip", "l_knee", "r_hip", "r_knee"), "legs", (90.5, 17.0)),
    Entity("torso", TORSO_BONES, ("pelvis", "spine", "chest"), "torso", (52.0, 8.0)),
    Entity("lowerlegs", ("l_ankle", "r_ankle"), ("l_knee", "r_knee"), "lowerlegs", rel_std=0.03),
    Entity("hip_width", ("l_hip", "r_hip"), (), "hip_width", rel_std=0.06),
    Entity("torso_width", (), ("pelvis", "spine", "chest"), "torso_width", rel_std=0.07,
           radial_mode="x"),
    Entity("torso_depth", (), ("pelvis", "spine", "chest"), "torso_depth", rel_std=0.07,
           radial_mode="z"),
    Entity("hands", ("hands",), ("hands",), "hands", rel_std=0.05),
    Entity("feet", ("l_toe", "r_toe"), ("l_ankle", "r_ankle"), "feet", rel_std=0.05),
)
ENTITY_NAMES = tuple(e.name for e in ENTITIES)
# Table 2.1 verbatim: entity -> (mean M_k in cm, variance sigma_k^2 in cm^2).
TABLE_2_1 = {e.name: e.prior_cm for e in ENTITIES if e.prior_cm is not None}


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
            from .model import load_body_model
            model = load_body_model("tracking")
        verts = apply_shape(model, self).vertices
        return verts[..., 1].max(-1) - verts[..., 1].min(-1)


@dataclass(frozen=True, eq=False)
class ShapedRest:
    """Rest geometry of a shaped subject: (V,3)/(J,3)/(E,3) or batched (B,...)."""

    vertices: np.ndarray
    joints: np.ndarray
    end_sites: np.ndarray


@dataclass(frozen=True, eq=False)
class ShapeBasis:
    """Linear shape basis of one model (built once, see ``shape_basis``)."""

    vertex: np.ndarray  # (nb + nr, V*3) float32: bone rows then radial (segment, mode) rows
    bone_joint: np.ndarray  # (nb, J*3)
    bone_end: np.ndarray  # (nb, E*3)
    bone_membership: np.ndarray  # (E_ent, nb)
    radial_membership: np.ndarray  # (E_ent, nr)
    bone_names: tuple
    radial_names: tuple


def _expand(names: tuple, available: list, hand_like: list) -> list:
    out = []
    for n in names:
        out += hand_like if n == "hands" else ([n] if n in available else [])
    return out


def _model_key(model) -> int:
    return id(model)


_BASIS_CACHE: dict = {}


def shape_basis(model) -> ShapeBasis:
    """Build (and cache per model object) the linear deformation basis of sec. 2.3.2."""
    key = _model_key(model)
    hit = _BASIS_CACHE.get(key)
    if hit is not None and hit[0] is model:
        return hit[1]
    from .skeleton import primary_child

    names = [str(n) for n in model.joint_names]
    ends = [str(n) for n in model.end_site_names]
    parents = np.asarray(model.parents)
    end_par = np.asarray(model.end_site_parents)
    pj = np.asarray(model.joints_rest, dtype=np.float64)
    pe = np.asarray(model.end_sites_rest, dtype=np.float64)
    verts = np.asarray(model.vertices, dtype=np.float64)
    w = np.asarray(model.weights, dtype=np.float64)
    nj, ne, nv = len(names), len(ends), len(verts)

    children: dict = {}
    end_children: dict = {}
    for j in range(1, nj):
        children.setdefault(names[parents[j]], []).append(names[j])
    for e in range(ne):
        end_children.setdefault(names[end_par[e]], []).append(ends[e])
    # descendant[c, j]: joint j is c or below c
    desc = np.eye(nj, dtype=bool)
    for j in range(1, nj):
        q = parents[j]
        while q >= 0:
            desc[q, j] = True
            q = parents[q]

    bone_names = tuple(names[1:] + ends)
    nb = len(bone_names)
    bone_vec = np.concatenate([pj[1:] - pj[parents[1:]], pe - pj[end_par]])
    bj = np.zeros((nb, nj, 3))
    be = np.zeros((nb, ne, 3))
    for b in range(nj - 1):
        c = b + 1
        bj[b, desc[c]] = bone_vec[b]
        be[b, desc[c][end_par]] = bone_vec[b]
    for e in range(ne):
        be[nj - 1 + e, e] = bone_vec[nj - 1 + e]
    bv = np.einsum("vj,bjk->bvk", w, bj)
    points = set(names) | set(ends)
    axis = np.zeros((nj, 3))
    for j, name in enumerate(names):
        child = primary_child(name, children, end_children, points)
        b = bone_names.index(child)
        vec = bone_vec[b]
        axis[j] = vec / np.linalg.norm(vec)
        s = np.clip((verts - pj[j]) @ vec / (vec @ vec), 0.0, 1.0)
        bv[b] += (w[:, j] * s)[:, None] * vec
    # radial offsets from each segment axis (unclamped perpendicular)
    rel = verts[:, None, :] - pj[None]  # (V, J, 3)
    perp = rel - np.einsum("vjk,jk->vj", rel, axis)[..., None] * axis
    radial_rows, radial_names = [], []
    for j, name in enumerate(names):
        iso = w[:, j, None] * perp[:, j]
        radial_rows.append(iso)
        radial_names.append((name, "iso"))
        for mode, k in (("x", 0), ("z", 2)):
            d = np.zeros((nv, 3))
            d[:, k] = w[:, j] * perp[:, j, k]
            radial_rows.append(d)
            radial_names.append((name, mode))
    rv = np.stack(radial_rows)

    hand_bones = [n for n in bone_names if n.endswith("_hand_tip")
                  or any(n[2:].startswith(f) for f in FINGERS)]
    hand_segments = [n for n in names if n.endswith("_wrist")
                     or any(n[2:].startswith(f) for f in FINGERS)]
    mb = np.zeros((len(ENTITIES), nb))
    mr = np.zeros((len(ENTITIES), len(radial_names)))
    for k, ent in enumerate(ENTITIES):
        for n in _expand(ent.bones, list(bone_names), hand_bones):
            mb[k, bone_names.index(n)] = 1.0
        for n in _expand(ent.radial, names, hand_segments):
            mr[k, radial_names.index((n, ent.radial_mode))] = 1.0
    used = mr.any(axis=0)  # drop (segment, mode) rows that no entity drives
    vertex = np.concatenate([bv.reshape(nb, -1), rv[used].reshape(int(used.sum()), -1)])
    basis = ShapeBasis(vertex=vertex.astype(np.float32), bone_joint=bj.reshape(nb, -1),
                       bone_end=be.reshape(nb, -1),
                       bone_membership=mb, radial_membership=mr[:, used], bone_names=bone_names,
                       radial_names=tuple(n for n, u in zip(radial_names, used) if u))
    _BASIS_CACHE[key] = (model, basis)
    return basis


def _check_entities(shape: BodyShape) -> None:
    if tuple(shape.entity_names) != ENTITY_NAMES:
        raise ValueError("BodyShape entity names do not match this module's ENTITIES")


def apply_shape(model, shape: BodyShape | None, vertex_subset: np.ndarray | None = None) -> ShapedRest:
    """Shaped rest geometry for one shape or a batch (sec. 2.3.2, all deformations at rest).

    v' = v + sum_b gamma_b B_b + sum_r beta_r R_r, re-grounded, then global scaling.
    ``vertex_subset``: compute only these vertices (the returned ``vertices`` hold them, in
    that order); the lowest shaped vertex, which re-grounds the body, must be among them.
    """
    verts0 = np.asarray(model.vertices, dtype=np.float64)
    if vertex_subset is not None:
        verts0 = verts0[vertex_subset]
    joints0 = np.asarray(model.joints_rest, dtype=np.float64)
    ends0 = np.asarray(model.end_sites_rest, dtype=np.float64)
    if shape is None:
        return ShapedRest(verts0, joints0, ends0)
    _check_entities(shape)
    basis = shape_basis(model)
    bone = np.atleast_2d(shape.bone_scale)
    radial = np.atleast_2d(shape.radial_scale)
    gamma = np.exp(np.log(bone) @ basis.bone_membership) - 1.0
    beta = np.exp(np.log(radial) @ basis.radial_membership) - 1.0
    n = len(gamma)
    coef = np.concatenate([gamma, beta], axis=1).astype(np.float32)
    vbasis = basis.vertex
    if vertex_subset is not None:
        cols = (3 * np.asarray(vertex_subset)[:, None] + np.arange(3)).ravel()
        vbasis = vbasis[:, cols]
    verts = (coef @ vbasis).reshape(n, -1, 3)  # float32: the mesh is float32 anyway
    verts += verts0.astype(np.float32)
    joints = joints0 + (gamma @ basis.bone_joint).reshape(n, -1, 3)
    ends = ends0 + (gamma @ basis.bone_end).reshape(n, -1, 3)
    rest_floor = np.asarray(model.vertices, dtype=np.float64)[:, 1].min()
    lift = rest_floor - verts[..., 1].min(-1)  # keep the feet on the floor
    for a in (verts, joints, ends):
        a[..., 1] += lift[:, None].astype(a.dtype)
    g = np.broadcast_to(shape.global_scale, (n,))[:, None, None]
    verts *= g.astype(np.float32)
    joints, ends = joints * g, ends * g
    if not shape.batched:
        verts, joints, ends = verts[0], joints[0], ends[0]
    return ShapedRest(verts, joints, ends)


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
