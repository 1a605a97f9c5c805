"""Silhouette XOR weighting of body particles over all views (thesis eq. 2.8, 2.14, 2.15).

The hot path of the body tracker: a batch of N pose vectors ``(N, D)`` is posed (eq. 2.11 and
LBS, eq. 2.12, on a shaped rest mesh), projected into the M available views at a working
resolution, and each (particle, view) silhouette is compared with the observed foreground mask
by the fused numba scan-fill of :func:`hmocap_ros.render.xor_counts`. Nothing loops over
particles in Python. The cost of a particle is

    eq. 2.8 / 2.14:  c = sum_v XOR(M_v, S_v) / C(S_v)               (whole image)
    eq. 2.15:        c = sum_v XOR(M_v, S_v, Omega_v) / |Omega_v|   (inside a box per view)

and its weight ``w = exp(-beta c)`` (:mod:`hmocap_ros.lpf.layered_filter`).

Working resolution: the foreground masks (full camera resolution, any non-zero value is
foreground) are reduced by area averaging to ``working_scale`` of their size and thresholded
at one half (:func:`downsample_mask`), and the cameras are scaled with the same half-pixel
convention (:meth:`PinholeCamera.scaled`), so the model and the observation stay registered.
At 1/4 (160x120 from 640x480) a person covers a few hundred pixels per view.

Missing views: a mask that is ``None`` or has the wrong size is left out of the
:class:`Observation` (its index is listed in ``dropped``); the cost is the sum over the views
that remain. ``C(S_v)`` is floored at ``min_count`` pixels so that a view in which the person
is hidden or outside the field of view does not divide by zero.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numba
import numpy as np

from hmocap_ros.body.anthropometry import BodyShape, ShapedRest, apply_shape
from hmocap_ros.body.kinematics import forward_kinematics, skin_vertices, skinning_matrices
from hmocap_ros.body.model import BodyModel
from hmocap_ros.body.skeleton import pose_to_local_rotations
from hmocap_ros.geometry.projection import project_batch
from hmocap_ros.geometry.rig import camera_arrays
from hmocap_ros.render import xor_counts
from hmocap_ros.render.fused_xor import xor_counts_from_vertices

__all__ = ["Observation", "SilhouetteFitness", "StageTimes", "downsample_mask", "posed_mesh",
           "serial_below"]

#: Below this many (particle, view) pairs the numba kernels run on the calling thread: waking
#: the worker threads costs more than such a batch takes (a Powell evaluation of the start-up;
#: docs/development.md, "Costs the code is shaped by").
SERIAL_BELOW = 256


@contextmanager
def serial_below(n_items: int, limit: int = SERIAL_BELOW):
    """Run numba's parallel kernels single-threaded inside the block when ``n_items < limit``."""
    if n_items >= limit or numba.get_num_threads() == 1:
        yield
        return
    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(previous)


def downsample_mask(mask: np.ndarray, width: int, height: int) -> np.ndarray:
    """Foreground mask reduced to ``width x height`` by area averaging, thresholded at 1/2.

    Any non-zero input pixel is foreground. Returns uint8 {0, 1}. ``cv2.INTER_AREA`` uses the
    pixel-centre convention of :meth:`PinholeCamera.scaled` (``u' = s (u + 0.5) - 0.5``).
    """
    m = np.asarray(mask)
    if m.ndim == 3:
        m = m[..., 0]
    if m.shape == (height, width):
        return (m != 0).astype(np.uint8)
    src = (m != 0).astype(np.float32)
    small = cv2.resize(src, (int(width), int(height)), interpolation=cv2.INTER_AREA)
    return (small >= 0.5).astype(np.uint8)


