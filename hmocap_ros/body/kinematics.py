"""Batched forward kinematics (eq. 2.11) and linear blend skinning (eq. 2.12).

Shapes: B poses, J joints, V vertices, K joints per vertex (sparse weights).  Rest joints
and rest vertices may be shared, (J, 3) / (V, 3), or per pose, (B, J, 3) / (B, V, 3), which
is how anthropometric shapes (``anthropometry.apply_shape``) enter.

Skinning is computed as v'_i = sum_j w_ij (G_j v_i + p_j - G_j r_j): the per-vertex blend
of the 3x4 bone matrices M_j = [G_j | p_j - G_j r_j] applied to the rest vertex.  Two
backends give the same numbers (float32): ``numba`` (loop over the sparse weights, parallel
for large batches; the default when numba is importable) and ``numpy`` (dense BLAS product).
"""
from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

try:  # numba is a dependency of the package, but keep the numpy path importable alone
    import numba
    from numba import njit, prange
except ImportError:  # pragma: no cover
    numba = None  # type: ignore[assignment]  # None marks numba absent: the numpy backend runs alone

# numba's default "workqueue" threading layer aborts on concurrent parallel launches from
# several Python threads (e.g. a multi-threaded rclpy executor): serialise the kernel.
_KERNEL_LOCK = threading.Lock()


@dataclass(frozen=True, eq=False)
class SparseWeights:
    """Skinning weights as K (joint, weight) pairs per vertex, heaviest first, 0-padded."""

    index: np.ndarray  # (V, K) int32
    value: np.ndarray  # (V, K) float32

    @classmethod
    def from_dense(cls, weights: np.ndarray) -> "SparseWeights":
        w = np.asarray(weights, dtype=np.float32)
        k = max(1, int((w > 0).sum(axis=1).max()))
        order = np.argsort(-w, axis=1, kind="stable")[:, :k]
        value = np.take_along_axis(w, order, axis=1)
        index = np.where(value > 0, order, 0).astype(np.int32)
        return cls(np.ascontiguousarray(index), np.ascontiguousarray(value, dtype=np.float32))

    def to_dense(self, n_joints: int) -> np.ndarray:
        out = np.zeros((len(self.index), n_joints), dtype=np.float32)
        np.add.at(out, (np.arange(len(self.index))[:, None], self.index), self.value)
        return out


def forward_kinematics(local_rotations: np.ndarray, root_translation: np.ndarray,
                       joints_rest: np.ndarray, parents: np.ndarray) -> tuple:
    """Global joint transforms (B, J, 4, 4) and positions (B, J, 3) (eq. 2.11).

    G_0 = R_0, p_0 = root translation (the world position of the root joint);
    G_j = G_parent R_j and p_j = p_parent + G_parent (r_j - r_parent), where r are the
    (possibly shape-scaled) rest joints, (J, 3) or (B, J, 3).  parents[j] < j.
    """
    rot = np.asarray(local_rotations, dtype=np.float64)
    n, nj = rot.shape[:2]
    rest = np.asarray(joints_rest, dtype=np.float64)
    parents = np.asarray(parents)
    offsets = rest - rest[..., np.maximum(parents, 0), :]
    offsets = np.broadcast_to(offsets, (n, nj, 3))
    g = np.empty((n, nj, 3, 3))
    p = np.empty((n, nj, 3))
    g[:, 0] = rot[:, 0]
    p[:, 0] = np.broadcast_to(np.asarray(root_translation, dtype=np.float64), (n, 3))
    for j in range(1, nj):
        q = parents[j]
        g[:, j] = g[:, q] @ rot[:, j]
        p[:, j] = p[:, q] + np.einsum("bik,bk->bi", g[:, q], offsets[:, j])
    transforms = np.zeros((n, nj, 4, 4))
    transforms[..., :3, :3] = g
    transforms[..., :3, 3] = p
    transforms[..., 3, 3] = 1.0
    return transforms, p


def skinning_matrices(transforms: np.ndarray, joints_rest: np.ndarray) -> np.ndarray:
    """Bone matrices M_j = [G_j | p_j - G_j r_j] (B, J, 3, 4) mapping rest space to posed."""
    g = transforms[..., :3, :3]
    p = transforms[..., :3, 3]
    rest = np.asarray(joints_rest, dtype=np.float64)
    out = np.empty(transforms.shape[:-2] + (3, 4))
    out[..., :3] = g
    out[..., 3] = p - np.einsum("...ik,...k->...i", g, np.broadcast_to(rest, p.shape))
    return out


def end_site_positions(transforms: np.ndarray, end_sites_rest: np.ndarray,
                       end_site_parents: np.ndarray, joints_rest: np.ndarray) -> np.ndarray:
    """Posed end sites (B, E, 3): rigidly attached to their parent joint."""
    par = np.asarray(end_site_parents)
    parent_tf = transforms[:, par]
    g = parent_tf[..., :3, :3]
    p = parent_tf[..., :3, 3]
    rest = np.asarray(joints_rest, dtype=np.float64)
    ends = np.asarray(end_sites_rest, dtype=np.float64)
    off = np.broadcast_to(ends - rest[..., par, :], p.shape)
    return p + np.einsum("beik,bek->bei", g, off)


# Below this many vertex evaluations (poses x vertices) one thread is faster: waking the
# worker threads costs more than the work, and on a loaded machine far more.
PARALLEL_MIN_WORK = 1 << 18

