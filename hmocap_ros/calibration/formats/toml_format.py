"""Pose2Sim's and Anipose's calibration TOML.

Both tools write one table per camera and a ``[metadata]`` table (Pose2Sim's ``toml_write`` in
``Pose2Sim/calibration.py``; aniposelib's ``CameraGroup.dump`` through the ``toml`` package,
which adds trailing commas inside arrays):

.. code-block:: toml

    [cam01]                       # Anipose: [cam_0], [cam_1], ...
    name = "cam01"
    size = [ 1088.0, 1920.0]      # width, height (pixels)
    matrix = [ [ fx, 0.0, cx], [ 0.0, fy, cy], [ 0.0, 0.0, 1.0]]
    distortions = [ k1, k2, p1, p2]   # Anipose: 5 values, k3 last
    rotation = [ rx, ry, rz]      # Rodrigues vector, world -> camera
    translation = [ tx, ty, tz]   # world -> camera
    fisheye = false               # Pose2Sim only

    [metadata]
    adjusted = false
    error = 0.0

Neither says its world's up axis or its length unit: Pose2Sim works in metres in a Z-up world
(the Qualisys world it converts from, or its scene calibration's), Anipose in the unit of its
board's squares (often millimetres) with the first camera at the origin. The reader leaves both
to :mod:`~hmocap_ros.calibration.formats.world_frame`; the writer writes Pose2Sim's layout.
"""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

import cv2
import numpy as np

from hmocap_ros.calibration.formats.foreign import CalibrationFormatError, ForeignCalibration, ForeignCamera

__all__ = ["read_toml", "write_toml"]

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _numbers(table: dict, key: str, where: str, shape: tuple[int, ...] | None = None,
             sizes: tuple[int, ...] = ()) -> np.ndarray:
    if key not in table:
        raise CalibrationFormatError(f"{where}: missing {key!r}")
    try:
        value = np.asarray(table[key], dtype=np.float64)
    except (TypeError, ValueError):
        raise CalibrationFormatError(f"{where}: {key!r} must hold numbers, got "
                                     f"{table[key]!r}") from None
    if shape is not None and value.shape != shape:
        raise CalibrationFormatError(f"{where}: {key!r} must be {shape}, got {value.shape}")
    if sizes and (value.ndim != 1 or value.size not in sizes):
        raise CalibrationFormatError(f"{where}: {key!r} must hold "
                                     f"{' or '.join(map(str, sizes))} numbers, got {value.size}")
    if not np.all(np.isfinite(value)):
        raise CalibrationFormatError(f"{where}: {key!r} has non-finite values")
    return value


def read_toml(path: str | Path) -> ForeignCalibration:
    """The cameras of a Pose2Sim or Anipose TOML file (module docstring), in file order."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as error:
        raise CalibrationFormatError(f"{path}: cannot read: {error}") from None
    except tomllib.TOMLDecodeError as error:
        raise CalibrationFormatError(f"{path}: not valid TOML ({error})") from None
    cameras = []
    for key, table in data.items():
        if not isinstance(table, dict) or "matrix" not in table:
            continue
        name = str(table.get("name", key))
        where = f"{path}: camera {name!r}"
        if table.get("fisheye", False):
            raise CalibrationFormatError(f"{where}: fisheye cameras are not supported")
        size = _numbers(table, "size", where, shape=(2,)) if "size" in table else None
        rotation = _numbers(table, "rotation", where, shape=(3,))
        cameras.append(ForeignCamera(
            name=name, size=None if size is None else (int(round(size[0])), int(round(size[1]))),
            K=_numbers(table, "matrix", where, shape=(3, 3)),
            D=_numbers(table, "distortions", where, sizes=(0, 4, 5, 8)),
            R=cv2.Rodrigues(rotation)[0], t=_numbers(table, "translation", where, shape=(3,))))
    if not cameras:
        raise CalibrationFormatError(f"{path}: no camera table (with a 'matrix') in the TOML")
    return ForeignCalibration(tuple(cameras), source=str(path), format="toml")


def _number(value: float) -> str:
    return repr(float(value))


def _array(values) -> str:
    return "[ " + ", ".join(_number(v) for v in values) + "]"


def write_toml(calibration: ForeignCalibration, path: str | Path) -> list[Path]:
    """Write Pose2Sim's layout (module docstring); returns the files written."""
    lines = []
    for camera in calibration.cameras:
        key = camera.name if _BARE_KEY.match(camera.name) else '"' + camera.name.replace('"', '\\"') + '"'
        K = camera.K
        D = np.pad(camera.D, (0, max(0, 4 - camera.D.size)))
        if D.size == 5 and D[4] == 0:
            D = D[:4]
        rotation = cv2.Rodrigues(np.asarray(camera.R, dtype=np.float64))[0].ravel()
        lines += [f"[{key}]",
                  f'name = "{camera.name}"',
                  f"size = {_array(camera.size)}",
                  "matrix = [ " + ", ".join(_array(row) for row in K) + "]",
                  f"distortions = {_array(D)}",
                  f"rotation = {_array(rotation)}",
                  f"translation = {_array(camera.t)}",
                  "fisheye = false", ""]
    lines += ["[metadata]", "adjusted = false", "error = 0.0", ""]
    path = Path(path)
    path.write_text("\n".join(lines))
    return [path]
