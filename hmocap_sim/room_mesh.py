"""Triangle meshes of the furnished room: a material per face, atlas coordinates and colours
per vertex, and the tessellated primitives (quads, boxes, spheres, cones) it is made of.

Large surfaces are cut into cells because the rasteriser does not clip at the near plane
and lens distortion bends long edges.  Every helper returns ``(vertices, faces, uv)``, which
:meth:`MeshBuilder.add_mesh` takes with a material index.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "MeshBuilder",
    "SceneMesh",
    "ball_mesh",
    "box_mesh",
    "cells_along",
    "cone_mesh",
    "textured_quad",
    "turn_yaw",
    "uv_sphere",
]


@dataclass(frozen=True, eq=False)
class SceneMesh:
    """Triangles with a material per face and texture coordinates per vertex."""

    vertices: np.ndarray  # (V, 3) float32
    faces: np.ndarray  # (F, 3) int32
    face_material: np.ndarray  # (F,) int32
    uv: np.ndarray  # (V, 2) float32, atlas coordinates (0 where unused)
    colours: np.ndarray  # (V, 3) float32 sRGB multipliers (1 where unused)

    @property
    def n_faces(self) -> int:
        return len(self.faces)


class MeshBuilder:
    """Accumulates mesh parts (vertices, faces, material, uv, colours) into a :class:`SceneMesh`."""

    def __init__(self) -> None:
        self._parts: list[tuple] = []
        self._n_vertices = 0

    def add(self, vertices, faces, material: int, uv=None, colours=None) -> None:
        v = np.asarray(vertices, dtype=np.float32).reshape(-1, 3)
        f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        uv = np.zeros((len(v), 2), np.float32) if uv is None else np.asarray(uv, np.float32)
        if colours is None:
            colours = np.ones((len(v), 3), np.float32)
        colours = np.broadcast_to(np.asarray(colours, np.float32), (len(v), 3))
        self._parts.append((v, f + self._n_vertices, np.full(len(f), material, np.int32), uv,
                            colours))
        self._n_vertices += len(v)

    def add_mesh(self, mesh: tuple, material: int, colours=None) -> None:
        """Add a ``(vertices, faces, uv)`` triple from the helpers of this module."""
        self.add(mesh[0], mesh[1], material, mesh[2], colours)

    def build(self) -> SceneMesh:
        if not self._parts:
            return SceneMesh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32),
                             np.zeros(0, np.int32), np.zeros((0, 2), np.float32),
                             np.zeros((0, 3), np.float32))
        v, f, m, uv, c = (np.concatenate(x) for x in zip(*self._parts))
        return SceneMesh(v.astype(np.float32), f.astype(np.int32), m.astype(np.int32),
                         uv.astype(np.float32), np.ascontiguousarray(c, np.float32))


def textured_quad(origin, edge_u, edge_v, n_u: int = 1, n_v: int = 1, uv_rect=None):
    """A planar quad ``origin + s edge_u + t edge_v`` in ``n_u x n_v`` cells (two triangles
    each), facing ``edge_u x edge_v``. ``uv_rect = (u0, v0, u1, v1)`` maps ``s`` to
    ``u0..u1`` and ``t`` to ``v1..v0`` (atlas images have their top row at ``v0``, and
    ``edge_v`` points up on walls). Returns ``(vertices, faces, uv)``."""
    n_u = max(int(n_u), 1)
    n_v = max(int(n_v), 1)
    s = np.linspace(0.0, 1.0, n_u + 1)
    t = np.linspace(0.0, 1.0, n_v + 1)
    ss, tt = np.meshgrid(s, t, indexing="xy")
    verts = (np.asarray(origin, float) + ss[..., None] * np.asarray(edge_u, float)
             + tt[..., None] * np.asarray(edge_v, float)).reshape(-1, 3)
    ii, jj = np.meshgrid(np.arange(n_u), np.arange(n_v), indexing="xy")
    a = (jj * (n_u + 1) + ii).ravel()
    b = a + 1
    c = a + n_u + 1
    d = c + 1
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    if uv_rect is None:
        uv = np.zeros((len(verts), 2))
    else:
        u0, v0, u1, v1 = uv_rect
        uv = np.stack([u0 + ss.ravel() * (u1 - u0), v1 - tt.ravel() * (v1 - v0)], 1)
    return verts.astype(np.float32), faces.astype(np.int32), uv.astype(np.float32)


def cells_along(length: float, cell: float) -> int:
    """Number of cells of at most ``cell`` metres that cover ``length``."""
    return max(1, int(math.ceil(abs(length) / cell - 1e-9)))


def _merge(parts):
    """Concatenate ``(vertices, faces, uv)`` parts into one, renumbering the faces."""
    verts, faces, uvs, n = [], [], [], 0
    for v, f, uv in parts:
        verts.append(v)
        faces.append(f + n)
        uvs.append(uv)
        n += len(v)
    return (np.concatenate(verts).astype(np.float32), np.concatenate(faces).astype(np.int32),
            np.concatenate(uvs).astype(np.float32))


def box_mesh(lo, hi, *, cell: float = 1.0, yaw: float = 0.0, pivot=(0.0, 0.0, 0.0),
             skip=(), uv_faces: dict | None = None):
    """Axis-aligned box ``lo..hi`` (outward faces), optionally turned by ``yaw`` about the
    vertical through ``pivot``. ``skip``: faces to leave out ('-x', '+x', '-y', '+y', '-z',
    '+z'); ``uv_faces``: atlas rectangles per face name. Returns ``(vertices, faces, uv)``."""
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    dx, dy, dz = hi - lo
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    uv_faces = uv_faces or {}
    spec = {
        "+x": ((x1, y0, z1), (0, 0, -dz), (0, dy, 0)),
        "-x": ((x0, y0, z0), (0, 0, dz), (0, dy, 0)),
        "+y": ((x0, y1, z1), (dx, 0, 0), (0, 0, -dz)),
        "-y": ((x0, y0, z0), (dx, 0, 0), (0, 0, dz)),
        "+z": ((x0, y0, z1), (dx, 0, 0), (0, dy, 0)),
        "-z": ((x1, y0, z0), (-dx, 0, 0), (0, dy, 0)),
    }
    parts = []
    for name, (o, eu, ev) in spec.items():
        if name in skip:
            continue
        nu = cells_along(np.linalg.norm(eu), cell)
        nv = cells_along(np.linalg.norm(ev), cell)
        parts.append(textured_quad(o, eu, ev, nu, nv, uv_faces.get(name)))
    v, f, uv = _merge(parts)
    if yaw:
        v = turn_yaw(v, yaw, pivot)
    return v, f, uv


def turn_yaw(vertices, yaw: float, pivot) -> np.ndarray:
    """Rotate points about the vertical axis through ``pivot`` (positive: +z towards +x)."""
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    p = np.asarray(pivot, float)
    return ((np.asarray(vertices, float) - p) @ rot.T + p).astype(np.float32)


def uv_sphere(centre, radii, n_lat: int = 10, n_lon: int = 16, *, split_lon: bool = False):
    """An ellipsoid (outward faces) with ``n_lat`` bands and ``n_lon`` segments. With
    ``split_lon`` every segment gets its own vertices (for sharp per-segment colours); uv
    holds (segment index, band index). Returns ``(vertices, faces, uv)``."""
    centre = np.asarray(centre, float)
    radii = np.broadcast_to(np.asarray(radii, float), (3,))
    lat = np.linspace(0.0, math.pi, n_lat + 1)
    parts = []
    if split_lon:
        for k in range(n_lon):
            lon = np.array([k, k + 1]) * 2 * math.pi / n_lon
            la, lo_ = np.meshgrid(lat, lon, indexing="ij")
            v = np.stack([np.sin(la) * np.sin(lo_), np.cos(la), np.sin(la) * np.cos(lo_)], -1)
            v = (v.reshape(-1, 3) * radii + centre)
            i = np.arange(n_lat)
            a, b, c, d = 2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3
            f = np.concatenate([np.stack([a, c, d], 1), np.stack([a, d, b], 1)])
            uv = np.tile([k, 0.0], (len(v), 1))
            parts.append((v, f, uv))
        return _merge(parts)
    lon = np.linspace(0.0, 2 * math.pi, n_lon + 1)
    la, lo_ = np.meshgrid(lat, lon, indexing="ij")
    v = np.stack([np.sin(la) * np.sin(lo_), np.cos(la), np.sin(la) * np.cos(lo_)], -1)
    v = v.reshape(-1, 3) * radii + centre
    ii, jj = np.meshgrid(np.arange(n_lat), np.arange(n_lon), indexing="ij")
    a = (ii * (n_lon + 1) + jj).ravel()
    b = a + 1
    c = a + n_lon + 1
    d = c + 1
    f = np.concatenate([np.stack([a, c, d], 1), np.stack([a, d, b], 1)])
    return v.astype(np.float32), f.astype(np.int32), np.zeros((len(v), 2), np.float32)


def cone_mesh(base, radius_bottom: float, radius_top: float, height: float, n: int = 16,
              cap: bool = True):
    """A (truncated) cone standing on ``base``, with a top cap unless ``cap`` is false.
    Returns ``(vertices, faces, uv)``."""
    base = np.asarray(base, float)
    ang = np.linspace(0.0, 2 * math.pi, n + 1)[:-1]
    ring = np.stack([np.sin(ang), np.zeros(n), np.cos(ang)], 1)
    bottom = base + ring * radius_bottom
    top = base + ring * radius_top + [0.0, height, 0.0]
    v = np.concatenate([bottom, top, [base + [0.0, height, 0.0]]])
    k = np.arange(n)
    k1 = (k + 1) % n
    f = [np.stack([k, k1, n + k1], 1), np.stack([k, n + k1, n + k], 1)]
    if cap:
        f.append(np.stack([n + k, n + k1, np.full(n, 2 * n)], 1))
    return v.astype(np.float32), np.concatenate(f).astype(np.int32), np.zeros((len(v), 2),
                                                                               np.float32)


def ball_mesh(centre, radius: float, spin: float = 0.0, axis_yaw: float = 0.0):
    """A beach ball: an 8-segment sphere rolled by ``spin`` radians about a horizontal axis
    at ``axis_yaw``. Returns ``(vertices, faces, segment index per vertex)``."""
    v, f, uv = uv_sphere((0.0, 0.0, 0.0), radius, 10, 8, split_lon=True)
    c, s = math.cos(spin), math.sin(spin)
    roll = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])  # about +x
    v = v @ roll.T
    v = turn_yaw(v, axis_yaw, (0.0, 0.0, 0.0)) + np.asarray(centre, np.float32)
    return v.astype(np.float32), f, uv[:, 0].astype(np.int32)