def posed_mesh(model, params: np.ndarray, rest: ShapedRest) -> tuple[np.ndarray, np.ndarray]:
    """Pose N parameter vectors on a shaped rest mesh: ``(vertices (N, V, 3) float32,
    joints (N, J, 3))`` (eq. 2.11, 2.12).

    ``rest`` is one shape (``vertices (V, 3)``, ``joints (J, 3)``) or one per particle
    (``(N, V, 3)``, ``(N, J, 3)``), as returned by :func:`apply_shape`; computing it once per
    shape rather than per call is what this function saves over ``BodyModel.pose``.
    """
    params = np.asarray(params, dtype=np.float64)
    rot, root_t = pose_to_local_rotations(model.skeleton, params)
    transforms, joints = forward_kinematics(rot, root_t, rest.joints, model.parents)
    mats = skinning_matrices(transforms, rest.joints)
    verts = skin_vertices(mats, rest.vertices, model.sparse_weights)
    return verts, joints


@dataclass
class StageTimes:
    """Seconds spent per stage of the weighting function and how many particles it weighed."""

    skinning: float = 0.0
    projection: float = 0.0
    xor: float = 0.0
    evaluations: int = 0

    def reset(self) -> None:
        self.skinning = self.projection = self.xor = 0.0
        self.evaluations = 0

    def weighting_seconds(self) -> float:
        """Skinning + projection + XOR so far."""
        return self.skinning + self.projection + self.xor

    def as_dict(self) -> dict:
        return {"skinning_s": self.skinning, "projection_s": self.projection, "xor_s": self.xor,
                "evaluations": self.evaluations}


@dataclass(frozen=True, eq=False)
class Observation:
    """Foreground silhouettes of one frame set at the working resolution.

    masks: (M, h, w) uint8 {0, 1}, one per available view, in rig order.
    views: (M,) rig indices of those views; dropped: rig indices of missing/invalid masks.
    K, R, t, D: stacked working-resolution cameras of the available views.
    counts: C(S_v), foreground pixels per view (int64, (M,)).
    max_r2: per view, the squared normalised radius where the distortion stays monotonic.
    stamp_ns: the frame set's stamp.
    """

    masks: np.ndarray
    views: np.ndarray
    dropped: tuple
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    D: np.ndarray
    counts: np.ndarray
    stamp_ns: int = 0
    max_r2: np.ndarray | None = None

    @property
    def n_views(self) -> int:
        return int(self.masks.shape[0])

    @property
    def height(self) -> int:
        return int(self.masks.shape[1])

    @property
    def width(self) -> int:
        return int(self.masks.shape[2])


