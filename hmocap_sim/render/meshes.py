"""Small mesh helpers for rendering: concatenation with face ranges, face and vertex normals."""

from __future__ import annotations

import numpy as np


def concatenate_meshes(meshes):
    """Concatenate meshes given as ``(vertices (V_i, 3), faces (F_i, 3))`` pairs.

    Returns ``(vertices (V, 3) float32, faces (F, 3) int32, face_offsets (n + 1,) int64,
    vertex_offsets (n + 1,) int64)``: mesh ``i`` owns faces
    ``face_offsets[i]:face_offsets[i + 1]`` (use with
    :func:`hmocap_sim.render.rasterize.face_range_mask`) and the matching vertex range.
    """
    meshes = list(meshes)
    verts = [np.asarray(v, dtype=np.float32).reshape(-1, 3) for v, _ in meshes]
    faces = [np.asarray(f, dtype=np.int64).reshape(-1, 3) for _, f in meshes]
    vertex_offsets = np.concatenate([[0], np.cumsum([len(v) for v in verts])]).astype(np.int64)
    face_offsets = np.concatenate([[0], np.cumsum([len(f) for f in faces])]).astype(np.int64)
    all_faces = [f + o for f, o in zip(faces, vertex_offsets[:-1])]
    return (np.concatenate(verts) if verts else np.zeros((0, 3), np.float32),
            (np.concatenate(all_faces) if all_faces else np.zeros((0, 3))).astype(np.int32),
            face_offsets, vertex_offsets)


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit normals ``(F, 3)`` float32 of counter-clockwise (right-handed) triangles."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return (n / np.where(norm > 0, norm, 1.0)).astype(np.float32)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals ``(V, 3)`` float32 (for smooth shading)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    acc = np.zeros_like(v)
    for k in range(3):
        np.add.at(acc, f[:, k], n)
    norm = np.linalg.norm(acc, axis=1, keepdims=True)
    return (acc / np.where(norm > 0, norm, 1.0)).astype(np.float32)


def grid_quad(origin, edge_u, edge_v, n_u: int, n_v: int):
    """A planar quad ``origin + s * edge_u + t * edge_v`` (s, t in [0, 1]) tessellated into
    ``n_u x n_v`` cells (2 triangles each), counter-clockwise seen from ``edge_u x edge_v``.
    Room walls and floors need this: the rasteriser does not clip at the near plane and lens
    distortion bends straight lines. Returns ``(vertices, faces)``."""
    origin = np.asarray(origin, dtype=np.float64)
    s = np.linspace(0.0, 1.0, n_u + 1)
    t = np.linspace(0.0, 1.0, n_v + 1)
    ss, tt = np.meshgrid(s, t, indexing="xy")
    verts = (origin + ss[..., None] * np.asarray(edge_u, float)
             + tt[..., None] * np.asarray(edge_v, float)).reshape(-1, 3)
    i = np.arange(n_u)
    j = np.arange(n_v)
    ii, jj = np.meshgrid(i, j, indexing="xy")
    a = (jj * (n_u + 1) + ii).ravel()
    b = a + 1
    c = a + n_u + 1
    d = c + 1
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    return verts.astype(np.float32), faces.astype(np.int32)
