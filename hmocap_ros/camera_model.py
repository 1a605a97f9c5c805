"""Calibrated pinhole cameras with OpenCV lens distortion, vectorised in numpy.

The thesis (sec. 2.1) assumes "a set of projective transformations p_v, given by the camera
calibration, that map points in R^3 onto each view v" (Bouguet's model, ref. [21]). This module
is that set: a frozen :class:`PinholeCamera` per view and stateless functions over lists of them.

Frames and conventions
----------------------
* **Room frame** (the world, ``frame_id: room`` in the rig file, the frame the simulator renders
  in): metres, right-handed, **+Y up**, the floor is the plane ``y = 0``. :data:`ROOM_UP` is the
  up axis :func:`look_at` uses by default.
* **Camera optical frame** (REP-103 ``*_optical_frame``): x right, y down, z forward along the
  optical axis. A camera stores the world->camera transform ``x_cam = R @ x_world + t``; its pose
  in the room (the camera centre :attr:`PinholeCamera.position` and the orientation of the
  optical frame, :meth:`PinholeCamera.pose_quaternion`, x, y, z, w like ``geometry_msgs``) is the
  inverse of that transform.
* **Pixels**: OpenCV/ROS convention, the centre of pixel ``(col, row)`` is at ``u = col``,
  ``v = row``; the image covers ``[-0.5, width - 0.5) x [-0.5, height - 0.5)``.
* **Depth** is the z coordinate in the optical frame (distance along the optical axis), the
  convention of depth images, not the Euclidean range.
* **Distortion**: the OpenCV model (Brown-Conrady radial + tangential), ROS ``plumb_bob``
  ``D = (k1, k2, p1, p2, k3)`` and ``rational_polynomial`` ``D = (k1, k2, p1, p2, k3, k4, k5, k6)``:

  .. math::
      r^2 = x^2 + y^2,\\quad g = \\frac{1 + k_1 r^2 + k_2 r^4 + k_3 r^6}{1 + k_4 r^2 + k_5 r^4 + k_6 r^6}

      x_d = x g + 2 p_1 x y + p_2 (r^2 + 2 x^2),\\quad y_d = y g + p_1 (r^2 + 2 y^2) + 2 p_2 x y

  and ``(u, v, 1) = K (x_d, y_d, 1)``. It is implemented here in numpy (matches
  ``cv2.projectPoints`` to 1e-9 px) so that it broadcasts over cameras and point batches.

Shapes: point arrays are ``(..., 3)`` and pixel arrays ``(..., 2)`` with any batch shape; the
multi-camera functions put the camera axis first, ``(M, ...)``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property
from typing import NamedTuple, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "ROOM_UP",
    "DISTORTION_MODELS",
    "PinholeCamera",
    "Projection",
    "look_at",
    "distort_normalized",
    "undistort_normalized",
    "project_points",
    "pixel_rays",
    "triangulate",
    "triangulate_robust",
    "reprojection_errors",
    "quaternion_to_matrix",
    "matrix_to_quaternion",
]

#: Up axis of the room frame (metres, +Y up, floor at y = 0).
ROOM_UP = (0.0, 1.0, 0.0)

#: Number of coefficients of each supported ROS ``distortion_model``.
DISTORTION_MODELS = {"plumb_bob": 5, "rational_polynomial": 8}

#: Tolerance on the norm of a pose quaternion before it is renormalised.
QUATERNION_TOLERANCE = 1e-3

#: Tolerance on R^T R = I for a world->camera rotation.
_ROTATION_TOLERANCE = 1e-6

#: Points nearer than this (metres along the optical axis) are not visible.
DEFAULT_MIN_DEPTH = 1e-6


# --------------------------------------------------------------------------------------------
# Rotations
# --------------------------------------------------------------------------------------------


def quaternion_to_matrix(quaternion_xyzw) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion ``(x, y, z, w)``.

    Raises ``ValueError`` if the quaternion is not finite or its norm differs from 1 by more
    than :data:`QUATERNION_TOLERANCE` (it is renormalised within the tolerance).
    """
    q = np.asarray(quaternion_xyzw, dtype=np.float64)
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise ValueError(f"quaternion must be 4 finite numbers (x, y, z, w), got {quaternion_xyzw!r}")
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        raise ValueError(f"quaternion {q.tolist()} is not a unit quaternion (norm {norm:.6g})")
    return Rotation.from_quat(q / norm).as_matrix()


