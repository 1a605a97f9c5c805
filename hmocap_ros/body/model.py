"""The skinned body model shipped with the package (MakeHuman hm08, CC0; see data/).

``load_body_model("tracking")`` gives the 2,400-triangle body with 19 joints used by the
tracker and the multi-view simulator; ``load_body_model("tracking_coarse")`` the same body
and joints decimated to 1,000 triangles, which the tracker can render its particles with
(``TrackerParams.mesh``: about twice as fast); ``load_body_model("hands")`` the 12,000-triangle
body with 5 three-segment fingers per hand (49 joints) for depth gesture rendering.
All three share the frame of ``skeleton.py`` (metres, +Y up, facing +Z, +X = person's left,
feet on y = 0, A-pose rest) and identical body joints.

    model = load_body_model("tracking")
    params = rest_pose(model.skeleton)[None]          # (B, D)
    verts, joints = model.pose(params)                # (B, V, 3), (B, J, 3)
    verts, joints = model.pose(params, sample_shape(rng))
"""
from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np

from .kinematics import SparseWeights, end_site_positions, forward_kinematics, skin_vertices, skinning_matrices
from .shape_deformation import ShapeFactors, apply_shape
from .skeleton import Skeleton, build_skeleton, pose_to_local_rotations, rest_pose

DATA_DIR = Path(__file__).resolve().parents[1] / "data"
MODEL_FILES = {"tracking": "body_tracking.npz", "tracking_coarse": "body_tracking_coarse.npz",
               "hands": "body_hands.npz"}
DEFAULT_DOFS = {"tracking": "tracking", "tracking_coarse": "tracking", "hands": "full"}
REQUIRED_KEYS = ("vertices", "faces", "joint_names", "parents", "joints_rest", "weights",
                 "end_site_names", "end_site_parents", "end_sites_rest", "meta")


@dataclass(frozen=True, eq=False)
class PoseResult:
    """Everything one posing produces (batched over B)."""

    vertices: np.ndarray  # (B, V, 3) float32
    joints: np.ndarray  # (B, J, 3)
    end_sites: np.ndarray  # (B, E, 3)
    transforms: np.ndarray  # (B, J, 4, 4) global joint transforms


@dataclass(frozen=True, eq=False)
class BodyModel:
    """Rest mesh, skeleton and skinning weights of one body asset (arrays read-only)."""

    name: str
    vertices: np.ndarray  # (V, 3) float32, rest pose
    faces: np.ndarray  # (F, 3) int32, outward winding
    joint_names: tuple
    parents: np.ndarray  # (J,) parent index, -1 for the root
    joints_rest: np.ndarray  # (J, 3)
    weights: np.ndarray  # (V, J) float32, rows sum to 1
    vertex_part: np.ndarray  # (V,) index of the dominant joint (body-part label)
    end_site_names: tuple
    end_site_parents: np.ndarray
    end_sites_rest: np.ndarray
    landmarks: dict
    skeleton: Skeleton
    meta: dict

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def height(self) -> float:
        return float(self.vertices[:, 1].max() - self.vertices[:, 1].min())

    @cached_property
    def sparse_weights(self) -> SparseWeights:
        return SparseWeights.from_dense(self.weights)

    def joint_index(self, name: str) -> int:
        return self.joint_names.index(name)

    def rest_pose(self, shape: ShapeFactors | None = None) -> np.ndarray:
        """Parameters that reproduce the (shaped) rest mesh standing on the floor.

        The root translation is the world pelvis position, so a shape with longer legs
        needs a higher pelvis: (D,) for one shape, (B, D) for a batch of shapes.
        """
        params = rest_pose(self.skeleton)
        if shape is None:
            return params
        pelvis = np.asarray(apply_shape(self, shape).joints)[..., 0, :]
        params = np.broadcast_to(params, pelvis.shape[:-1] + params.shape).copy()
        params[..., self.skeleton.translation_dofs] = pelvis
        return params

    def with_dofs(self, dof_set: str) -> "BodyModel":
        """The same mesh with another DoF set ("tracking" or "full")."""
        return load_body_model(self.name, dof_set)

    def with_mesh(self, name: str) -> "BodyModel":
        """The shipped mesh ``name`` on this model's skeleton and DoF set.

        The joints, end sites, landmarks and DoFs must be identical (as for "tracking" and
        "tracking_coarse", both built from one rig), so a pose vector means the same on both;
        raises ValueError otherwise. A BodyShape's factors scale each mesh's own surface, so
        surface sizes differ a little between meshes (the neutral "tracking_coarse" torso is
        thinner front to back): measure a shape on the mesh it was estimated with.
        """
        if name == self.name:
            return self
        other = load_body_model(name, self.skeleton.dof_set)
        a, b = self.skeleton, other.skeleton
        same = (other.joint_names == self.joint_names
                and other.end_site_names == self.end_site_names
                and np.array_equal(other.parents, self.parents)
                and np.array_equal(other.joints_rest, self.joints_rest)
                and np.array_equal(other.end_site_parents, self.end_site_parents)
                and np.array_equal(other.end_sites_rest, self.end_sites_rest)
                and other.landmarks.keys() == self.landmarks.keys()
                and all(np.array_equal(other.landmarks[k], v) for k, v in self.landmarks.items())
                and b.dof_names == a.dof_names
                and np.array_equal(b.lower, a.lower) and np.array_equal(b.upper, a.upper))
        if not same:
            raise ValueError(f"body mesh {name!r} has another skeleton than {self.name!r}; "
                             "a tracker can only swap meshes built on the same joints")
        return other

    def forward(self, params: np.ndarray, shape: ShapeFactors | None = None,
                backend: str = "auto") -> PoseResult:
        """Pose B parameter vectors (B, D) with an optional shape (one, or a batch of B).

        eq. 2.11 (kinematic chain) then eq. 2.12 (LBS) on the shaped rest mesh.
        """
        params = np.asarray(params, dtype=np.float64)
        if params.ndim == 1:
            params = params[None]
        rest = apply_shape(self, shape)
        rot, root_t = pose_to_local_rotations(self.skeleton, params)
        transforms, joints = forward_kinematics(rot, root_t, rest.joints, self.parents)
        mats = skinning_matrices(transforms, rest.joints)
        verts = skin_vertices(mats, rest.vertices, self.sparse_weights, backend=backend)
        ends = end_site_positions(transforms, rest.end_sites, self.end_site_parents, rest.joints)
        return PoseResult(verts, joints, ends, transforms)

    def pose(self, params: np.ndarray, shape: ShapeFactors | None = None,
             backend: str = "auto") -> tuple:
        """(vertices (B, V, 3) float32, joints (B, J, 3)); a (D,) vector gives (V, 3), (J, 3)."""
        single = np.ndim(params) == 1
        res = self.forward(params, shape, backend)
        if single:
            return res.vertices[0], res.joints[0]
        return res.vertices, res.joints


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