if numba is not None:
    # Two copies of one loop (serial / parallel): a shared helper function defeats numba's
    # optimisation of the inner loop, so the body is written out twice (docs/development.md,
    # "Costs the code is shaped by").

    @njit(fastmath=True, cache=True)
    def _lbs_serial(mats, verts, index, value, out):  # pragma: no cover - compiled
        n_vert = index.shape[0]
        shared = verts.shape[0] == 1
        for t in range(mats.shape[0] * n_vert):
            b = t // n_vert
            v = t - b * n_vert
            vb = 0 if shared else b
            a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = a8 = a9 = a10 = a11 = np.float32(0.0)
            for k in range(index.shape[1]):
                w = value[v, k]
                if w == 0.0:
                    break
                j = index[v, k]
                a0 += w * mats[b, j, 0]
                a1 += w * mats[b, j, 1]
                a2 += w * mats[b, j, 2]
                a3 += w * mats[b, j, 3]
                a4 += w * mats[b, j, 4]
                a5 += w * mats[b, j, 5]
                a6 += w * mats[b, j, 6]
                a7 += w * mats[b, j, 7]
                a8 += w * mats[b, j, 8]
                a9 += w * mats[b, j, 9]
                a10 += w * mats[b, j, 10]
                a11 += w * mats[b, j, 11]
            x = verts[vb, v, 0]
            y = verts[vb, v, 1]
            z = verts[vb, v, 2]
            out[b, v, 0] = a0 * x + a1 * y + a2 * z + a3
            out[b, v, 1] = a4 * x + a5 * y + a6 * z + a7
            out[b, v, 2] = a8 * x + a9 * y + a10 * z + a11

    @njit(parallel=True, fastmath=True, cache=True)
    def _lbs_parallel(mats, verts, index, value, out):  # pragma: no cover - compiled
        n_vert = index.shape[0]
        shared = verts.shape[0] == 1
        for t in prange(mats.shape[0] * n_vert):
            b = t // n_vert
            v = t - b * n_vert
            vb = 0 if shared else b
            a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = a8 = a9 = a10 = a11 = np.float32(0.0)
            for k in range(index.shape[1]):
                w = value[v, k]
                if w == 0.0:
                    break
                j = index[v, k]
                a0 += w * mats[b, j, 0]
                a1 += w * mats[b, j, 1]
                a2 += w * mats[b, j, 2]
                a3 += w * mats[b, j, 3]
                a4 += w * mats[b, j, 4]
                a5 += w * mats[b, j, 5]
                a6 += w * mats[b, j, 6]
                a7 += w * mats[b, j, 7]
                a8 += w * mats[b, j, 8]
                a9 += w * mats[b, j, 9]
                a10 += w * mats[b, j, 10]
                a11 += w * mats[b, j, 11]
            x = verts[vb, v, 0]
            y = verts[vb, v, 1]
            z = verts[vb, v, 2]
            out[b, v, 0] = a0 * x + a1 * y + a2 * z + a3
            out[b, v, 1] = a4 * x + a5 * y + a6 * z + a7
            out[b, v, 2] = a8 * x + a9 * y + a10 * z + a11


def skin_vertices(skin_mats: np.ndarray, rest_vertices: np.ndarray, weights,
                  backend: str = "auto") -> np.ndarray:
    """Linear blend skinning, eq. 2.12: v'_i = sum_j w_ij M_j v_i  -> (B, V, 3) float32.

    skin_mats: (B, J, 3, 4) from ``skinning_matrices``; rest_vertices: (V, 3) or (B, V, 3);
    weights: dense (V, J) array or ``SparseWeights``.  backend: "numba", "numpy" or "auto".
    """
    mats = np.asarray(skin_mats)
    n, nj = mats.shape[:2]
    verts = np.asarray(rest_vertices, dtype=np.float32)
    if backend == "auto":
        backend = "numba" if numba is not None else "numpy"
    if backend == "numba":
        if numba is None:  # pragma: no cover
            raise RuntimeError("numba is not available")
        sw = weights if isinstance(weights, SparseWeights) else SparseWeights.from_dense(weights)
        v3 = verts.reshape((-1,) + verts.shape[-2:])
        if v3.shape[0] not in (1, n):
            raise ValueError("rest_vertices batch does not match the poses")
        out = np.empty((n, sw.index.shape[0], 3), dtype=np.float32)
        m12 = np.ascontiguousarray(mats.reshape(n, nj, 12), dtype=np.float32)
        v3 = np.ascontiguousarray(v3)
        if n * len(sw.index) < PARALLEL_MIN_WORK or numba.get_num_threads() == 1:
            _lbs_serial(m12, v3, sw.index, sw.value, out)
        else:
            with _KERNEL_LOCK:
                _lbs_parallel(m12, v3, sw.index, sw.value, out)
        return out
    if backend != "numpy":
        raise ValueError(f"unknown backend {backend!r}")
    dense = weights.to_dense(nj) if isinstance(weights, SparseWeights) else np.asarray(weights, np.float32)
    # per-vertex blended 3x4 matrices, one BLAS product per pose
    blended = np.matmul(dense, mats.reshape(n, nj, 12).astype(np.float32)).reshape(n, -1, 3, 4)
    x, y, z = verts[..., 0, None], verts[..., 1, None], verts[..., 2, None]
    out = blended[..., 3] + blended[..., 0] * x + blended[..., 1] * y + blended[..., 2] * z
    return out.astype(np.float32, copy=False)