def matrix_to_quaternion(rotation) -> np.ndarray:
    """Unit quaternion ``(x, y, z, w)`` of a rotation matrix, with ``w >= 0`` (canonical sign)."""
    return Rotation.from_matrix(np.asarray(rotation, dtype=np.float64)).as_quat(canonical=True)


# --------------------------------------------------------------------------------------------
# Distortion (stateless, broadcasting)
# --------------------------------------------------------------------------------------------


def _coefficients8(D) -> np.ndarray:
    """Distortion coefficients padded with zeros to OpenCV's 8 (k1, k2, p1, p2, k3, k4, k5, k6)."""
    d = np.asarray(D, dtype=np.float64)
    if d.shape[-1] > 8:
        raise ValueError(f"at most 8 distortion coefficients are supported, got {d.shape[-1]}")
    pad = [(0, 0)] * (d.ndim - 1) + [(0, 8 - d.shape[-1])]
    return np.pad(d, pad)


def _radial_terms(r2, d8):
    """Radial factor g(r^2) and its derivative dg/d(r^2); ``d8`` is a tuple of 8 broadcastable arrays."""
    k1, k2, _, _, k3, k4, k5, k6 = d8
    num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    dnum = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3)
    dden = k4 + r2 * (2.0 * k5 + 3.0 * r2 * k6)
    g = num / den
    dg = (dnum * den - num * dden) / (den * den)
    return g, dg


def _radial_factor(r2, d8):
    """Radial factor g(r^2) alone; skips the rational denominator when it is 1 (plumb_bob)."""
    k1, k2, _, _, k3, k4, k5, k6 = d8
    g = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    if np.any(k4) or np.any(k5) or np.any(k6):
        g = g / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    return g


def _distort_xy(x, y, d8):
    """OpenCV distortion of normalized coordinates (module docstring formula)."""
    p1, p2 = d8[2], d8[3]
    r2 = x * x + y * y
    g = _radial_factor(r2, d8)
    xy = x * y
    xd = x * g + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x)
    yd = y * g + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy
    return xd, yd


def distort_normalized(xy, D) -> np.ndarray:
    """Apply OpenCV distortion ``D`` (0 to 8 coefficients) to normalized coordinates ``(..., 2)``."""
    xy = np.asarray(xy, dtype=np.float64)
    d8 = tuple(_coefficients8(D))
    xd, yd = _distort_xy(xy[..., 0], xy[..., 1], d8)
    return np.stack([xd, yd], axis=-1)