def read_body_model(path: str | Path, name: str = "custom", dof_set: str = "tracking") -> BodyModel:
    """Load a body asset file written by tools/build_body_model.py (clear errors if corrupt)."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in REQUIRED_KEYS if k not in z.files]
            if missing:
                raise ValueError(f"{path}: missing keys {missing}")
            data = {k: z[k] for k in z.files}
    except (OSError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path}: cannot read body model ({exc})") from exc
    verts = data["vertices"].astype(np.float32)
    faces = data["faces"].astype(np.int32)
    weights = data["weights"].astype(np.float32)
    names = tuple(str(n) for n in data["joint_names"])
    if weights.shape != (len(verts), len(names)):
        raise ValueError(f"{path}: weights shape {weights.shape} != ({len(verts)}, {len(names)})")
    if faces.min() < 0 or faces.max() >= len(verts):
        raise ValueError(f"{path}: face indices out of range")
    if not np.allclose(weights.sum(axis=1), 1.0, atol=1e-4):
        raise ValueError(f"{path}: skinning weights do not sum to 1")
    end_names = tuple(str(n) for n in data["end_site_names"])
    landmarks = {}
    if "landmark_names" in data:
        landmarks = {str(n): p.astype(np.float64)
                     for n, p in zip(data["landmark_names"], data["landmarks_rest"])}
    part = data.get("vertex_part")
    if part is None:
        part = np.argmax(weights, axis=1)
    skeleton = build_skeleton(names, data["parents"], data["joints_rest"], end_names,
                              data["end_site_parents"], data["end_sites_rest"], landmarks,
                              dof_set=dof_set)
    return BodyModel(
        name=name, vertices=_readonly(verts), faces=_readonly(faces), joint_names=names,
        parents=_readonly(data["parents"].astype(np.intp)),
        joints_rest=_readonly(data["joints_rest"].astype(np.float64)),
        weights=_readonly(weights), vertex_part=_readonly(part.astype(np.intp)),
        end_site_names=end_names,
        end_site_parents=_readonly(data["end_site_parents"].astype(np.intp)),
        end_sites_rest=_readonly(data["end_sites_rest"].astype(np.float64)),
        landmarks=landmarks, skeleton=skeleton, meta=json.loads(str(data["meta"])))


def load_body_model(name: str = "tracking", dof_set: str | None = None) -> BodyModel:
    """Shipped model "tracking" or "tracking_coarse" (default DoFs: tracking set) or "hands"
    (full set).

    Cached: repeated calls return the same (immutable) object.
    """
    if name not in MODEL_FILES:
        raise ValueError(f"unknown body model {name!r}; choose one of {sorted(MODEL_FILES)}")
    return _load_cached(name, dof_set or DEFAULT_DOFS[name])


@lru_cache(maxsize=None)
def _load_cached(name: str, dof_set: str) -> BodyModel:
    return read_body_model(DATA_DIR / MODEL_FILES[name], name, dof_set)