@dataclass(eq=False)
class SilhouetteFitness:
    """Silhouette XOR cost of body particles for one rig (eq. 2.8 and 2.15).

    model: the body model (``load_body_model("tracking")``).
    cameras: the rig's cameras at full resolution (a :class:`~hmocap_ros.geometry.rig.Rig` or a list).
    working_scale: image scale of the comparison (0.25: 640x480 -> 160x120).
    front_only: rasterise only front faces (exact for the closed body mesh, and faster).
    min_count: floor of ``C(S_v)`` in working-resolution pixels.
    times: accumulated :class:`StageTimes` (reset by the caller when it wants).
    """

    model: BodyModel
    cameras: Sequence
    working_scale: float = 0.25
    front_only: bool = True
    min_count: int = 20
    times: StageTimes = field(default_factory=StageTimes)

    def __post_init__(self) -> None:
        if not 0.0 < self.working_scale <= 1.0:
            raise ValueError(f"working_scale must lie in (0, 1], got {self.working_scale}")
        self.cameras = tuple(self.cameras)
        self.working = tuple(c.scaled(self.working_scale) for c in self.cameras)
        self._K, self._R, self._t, self._D = camera_arrays(self.working)
        self._max_r2 = np.array([c.max_normalized_radius2 for c in self.working])
        self.faces = np.ascontiguousarray(self.model.faces, dtype=np.int32)
        self._rest_cache: tuple | None = None

    # ------------------------------------------------------------------ observation

    def observe(self, masks: Sequence[np.ndarray | None], stamp_ns: int = 0) -> Observation:
        """Working-resolution observation from one foreground mask per rig camera.

        A mask that is None or whose size is neither the camera's full nor its working
        resolution is dropped (listed in ``Observation.dropped``), never an error. Views of
        different sizes are stacked padded at the right and bottom to the largest (below).
        """
        if len(masks) != len(self.cameras):
            raise ValueError(f"expected {len(self.cameras)} masks (one per camera, None for a "
                             f"missing one), got {len(masks)}")
        kept, dropped, small = [], [], []
        for i, (mask, full, work) in enumerate(zip(masks, self.cameras, self.working)):
            if mask is None:
                dropped.append(i)
                continue
            shape = np.shape(mask)[:2]
            if shape not in ((full.height, full.width), (work.height, work.width)):
                dropped.append(i)
                continue
            kept.append(i)
            small.append(downsample_mask(mask, work.width, work.height))
        views = np.asarray(kept, dtype=np.intp)
        if small:
            stack = _stack_padded(small)
        else:
            w = self.working[0]
            stack = np.zeros((0, w.height, w.width), dtype=np.uint8)
        counts = stack.sum(axis=(1, 2), dtype=np.int64)
        return Observation(masks=stack, views=views, dropped=tuple(dropped), K=self._K[views],
                           R=self._R[views], t=self._t[views], D=self._D[views], counts=counts,
                           stamp_ns=int(stamp_ns), max_r2=self._max_r2[views])

    # ------------------------------------------------------------------ posing

    def rest(self, shape: BodyShape | None) -> ShapedRest:
        """Shaped rest geometry, cached for the last single shape seen."""
        if shape is not None and shape.batched:
            return apply_shape(self.model, shape)
        key = None if shape is None else tuple(shape.to_vector().round(12))
        if self._rest_cache is not None and self._rest_cache[0] == key:
            return self._rest_cache[1]
        rest = apply_shape(self.model, shape)
        rest = ShapedRest(np.ascontiguousarray(rest.vertices, dtype=np.float32),
                          np.asarray(rest.joints), np.asarray(rest.end_sites))
        self._rest_cache = (key, rest)
        return rest

    def pose(self, params: np.ndarray, shape: BodyShape | ShapedRest | None = None):
        """(vertices (N, V, 3), joints (N, J, 3)) of N particles, timed as "skinning"."""
        t0 = time.perf_counter()
        rest = shape if isinstance(shape, ShapedRest) else self.rest(shape)
        verts, joints = posed_mesh(self.model, np.atleast_2d(params), rest)
        self.times.skinning += time.perf_counter() - t0
        return verts, joints

    def project(self, verts: np.ndarray, obs: Observation) -> np.ndarray:
        """Vertices (N, V, 3) -> pixels (N, M, V, 2) in the observation's views."""
        t0 = time.perf_counter()
        uv, _ = project_batch(verts, obs.K, obs.R, obs.t, obs.D)
        self.times.projection += time.perf_counter() - t0
        return uv

    # ------------------------------------------------------------------ costs

    def view_xor(self, uv: np.ndarray, obs: Observation,
                 boxes: np.ndarray | None = None) -> np.ndarray:
        """XOR pixel counts (N, M) of projected particles, inside ``boxes`` (M, 4) if given."""
        t0 = time.perf_counter()
        out = xor_counts(uv, self.faces, obs.masks, boxes, front_only=self.front_only)
        self.times.xor += time.perf_counter() - t0
        self.times.evaluations += uv.shape[0]
        return out

    def normalisers(self, obs: Observation, boxes: np.ndarray | None = None) -> np.ndarray:
        """Per-view divisor: ``C(S_v)`` (eq. 2.8) or the box area ``|Omega_v|`` (eq. 2.15)."""
        if boxes is None:
            return np.maximum(obs.counts, self.min_count).astype(np.float64)
        b = np.asarray(boxes, dtype=np.float64)
        w = np.clip(np.floor(b[:, 2] + 0.5), 0, obs.width) - np.clip(np.floor(b[:, 0] + 0.5), 0, obs.width)
        h = np.clip(np.floor(b[:, 3] + 0.5), 0, obs.height) - np.clip(np.floor(b[:, 1] + 0.5), 0, obs.height)
        return np.maximum(w * h, float(self.min_count))

    def costs_from_uv(self, uv: np.ndarray, obs: Observation,
                      boxes: np.ndarray | None = None) -> np.ndarray:
        """Eq. 2.8 (``boxes`` None) or eq. 2.15 cost (N,) of projected particles."""
        if obs.n_views == 0:
            return np.zeros(uv.shape[0])
        xor = self.view_xor(uv, obs, boxes)
        return (xor / self.normalisers(obs, boxes)).sum(axis=1)

    def view_xor_from_verts(self, verts: np.ndarray, obs: Observation,
                            boxes: np.ndarray | None = None) -> np.ndarray:
        """XOR pixel counts (N, M) of posed meshes (N, V, 3), inside ``boxes`` if given
        (projection and scan-fill fused), timed as "xor"."""
        t0 = time.perf_counter()
        xor = xor_counts_from_vertices(verts, obs.K, obs.R, obs.t, obs.D, self.faces, obs.masks,
                                       boxes, front_only=self.front_only, max_r2=obs.max_r2)
        self.times.xor += time.perf_counter() - t0
        self.times.evaluations += verts.shape[0]
        return xor

    def costs_from_verts(self, verts: np.ndarray, obs: Observation,
                         boxes: np.ndarray | None = None) -> np.ndarray:
        """Eq. 2.8 / 2.15 cost (N,) of posed meshes (N, V, 3): projection and scan-fill fused
        (:func:`~hmocap_ros.render.fused_xor.xor_counts_from_vertices`; the same counts as
        :meth:`costs_from_uv` of :meth:`project`), timed as "xor"."""
        if obs.n_views == 0:
            return np.zeros(verts.shape[0])
        xor = self.view_xor_from_verts(verts, obs, boxes)
        return (xor / self.normalisers(obs, boxes)).sum(axis=1)

    def costs(self, params: np.ndarray, obs: Observation,
              shape: BodyShape | ShapedRest | None = None,
              boxes: np.ndarray | None = None) -> np.ndarray:
        """Silhouette XOR cost (N,) of pose particles (N, D): eq. 2.8, or eq. 2.15 in boxes.

        ``shape``: one BodyShape (cached), a batch of N shapes (anthropometry estimation), or
        a precomputed ShapedRest.
        """
        n = np.atleast_2d(params).shape[0]
        with serial_below(n * max(obs.n_views, 1)):
            verts, _ = self.pose(params, shape)
            return self.costs_from_verts(verts, obs, boxes)

    def mean_view_cost(self, cost: float | np.ndarray, obs: Observation):
        """Eq. 2.8 cost divided by the number of views: comparable across dropped cameras."""
        return np.asarray(cost) / max(obs.n_views, 1)


def _stack_padded(masks: list[np.ndarray]) -> np.ndarray:
    """The masks as one (V, H, W) array; a view smaller than the largest is padded with
    background at its right and bottom. Its pixels keep their coordinates, so its camera
    projects as it is; a body part beyond such a view's edge counts in the XOR as model
    without foreground (the renderer clips at the stack's size), a small pull into that
    view that same-size rigs do not have."""
    height = max(m.shape[0] for m in masks)
    width = max(m.shape[1] for m in masks)
    if all(m.shape == (height, width) for m in masks):
        return np.ascontiguousarray(np.stack(masks))
    out = np.zeros((len(masks), height, width), dtype=masks[0].dtype)
    for i, m in enumerate(masks):
        out[i, :m.shape[0], :m.shape[1]] = m
    return out