def undistort_normalized(xy_distorted, D, iterations: int = 20, tolerance: float = 1e-14) -> np.ndarray:
    """Invert :func:`distort_normalized` by vectorised Newton iterations.

    Solves ``distort(x) = x_d`` for every point with the analytic 2x2 Jacobian of the OpenCV
    model, starting from ``x = x_d``; converges quadratically for any point inside the monotonic
    part of the distortion (every point of a calibrated image). Points that do not converge are
    returned as NaN. ``D`` may be ``(n,)`` or broadcast against the batch shape as ``(..., n)``.
    """
    xy_distorted = np.asarray(xy_distorted, dtype=np.float64)
    coeffs = _coefficients8(D)
    d8 = tuple(np.moveaxis(coeffs, -1, 0))
    if not np.any(coeffs):
        return xy_distorted.copy()
    p1, p2 = d8[2], d8[3]
    xd, yd = xy_distorted[..., 0], xy_distorted[..., 1]
    x, y = xd.copy(), yd.copy()
    for _ in range(iterations):
        r2 = x * x + y * y
        g, dg = _radial_terms(r2, d8)
        xy = x * y
        fx = x * g + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x) - xd
        fy = y * g + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy - yd
        j11 = g + 2.0 * x * x * dg + 2.0 * p1 * y + 6.0 * p2 * x
        j12 = 2.0 * xy * dg + 2.0 * p1 * x + 2.0 * p2 * y
        j22 = g + 2.0 * y * y * dg + 6.0 * p1 * y + 2.0 * p2 * x
        det = j11 * j22 - j12 * j12  # the Jacobian is symmetric (j21 == j12)
        with np.errstate(divide="ignore", invalid="ignore"):
            dx = (j22 * fx - j12 * fy) / det
            dy = (j11 * fy - j12 * fx) / det
        x = x - dx
        y = y - dy
        if np.nanmax(np.abs(np.concatenate([np.ravel(dx), np.ravel(dy), [0.0]]))) < tolerance:
            break
    r2 = x * x + y * y
    x2, y2 = _distort_xy(x, y, d8)
    with np.errstate(invalid="ignore"):
        bad = ~(np.hypot(x2 - xd, y2 - yd) <= 1e-9 * (1.0 + np.sqrt(r2)))
    out = np.stack([x, y], axis=-1)
    out[bad] = np.nan
    return out


def _max_normalized_radius2(d8: np.ndarray, r_max: float = 20.0, samples: int = 8001) -> float:
    """Largest r^2 up to which the radial distortion r -> r g(r^2) is increasing.

    Beyond it the polynomial folds back and maps points far outside the field of view into the
    image, so projections there are meaningless; :func:`project_points` marks them invisible.
    Tangential terms are ignored (they are tiny in any real calibration).
    """
    if not np.any(d8[[0, 1, 4, 5, 6, 7]]):
        return float("inf")
    r = np.linspace(0.0, r_max, samples)
    r2 = r * r
    num = 1.0 + r2 * (d8[0] + r2 * (d8[1] + r2 * d8[4]))
    den = 1.0 + r2 * (d8[5] + r2 * (d8[6] + r2 * d8[7]))
    g, dg = _radial_terms(r2, tuple(d8))
    slope = g + 2.0 * r2 * dg  # d(r g(r^2)) / dr
    bad = (slope <= 0.0) | (den <= 0.0) | (num <= 0.0)
    if not np.any(bad):
        return float("inf")
    first = int(np.argmax(bad))
    return float(r2[max(first - 1, 0)])


