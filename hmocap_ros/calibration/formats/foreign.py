"""Cameras as other tools' calibration files hold them, before the package's room frame.

A :class:`ForeignCalibration` is what a reader of :mod:`hmocap_ros.calibration.formats` returns
and what a writer takes: per camera the OpenCV model (``K``, distortion coefficients in OpenCV's
order ``k1, k2, p1, p2[, k3[, k4, k5, k6]]``) and the world -> camera transform
``x_cam = R x_world + t`` of the file's own world, in the file's own length unit. Whether that
world is Z-up or Y-up and whether its unit is the metre or the millimetre is what the file says
(``up``, ``metres_per_unit``) or, where the format does not say, None:
:mod:`~hmocap_ros.calibration.formats.world_frame` settles both (from the user or from the
cameras) when it turns the calibration into a :class:`~hmocap_ros.geometry.rig.Rig`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["CalibrationFormatError", "ForeignCalibration", "ForeignCamera"]

#: OpenCV distortion coefficients the package's camera model takes (rational_polynomial).
MAX_COEFFICIENTS = 8


class CalibrationFormatError(ValueError):
    """A calibration file that cannot be read or written; the message (one line) names the file,
    the camera and the field."""


@dataclass(frozen=True, eq=False)
class ForeignCamera:
    """One camera of a calibration file: name, image size (None where the file has none),
    ``K`` (3, 3), ``D`` OpenCV coefficients, ``R`` (3, 3) and ``t`` (3,) world -> camera in the
    file's unit."""

    name: str
    size: tuple[int, int] | None
    K: np.ndarray
    D: np.ndarray
    R: np.ndarray
    t: np.ndarray

    def __post_init__(self) -> None:
        where = f"camera {self.name!r}"
        K = np.asarray(self.K, dtype=np.float64)
        D = np.asarray(self.D, dtype=np.float64).reshape(-1)
        R = np.asarray(self.R, dtype=np.float64)
        t = np.asarray(self.t, dtype=np.float64).reshape(-1)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise CalibrationFormatError(f"{where}: the camera matrix must be a finite 3x3 with "
                                         f"positive focal lengths, got {K.tolist()}")
        if D.size > MAX_COEFFICIENTS and np.any(D[MAX_COEFFICIENTS:] != 0):
            raise CalibrationFormatError(
                f"{where}: {D.size} distortion coefficients: the thin-prism and tilted terms "
                f"(beyond k6) are not supported")
        D = D[:MAX_COEFFICIENTS]
        if not np.all(np.isfinite(D)):
            raise CalibrationFormatError(f"{where}: non-finite distortion coefficients")
        if (R.shape != (3, 3) or not np.all(np.isfinite(R))
                or np.abs(R.T @ R - np.eye(3)).max() > 1e-5 or abs(np.linalg.det(R) - 1) > 1e-5):
            raise CalibrationFormatError(f"{where}: the rotation is not a proper rotation "
                                         f"matrix: {R.tolist()}")
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise CalibrationFormatError(f"{where}: the translation must be 3 finite numbers")
        if self.size is not None:
            w, h = (int(v) for v in self.size)
            if w <= 0 or h <= 0:
                raise CalibrationFormatError(f"{where}: image size must be positive, got "
                                             f"{self.size}")
            object.__setattr__(self, "size", (w, h))
        for name, value in (("K", K), ("D", D), ("R", R), ("t", t)):
            object.__setattr__(self, name, value)

    @property
    def centre(self) -> np.ndarray:
        """Camera centre in the file's world and unit, ``-R^T t``."""
        return -self.R.T @ self.t


@dataclass(frozen=True, eq=False)
class ForeignCalibration:
    """The cameras of one calibration file, in file order, and what the file says of its world:
    ``up`` (``"+Z"``, ``"-Y"``, ...; None: the format does not say) and ``metres_per_unit``
    (0.001 for millimetres; None: the format does not say). ``source`` names the file and
    ``format`` its format in messages."""

    cameras: tuple[ForeignCamera, ...]
    up: str | None = None
    metres_per_unit: float | None = None
    source: str = "<calibration>"
    format: str = ""
    notes: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        cameras = tuple(self.cameras)
        if not cameras:
            raise CalibrationFormatError(f"{self.source}: no cameras")
        names = [c.name for c in cameras]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise CalibrationFormatError(f"{self.source}: camera name(s) given twice: "
                                         f"{', '.join(twice)}")
        object.__setattr__(self, "cameras", cameras)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.cameras)

    def camera(self, name: str) -> ForeignCamera:
        for camera in self.cameras:
            if camera.name == name:
                return camera
        raise KeyError(name)
