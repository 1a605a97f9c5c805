"""A calibrated pinhole camera with OpenCV lens distortion, and :func:`look_at` to place one.

Frames and conventions (room frame, optical frame, pixels, depth) are those of
:mod:`hmocap_ros.geometry`; distortion is :mod:`hmocap_ros.geometry.distortion`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from hmocap_ros.geometry.distortion import DISTORTION_MODELS, coefficients8, monotonic_radius2, undistort_normalized
from hmocap_ros.geometry.projection import DEFAULT_MIN_DEPTH, project_points
from hmocap_ros.geometry.rotations import matrix_to_quaternion, quaternion_to_matrix

__all__ = ["ROOM_UP", "PinholeCamera", "look_at", "look_at_pose"]

#: Up axis of the room frame (metres, +Y up, floor at y = 0).
ROOM_UP = (0.0, 1.0, 0.0)

#: Tolerance on R^T R = I for a world->camera rotation.
_ROTATION_TOLERANCE = 1e-6


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=np.float64, copy=True)
    array.flags.writeable = False
    return array


def _validated_arrays(camera: PinholeCamera, where: str) -> dict[str, np.ndarray]:
    """The camera's K, D (padded to its model's length), R, t, rectification and projection as
    float64 arrays; ``ValueError`` (prefixed with ``where``) for a malformed one."""
    K = np.asarray(camera.K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise ValueError(f"{where}: K must be a finite 3x3 matrix, got shape {K.shape}")
    if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], (0.0, 0.0, 1.0)) or K[1, 0] != 0:
        raise ValueError(f"{where}: K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got {K.tolist()}")
    if camera.distortion_model not in DISTORTION_MODELS:
        raise ValueError(
            f"{where}: unsupported distortion_model {camera.distortion_model!r} "
            f"(supported: {', '.join(DISTORTION_MODELS)})"
        )
    D = np.asarray(camera.D, dtype=np.float64).reshape(-1)
    n = DISTORTION_MODELS[camera.distortion_model]
    if D.size > n or not np.all(np.isfinite(D)):
        raise ValueError(
            f"{where}: distortion_model {camera.distortion_model!r} takes at most {n} finite coefficients, "
            f"got {D.tolist()}"
        )
    D = np.pad(D, (0, n - D.size))
    R = np.asarray(camera.R, dtype=np.float64)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ValueError(f"{where}: R must be a finite 3x3 rotation, got shape {R.shape}")
    if not np.allclose(R @ R.T, np.eye(3), atol=_ROTATION_TOLERANCE) or np.linalg.det(R) < 0:
        raise ValueError(f"{where}: R is not a proper rotation matrix: {R.tolist()}")
    t = np.asarray(camera.t, dtype=np.float64).reshape(-1)
    if t.shape != (3,) or not np.all(np.isfinite(t)):
        raise ValueError(f"{where}: t must be 3 finite numbers, got {np.asarray(camera.t).tolist()}")
    rect = np.eye(3) if camera.rectification is None else np.asarray(camera.rectification, dtype=np.float64)
    if rect.shape != (3, 3):
        raise ValueError(f"{where}: rectification must be 3x3, got shape {rect.shape}")
    proj = (np.hstack([K, np.zeros((3, 1))]) if camera.projection is None
            else np.asarray(camera.projection, dtype=np.float64))
    if proj.shape != (3, 4):
        raise ValueError(f"{where}: projection must be 3x4, got shape {proj.shape}")
    return {"K": K, "D": D, "R": R, "t": t, "rectification": rect, "projection": proj}


@dataclass(frozen=True, eq=False)
class PinholeCamera:
    """A calibrated camera: intrinsics ``K``, OpenCV distortion ``D`` and its pose in the room.

    ``x_cam = R @ x_world + t`` maps room coordinates to the camera optical frame (x right,
    y down, z forward). Arrays are copied to float64 and made read-only. ``rectification`` and
    ``projection`` are the CameraInfo ``R`` and ``P`` (identity and ``[K | 0]`` for a monocular
    camera); they are carried for faithful round trips and not used for projection, which works
    on the raw (distorted) image like ``cv2.projectPoints``.

    Build one with :meth:`from_pose`, :func:`look_at` or :meth:`from_camera_info`; compare two
    with :meth:`isclose` (``==`` is identity, as arrays have no single truth value).
    """

    name: str
    width: int
    height: int
    K: np.ndarray
    D: np.ndarray = field(default_factory=lambda: np.zeros(5))
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    distortion_model: str = "plumb_bob"
    frame_id: str = ""
    rectification: np.ndarray | None = None
    projection: np.ndarray | None = None

    def __post_init__(self) -> None:
        where = f"camera {self.name!r}"
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"camera name must be a non-empty string, got {self.name!r}")
        for attr in ("width", "height"):
            value = getattr(self, attr)
            if isinstance(value, (bool, np.bool_)) or int(value) != value or int(value) <= 0:
                raise ValueError(f"{where}: {attr} must be a positive integer, got {value!r}")
            object.__setattr__(self, attr, int(value))
        for attr, value in _validated_arrays(self, where).items():
            object.__setattr__(self, attr, _readonly(value))
        if not self.frame_id:
            object.__setattr__(self, "frame_id", f"{self.name}_optical_frame")

    # ---- constructors -------------------------------------------------------------------

    @classmethod
    def from_pose(
        cls,
        name: str,
        width: int,
        height: int,
        K,
        position,
        quaternion_xyzw,
        D=(),
        distortion_model: str = "plumb_bob",
        frame_id: str = "",
        rectification=None,
        projection=None,
    ) -> "PinholeCamera":
        """Camera from its pose in the room: optical-frame origin ``position`` (metres) and
        orientation ``quaternion_xyzw`` (x, y, z, w; rotates optical-frame vectors into the room)."""
        try:
            R_wc = quaternion_to_matrix(quaternion_xyzw)
        except ValueError as error:
            raise ValueError(f"camera {name!r}: orientation: {error}") from None
        position = np.asarray(position, dtype=np.float64).reshape(-1)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise ValueError(f"camera {name!r}: position must be 3 finite numbers, got {position.tolist()}")
        R = R_wc.T
        return cls(
            name=name, width=width, height=height, K=K, D=D, R=R, t=-R @ position,
            distortion_model=distortion_model, frame_id=frame_id,
            rectification=rectification, projection=projection,
        )

    @classmethod
    def from_camera_info(cls, d: dict, name: str | None = None, position=(0.0, 0.0, 0.0),
                         quaternion=(0.0, 0.0, 0.0, 1.0)) -> "PinholeCamera":
        """Camera from a CameraInfo dict (keys ``width, height, K, D, distortion_model, R, P,
        frame_id``, as produced by ``hmocap_ros.io.conversions.camera_info_to_dict``) and a pose.

        ``name`` defaults to the dict's ``frame_id`` with a trailing ``_optical_frame`` removed.
        An empty ``distortion_model`` with no coefficients is read as ``plumb_bob``.
        """
        missing = [key for key in ("width", "height", "K") if key not in d]
        if missing:
            raise ValueError(f"camera info dict lacks {', '.join(missing)}")
        frame_id = str(d.get("frame_id", "") or "")
        if name is None:
            name = frame_id.removesuffix("_optical_frame") or "camera"
        D = np.asarray(d.get("D", ()), dtype=np.float64).reshape(-1)
        model = str(d.get("distortion_model", "") or "")
        if not model and D.size == 0:
            model = "plumb_bob"
        return cls.from_pose(
            name=name, width=d["width"], height=d["height"], K=np.asarray(d["K"]).reshape(3, 3),
            position=position, quaternion_xyzw=quaternion, D=D, distortion_model=model,
            frame_id=frame_id,
            rectification=None if d.get("R") is None else np.asarray(d["R"]).reshape(3, 3),
            projection=None if d.get("P") is None else np.asarray(d["P"]).reshape(3, 4),
        )

    def to_camera_info_dict(self) -> dict:
        """The intrinsics as the CameraInfo dict of ``hmocap_ros.io.conversions`` (fresh arrays)."""
        return {
            "width": self.width,
            "height": self.height,
            "K": np.array(self.K),
            "D": np.array(self.D),
            "distortion_model": self.distortion_model,
            "R": np.array(self.rectification),
            "P": np.array(self.projection),
            "frame_id": self.frame_id,
        }

    def scaled(self, factor: float) -> "PinholeCamera":
        """The same camera seen in an image resized by ``factor`` (e.g. 0.25 for silhouettes).

        The new size is ``round(width * factor) x round(height * factor)``; intrinsics follow the
        exact per-axis ratio with the half-pixel shift of ``cv2.resize``
        (``u' = s (u + 0.5) - 0.5``). Distortion coefficients act on normalized coordinates and
        do not change.
        """
        if not np.isfinite(factor) or factor <= 0:
            raise ValueError(f"camera {self.name!r}: scale factor must be positive, got {factor!r}")
        width = max(1, int(round(self.width * factor)))
        height = max(1, int(round(self.height * factor)))
        sx, sy = width / self.width, height / self.height
        S = np.array([[sx, 0.0, 0.5 * (sx - 1.0)], [0.0, sy, 0.5 * (sy - 1.0)], [0.0, 0.0, 1.0]])
        return dataclasses.replace(self, width=width, height=height, K=S @ self.K, projection=S @ self.projection)

    # ---- pose ---------------------------------------------------------------------------

    @property
    def position(self) -> np.ndarray:
        """Camera centre in the room frame (metres), ``-R^T t``."""
        return -self.R.T @ self.t

    @property
    def R_wc(self) -> np.ndarray:
        """Camera->room rotation (columns: optical x, y, z axes in the room frame)."""
        return self.R.T

    @property
    def optical_axis(self) -> np.ndarray:
        """Unit viewing direction (optical +z) in the room frame."""
        return self.R[2].copy()

    def pose_quaternion(self) -> np.ndarray:
        """Orientation of the optical frame in the room as a unit quaternion (x, y, z, w), w >= 0."""
        return matrix_to_quaternion(self.R.T)

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels, the order ``cv2`` functions take."""
        return self.width, self.height

    @cached_property
    def distortion8(self) -> np.ndarray:
        """``D`` padded with zeros to OpenCV's 8 coefficients (k1, k2, p1, p2, k3, k4, k5, k6)."""
        return coefficients8(self.D)

    @cached_property
    def max_normalized_radius2(self) -> float:
        """r^2 of normalized coordinates beyond which the distortion folds back
        (:func:`~hmocap_ros.geometry.distortion.monotonic_radius2`)."""
        return monotonic_radius2(self.distortion8)

    # ---- projection ---------------------------------------------------------------------

    def world_to_camera(self, points_world) -> np.ndarray:
        """Points ``(..., 3)`` in the room frame -> camera optical frame."""
        points = np.asarray(points_world, dtype=np.float64)
        return points @ self.R.T + self.t

    def camera_to_world(self, points_camera) -> np.ndarray:
        """Points ``(..., 3)`` in the camera optical frame -> room frame."""
        points = np.asarray(points_camera, dtype=np.float64)
        return (points - self.t) @ self.R

    def project(self, points_world, distort: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Project room points ``(..., 3)`` to pixels ``(..., 2)``; also returns depth ``(...)``.

        Points behind the camera still get (meaningless) pixels, like ``cv2.projectPoints``;
        use :meth:`visible` or :func:`project_points` for the mask.
        """
        result = project_points([self], points_world, distort=distort)
        return result.pixels[0], result.depth[0]

    def visible(self, points_world, min_depth: float = DEFAULT_MIN_DEPTH) -> np.ndarray:
        """Boolean mask ``(...)``: in front of the camera and projecting inside the image."""
        return project_points([self], points_world, min_depth=min_depth).visible[0]

    def in_image(self, pixels) -> np.ndarray:
        """Boolean mask ``(...)`` of pixels ``(..., 2)`` inside ``[-0.5, W-0.5) x [-0.5, H-0.5)``."""
        pixels = np.asarray(pixels, dtype=np.float64)
        u, v = pixels[..., 0], pixels[..., 1]
        return (u >= -0.5) & (u < self.width - 0.5) & (v >= -0.5) & (v < self.height - 0.5)

    def undistort_points(self, pixels) -> np.ndarray:
        """Distorted pixels ``(..., 2)`` -> normalized undistorted coordinates ``(x/z, y/z)``.

        Same result as ``cv2.undistortPoints(pixels, K, D)`` (without ``P``), but solved with
        Newton iterations to machine precision and broadcast over any batch shape.
        """
        pixels = np.asarray(pixels, dtype=np.float64)
        K = self.K
        y_d = (pixels[..., 1] - K[1, 2]) / K[1, 1]
        x_d = (pixels[..., 0] - K[0, 2] - K[0, 1] * y_d) / K[0, 0]
        return undistort_normalized(np.stack([x_d, y_d], axis=-1), self.distortion8)

    def undistort_pixels(self, pixels) -> np.ndarray:
        """Distorted pixels ``(..., 2)`` -> pixels of the ideal (distortion-free) camera ``K``."""
        xy = self.undistort_points(pixels)
        K = self.K
        u = K[0, 0] * xy[..., 0] + K[0, 1] * xy[..., 1] + K[0, 2]
        v = K[1, 1] * xy[..., 1] + K[1, 2]
        return np.stack([u, v], axis=-1)

    def back_project(self, pixels, depth=None) -> np.ndarray:
        """Pixels ``(..., 2)`` -> unit ray directions in the room ``(..., 3)``, or room points.

        Without ``depth`` the rays start at :attr:`position`. With ``depth`` (z in the optical
        frame, broadcastable to ``(...)``) the room points ``(..., 3)`` are returned, so that
        ``back_project(*project(X)) == X``.
        """
        xy = self.undistort_points(pixels)
        rays = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
        if depth is None:
            rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
            return rays @ self.R
        depth = np.asarray(depth, dtype=np.float64)
        return self.camera_to_world(rays * depth[..., None])

    # ---- comparison ---------------------------------------------------------------------

    def isclose(self, other: "PinholeCamera", atol: float = 1e-9) -> bool:
        """True if both cameras have the same names, sizes, models and parameters within ``atol``."""
        if not isinstance(other, PinholeCamera):
            return False
        same = (
            self.name == other.name
            and self.frame_id == other.frame_id
            and (self.width, self.height) == (other.width, other.height)
            and self.distortion_model == other.distortion_model
            and self.D.shape == other.D.shape
        )
        return same and all(
            np.allclose(getattr(self, attr), getattr(other, attr), atol=atol, rtol=0.0)
            for attr in ("K", "D", "R", "t", "rectification", "projection")
        )

    def __repr__(self) -> str:
        pos = np.array2string(self.position, precision=3, separator=", ")
        return (
            f"PinholeCamera(name={self.name!r}, {self.width}x{self.height}, fx={self.fx:.2f}, "
            f"fy={self.fy:.2f}, cx={self.cx:.2f}, cy={self.cy:.2f}, {self.distortion_model}, position={pos})"
        )


def look_at_pose(position, target, up=ROOM_UP, where: str = "camera") -> tuple[np.ndarray, np.ndarray]:
    """World -> camera ``(R, t)`` of a camera at ``position`` looking at ``target`` (room frame,
    metres), image "up" along ``up``.

    The optical z axis points from ``position`` to ``target``; x (image right) is ``z x up``
    normalised and y (image down) is ``z x x`` (OpenCV axes), so ``up`` appears upwards in the
    image. ``ValueError`` (prefixed with ``where``) when the target is the position or the
    viewing direction is parallel to ``up``. Cameras (:func:`look_at`), shadow maps and lamps
    are placed with it.
    """
    position = np.asarray(position, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - position
    norm = np.linalg.norm(forward)
    if norm < 1e-12:
        raise ValueError(f"{where}: target coincides with position")
    z = forward / norm
    x = np.cross(z, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(x) < 1e-9:
        raise ValueError(f"{where}: viewing direction {z.tolist()} is parallel to up {list(up)}")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ position


def look_at(
    name: str,
    position,
    target,
    up=ROOM_UP,
    width: int = 640,
    height: int = 480,
    fx: float = 520.0,
    fy: float | None = None,
    cx: float | None = None,
    cy: float | None = None,
    D=(),
    distortion_model: str = "plumb_bob",
    frame_id: str = "",
) -> PinholeCamera:
    """A camera at ``position`` looking at ``target`` (room frame, metres), image "up" along ``up``.

    The optical z axis points from ``position`` to ``target``; x (image right) is
    ``z x up`` normalised and y (image down) is ``z x x``, so the room's up axis
    (:data:`ROOM_UP`, +Y) appears upwards in the image. ``fy`` defaults to ``fx`` and the
    principal point to the image centre ``((W-1)/2, (H-1)/2)``.
    """
    R, t = look_at_pose(position, target, up, where=f"camera {name!r}")
    K = np.array([
        [fx, 0.0, (width - 1) / 2.0 if cx is None else cx],
        [0.0, fx if fy is None else fy, (height - 1) / 2.0 if cy is None else cy],
        [0.0, 0.0, 1.0],
    ])
    return PinholeCamera(name=name, width=width, height=height, K=K, D=D, R=R, t=t,
                         distortion_model=distortion_model, frame_id=frame_id)