# --------------------------------------------------------------------------------------------
# The camera
# --------------------------------------------------------------------------------------------


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=np.float64, copy=True)
    array.flags.writeable = False
    return array


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
        K = np.asarray(self.K, dtype=np.float64)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise ValueError(f"{where}: K must be a finite 3x3 matrix, got shape {K.shape}")
        if K[0, 0] <= 0 or K[1, 1] <= 0 or not np.allclose(K[2], (0.0, 0.0, 1.0)) or K[1, 0] != 0:
            raise ValueError(f"{where}: K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got {K.tolist()}")
        if self.distortion_model not in DISTORTION_MODELS:
            raise ValueError(
                f"{where}: unsupported distortion_model {self.distortion_model!r} "
                f"(supported: {', '.join(DISTORTION_MODELS)})"
            )
        D = np.asarray(self.D, dtype=np.float64).reshape(-1)
        n = DISTORTION_MODELS[self.distortion_model]
        if D.size > n or not np.all(np.isfinite(D)):
            raise ValueError(
                f"{where}: distortion_model {self.distortion_model!r} takes at most {n} finite coefficients, got {D.tolist()}"
            )
        D = np.pad(D, (0, n - D.size))
        R = np.asarray(self.R, dtype=np.float64)
        if R.shape != (3, 3) or not np.all(np.isfinite(R)):
            raise ValueError(f"{where}: R must be a finite 3x3 rotation, got shape {R.shape}")
        if not np.allclose(R @ R.T, np.eye(3), atol=_ROTATION_TOLERANCE) or np.linalg.det(R) < 0:
            raise ValueError(f"{where}: R is not a proper rotation matrix: {R.tolist()}")
        t = np.asarray(self.t, dtype=np.float64).reshape(-1)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise ValueError(f"{where}: t must be 3 finite numbers, got {np.asarray(self.t).tolist()}")
        rect = np.eye(3) if self.rectification is None else np.asarray(self.rectification, dtype=np.float64)
        if rect.shape != (3, 3):
            raise ValueError(f"{where}: rectification must be 3x3, got shape {rect.shape}")
        proj = np.hstack([K, np.zeros((3, 1))]) if self.projection is None else np.asarray(self.projection, dtype=np.float64)
        if proj.shape != (3, 4):
            raise ValueError(f"{where}: projection must be 3x4, got shape {proj.shape}")
        object.__setattr__(self, "K", _readonly(K))
        object.__setattr__(self, "D", _readonly(D))
        object.__setattr__(self, "R", _readonly(R))
        object.__setattr__(self, "t", _readonly(t))
        object.__setattr__(self, "rectification", _readonly(rect))
        object.__setattr__(self, "projection", _readonly(proj))
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
    def _d8(self) -> np.ndarray:
        return _coefficients8(self.D)

    @cached_property
    def max_normalized_radius2(self) -> float:
        """r^2 of normalized coordinates beyond which the distortion folds back (see module docs)."""
        return _max_normalized_radius2(self._d8)

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
        return undistort_normalized(np.stack([x_d, y_d], axis=-1), self._d8)

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
    position = np.asarray(position, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - position
    norm = np.linalg.norm(forward)
    if norm < 1e-12:
        raise ValueError(f"camera {name!r}: target coincides with position")
    z = forward / norm
    x = np.cross(z, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(x) < 1e-9:
        raise ValueError(f"camera {name!r}: viewing direction {z.tolist()} is parallel to up {list(up)}")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    K = np.array([
        [fx, 0.0, (width - 1) / 2.0 if cx is None else cx],
        [0.0, fx if fy is None else fy, (height - 1) / 2.0 if cy is None else cy],
        [0.0, 0.0, 1.0],
    ])
    return PinholeCamera(name=name, width=width, height=height, K=K, D=D, R=R, t=-R @ position,
                         distortion_model=distortion_model, frame_id=frame_id)


# --------------------------------------------------------------------------------------------
# Multi-camera functions
# --------------------------------------------------------------------------------------------


class Projection(NamedTuple):
    """Result of :func:`project_points` for M cameras and points of batch shape ``S``."""

    pixels: np.ndarray  #: (M, *S, 2) pixel coordinates (distorted image)
    depth: np.ndarray  #: (M, *S) z in each camera's optical frame
    visible: np.ndarray  #: (M, *S) in front, inside the image and inside the valid distortion range


def _stack(cameras: Sequence[PinholeCamera]):
    cameras = list(cameras)
    if not cameras:
        raise ValueError("need at least one camera")
    R = np.stack([c.R for c in cameras])
    t = np.stack([c.t for c in cameras])
    K = np.stack([c.K for c in cameras])
    D = np.stack([c._d8 for c in cameras])
    return cameras, R, t, K, D


def project_points(cameras: Sequence[PinholeCamera], points_world, distort: bool = True,
                   min_depth: float = DEFAULT_MIN_DEPTH) -> Projection:
    """Project room points ``(..., 3)`` into M cameras at once.

    Returns :class:`Projection` with pixels ``(M, ..., 2)``, depth ``(M, ...)`` and the visibility
    mask ``(M, ...)``: depth > ``min_depth``, inside the image, and (with distortion) within the
    range where the lens model is monotonic. ``cameras`` is any sequence (e.g. a ``Rig``).
    """
    cameras, R, t, K, D = _stack(cameras)
    points = np.asarray(points_world, dtype=np.float64)
    if points.shape[-1] != 3:
        raise ValueError(f"points must have shape (..., 3), got {points.shape}")
    batch = points.shape[:-1]
    flat = points.reshape(-1, 3)
    cam = np.matmul(flat[None], R.transpose(0, 2, 1)) + t[:, None, :]  # (M, N, 3); BLAS, unlike einsum
    depth = cam[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = cam[..., 0] / depth
        y = cam[..., 1] / depth
    r2 = x * x + y * y
    if distort:
        xd, yd = _distort_xy(x, y, tuple(D.T[:, :, None]))
    else:
        xd, yd = x, y
    u = K[:, 0, 0, None] * xd + K[:, 0, 1, None] * yd + K[:, 0, 2, None]
    v = K[:, 1, 1, None] * yd + K[:, 1, 2, None]
    sizes = np.array([[c.width, c.height] for c in cameras], dtype=np.float64)
    with np.errstate(invalid="ignore"):
        visible = (
            (depth > min_depth)
            & (u >= -0.5) & (u < sizes[:, 0, None] - 0.5)
            & (v >= -0.5) & (v < sizes[:, 1, None] - 0.5)
        )
        if distort:
            r2_max = np.array([c.max_normalized_radius2 for c in cameras])
            visible &= r2 <= r2_max[:, None]
    M = len(cameras)
    pixels = np.stack([u, v], axis=-1).reshape((M,) + batch + (2,))
    return Projection(pixels, depth.reshape((M,) + batch), visible.reshape((M,) + batch))


def pixel_rays(cameras: Sequence[PinholeCamera], pixels) -> tuple[np.ndarray, np.ndarray]:
    """Viewing rays of pixels ``(M, ..., 2)`` (axis 0: one entry per camera) in the room frame.

    Returns ``(origins (M, 3), directions (M, ..., 3))`` with unit directions.
    """
    cameras = list(cameras)
    pixels = np.asarray(pixels, dtype=np.float64)
    if pixels.shape[0] != len(cameras) or pixels.shape[-1] != 2:
        raise ValueError(f"pixels must have shape ({len(cameras)}, ..., 2), got {pixels.shape}")
    origins = np.stack([c.position for c in cameras])
    directions = np.stack([c.back_project(p) for c, p in zip(cameras, pixels)])
    return origins, directions


def triangulate(cameras: Sequence[PinholeCamera], pixels, valid=None, min_views: int = 2) -> np.ndarray:
    """Linear (DLT) triangulation of N points seen by M cameras, vectorised over points.

    Hartley & Zisserman, *Multiple View Geometry*, sec. 12.2: each valid view m of point n gives
    the rows ``x P_m^3 - P_m^1`` and ``y P_m^3 - P_m^2`` with ``P_m = [R_m | t_m]`` and ``(x, y)``
    the undistorted normalized coordinates; the homogeneous point is the right singular vector
    of the smallest singular value of the stacked rows ``A`` (batched over N).

    ``pixels`` is ``(M, N, 2)``; ``valid`` ``(M, N)`` selects the views to use (default: all
    finite pixels). Points with fewer than ``min_views`` valid views, or at infinity, are NaN.
    Returns ``(N, 3)`` room points.
    """
    cameras = list(cameras)
    pixels = np.asarray(pixels, dtype=np.float64)
    M = len(cameras)
    if pixels.ndim != 3 or pixels.shape[0] != M or pixels.shape[2] != 2:
        raise ValueError(f"pixels must have shape ({M}, N, 2), got {pixels.shape}")
    N = pixels.shape[1]
    finite = np.all(np.isfinite(pixels), axis=-1)
    valid = finite if valid is None else (np.asarray(valid, dtype=bool) & finite)
    if valid.shape != (M, N):
        raise ValueError(f"valid must have shape ({M}, {N}), got {valid.shape}")
    xy = np.stack([c.undistort_points(np.where(finite[m, :, None], pixels[m], 0.0)) for m, c in enumerate(cameras)])
    valid = valid & np.all(np.isfinite(xy), axis=-1)
    xy = np.where(valid[..., None], xy, 0.0)
    P = np.stack([np.hstack([c.R, c.t[:, None]]) for c in cameras])  # (M, 3, 4)
    rows_x = xy[..., 0, None] * P[:, None, 2, :] - P[:, None, 0, :]  # (M, N, 4)
    rows_y = xy[..., 1, None] * P[:, None, 2, :] - P[:, None, 1, :]
    weight = valid[..., None].astype(np.float64)
    A = np.concatenate([rows_x * weight, rows_y * weight], axis=0)  # (2M, N, 4)
    A = np.moveaxis(A, 1, 0)  # (N, 2M, 4)
    out = np.full((N, 3), np.nan)
    enough = valid.sum(axis=0) >= max(int(min_views), 2)
    if not np.any(enough):
        return out
    A = A[enough]
    # The right singular vector of A for the smallest singular value is the eigenvector of the
    # 4x4 A^T A for the smallest eigenvalue: a batched eigh is twice as fast as a batched SVD.
    _, eigenvectors = np.linalg.eigh(np.matmul(A.transpose(0, 2, 1), A))
    X = eigenvectors[:, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        points = X[:, :3] / X[:, 3:]
    points[np.abs(X[:, 3]) < 1e-12] = np.nan
    out[enough] = points
    return out


def reprojection_errors(cameras: Sequence[PinholeCamera], points, pixels) -> np.ndarray:
    """Pixel distance ``(M, N)`` between room points ``(N, 3)`` projected into each camera and
    the observed ``pixels`` ``(M, N, 2)``; NaN where the point or the pixel is NaN."""
    points = np.asarray(points, dtype=np.float64)
    finite = np.all(np.isfinite(points), axis=1)
    projected = project_points(list(cameras), np.where(finite[:, None], points, 0.0)).pixels
    errors = np.linalg.norm(projected - np.asarray(pixels, dtype=np.float64), axis=-1)
    errors[:, ~finite] = np.nan
    return errors


def triangulate_robust(cameras: Sequence[PinholeCamera], pixels, valid=None,
                       max_reprojection_px: float = 20.0, min_views: int = 2):
    """:func:`triangulate`, leaving out views that disagree with the others.

    A point whose worst used view reprojects further than ``max_reprojection_px`` is
    triangulated again without one view, the one whose removal leaves the best worst-view
    error (the view with the largest error is not always the wrong one: a wrong view drags the
    point towards itself), repeatedly while more than ``min_views`` remain. Meant for
    per-view 2D detections, where one view may have found another person or limb.
    Returns ``(points (N, 3), used (M, N) bool)``.
    """
    cameras = list(cameras)
    pixels = np.asarray(pixels, dtype=np.float64)
    used = np.all(np.isfinite(pixels), axis=-1)
    if valid is not None:
        used &= np.asarray(valid, dtype=bool)
    points = triangulate(cameras, pixels, used, min_views)

    def worst_error(pts, pix, use):
        err = np.where(use, reprojection_errors(cameras, pts, pix), -np.inf)
        return np.nan_to_num(err.max(axis=0), nan=np.inf)

    while True:
        bad = (worst_error(points, pixels, used) > max_reprojection_px) & (used.sum(axis=0) > min_views)
        if not bad.any():
            return points, used
        best_error = np.full(points.shape[0], np.inf)
        best_view = np.full(points.shape[0], -1)
        for m in range(len(cameras)):  # leave one view out at a time (M is a handful)
            candidates = np.flatnonzero(bad & used[m])
            if candidates.size == 0:
                continue
            trial = used[:, candidates].copy()
            trial[m] = False
            error = worst_error(triangulate(cameras, pixels[:, candidates], trial, min_views),
                                pixels[:, candidates], trial)
            better = error < best_error[candidates]
            best_error[candidates[better]] = error[better]
            best_view[candidates[better]] = m
        drop = np.flatnonzero(bad & (best_view >= 0))
        if drop.size == 0:
            return points, used
        used[best_view[drop], drop] = False
        points[drop] = triangulate(cameras, pixels[:, drop], used[:, drop], min_views)
