"""Skeleton-based shape deformation of the body model (thesis sec. 2.3.2).

Two deformations per bone, both written as LBS of per-vertex translations (eq. 2.12) and both
linear in their coefficients, so a batch of shapes is one matrix product with a precomputed
basis (:func:`shape_basis`):

* **bone scale** gamma_b: bone b (parent joint -> child joint or end site) gets length
  (1 + gamma_b) S; its child subtree is translated by gamma_b times the bone vector, and
  the vertices of the segment that the bone spans are stretched along it (the thesis
  translates the segment rigidly; stretching by the vertex's position along the bone,
  clamped to [0, 1], avoids the tear that a rigid shift leaves in the middle of a limb);
* **radial scale** beta_j: the offset of each vertex from the axis of segment j (the
  line through joint j along its bone) grows by beta_j, weighted by the skinning weight;
  the torso has directional variants (x = width, z = depth: only the offset component
  along that axis is scaled, as the thesis describes for torso width/depth).

The coefficients come from the per-entity factors of a
:class:`~hmocap_ros.body.anthropometry.BodyShape` (:mod:`hmocap_ros.body.entities`). After
deformation the body is put back on the floor (its lowest vertex keeps its rest height) and
scaled about the origin by the global scale.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np

from .dof_table import FINGERS
from .entities import ENTITIES, ENTITY_NAMES
from .skeleton import primary_child

__all__ = ["ShapeBasis", "ShapeFactors", "ShapedRest", "apply_shape", "shape_basis"]


class ShapeFactors(Protocol):
    """The per-entity factors the deformation reads: a
    :class:`~hmocap_ros.body.anthropometry.BodyShape`."""

    @property
    def bone_scale(self) -> np.ndarray: ...  # (E,) or (B, E)

    @property
    def radial_scale(self) -> np.ndarray: ...  # (E,) or (B, E)

    @property
    def global_scale(self) -> float | np.ndarray: ...  # float or (B,)

    @property
    def entity_names(self) -> tuple: ...

    @property
    def batched(self) -> bool: ...


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
    tree = _rest_tree(model)
    verts = np.asarray(model.vertices, dtype=np.float64)
    w = np.asarray(model.weights, dtype=np.float64)
    bone_names, bj, be, bv, axis = _bone_basis(tree, verts, w)
    rv, radial_names = _radial_basis(tree.names, verts, tree.joints, w, axis)
    mb, mr = _entity_membership(bone_names, tree.names, radial_names)
    nb = len(bone_names)
    used = mr.any(axis=0)  # drop (segment, mode) rows that no entity drives
    vertex = np.concatenate([bv.reshape(nb, -1), rv[used].reshape(int(used.sum()), -1)])
    basis = ShapeBasis(vertex=vertex.astype(np.float32), bone_joint=bj.reshape(nb, -1),
                       bone_end=be.reshape(nb, -1),
                       bone_membership=mb, radial_membership=mr[:, used], bone_names=bone_names,
                       radial_names=tuple(n for n, u in zip(radial_names, used) if u))
    _BASIS_CACHE[key] = (model, basis)
    return basis


class _RestTree(NamedTuple):
    """A model's kinematic tree at rest, as the basis needs it."""

    names: list  # joint names
    ends: list  # end site names
    parents: np.ndarray  # (J,)
    end_parents: np.ndarray  # (E,)
    joints: np.ndarray  # (J, 3) rest positions
    end_sites: np.ndarray  # (E, 3) rest positions
    children: dict  # joint name -> child joint names
    end_children: dict  # joint name -> end site names
    descendant: np.ndarray  # (J, J) bool: [c, j] iff joint j is c or below c


def _rest_tree(model) -> _RestTree:
    names = [str(n) for n in model.joint_names]
    ends = [str(n) for n in model.end_site_names]
    parents = np.asarray(model.parents)
    end_par = np.asarray(model.end_site_parents)
    nj, ne = len(names), len(ends)
    children: dict = {}
    end_children: dict = {}
    for j in range(1, nj):
        children.setdefault(names[parents[j]], []).append(names[j])
    for e in range(ne):
        end_children.setdefault(names[end_par[e]], []).append(ends[e])
    desc = np.eye(nj, dtype=bool)
    for j in range(1, nj):
        q = parents[j]
        while q >= 0:
            desc[q, j] = True
            q = parents[q]
    return _RestTree(names, ends, parents, end_par,
                     np.asarray(model.joints_rest, dtype=np.float64),
                     np.asarray(model.end_sites_rest, dtype=np.float64),
                     children, end_children, desc)


def _bone_basis(tree: _RestTree, verts: np.ndarray, w: np.ndarray) -> tuple:
    """Bone-scale basis: (bone names, joint rows (nb, J, 3), end-site rows (nb, E, 3), vertex
    rows (nb, V, 3), unit segment axis of every joint (J, 3)).

    A bone's rows translate its child subtree by the bone vector; the vertex rows are the
    LBS of those translations (eq. 2.12) plus the stretch of the segment the bone spans.
    """
    names, parents, end_par = tree.names, tree.parents, tree.end_parents
    pj, pe, desc = tree.joints, tree.end_sites, tree.descendant
    nj, ne = len(names), len(tree.ends)
    bone_names = tuple(names[1:] + tree.ends)
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
    points = set(names) | set(tree.ends)
    axis = np.zeros((nj, 3))
    for j, name in enumerate(names):
        child = primary_child(name, tree.children, tree.end_children, points)
        b = bone_names.index(child)
        vec = bone_vec[b]
        axis[j] = vec / np.linalg.norm(vec)
        s = np.clip((verts - pj[j]) @ vec / (vec @ vec), 0.0, 1.0)
        bv[b] += (w[:, j] * s)[:, None] * vec
    return bone_names, bj, be, bv, axis


def _radial_basis(names: list, verts: np.ndarray, pj: np.ndarray, w: np.ndarray,
                  axis: np.ndarray) -> tuple:
    """Radial-scale vertex rows (3J, V, 3) and their (segment, mode) names: the skinning-weighted
    offset of each vertex from each segment axis (unclamped perpendicular), whole ("iso") or
    only its x or z component."""
    nv = len(verts)
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
    return np.stack(radial_rows), radial_names


def _entity_membership(bone_names: tuple, names: list, radial_names: list) -> tuple:
    """0/1 matrices (E_ent, nb) and (E_ent, nr): which bones and radial rows each entity drives."""
    hand_bones = [n for n in bone_names if n.endswith("_hand_tip")
                  or any(n[2:].startswith(f) for f in FINGERS)]
    hand_segments = [n for n in names if n.endswith("_wrist")
                     or any(n[2:].startswith(f) for f in FINGERS)]
    mb = np.zeros((len(ENTITIES), len(bone_names)))
    mr = np.zeros((len(ENTITIES), len(radial_names)))
    for k, ent in enumerate(ENTITIES):
        for n in _expand(ent.bones, list(bone_names), hand_bones):
            mb[k, bone_names.index(n)] = 1.0
        for n in _expand(ent.radial, names, hand_segments):
            mr[k, radial_names.index((n, ent.radial_mode))] = 1.0
    return mb, mr


def _check_entities(shape: ShapeFactors) -> None:
    if tuple(shape.entity_names) != ENTITY_NAMES:
        raise ValueError("BodyShape entity names do not match this module's ENTITIES")


def apply_shape(model, shape: ShapeFactors | None, vertex_subset: np.ndarray | None = None) -> ShapedRest:
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
