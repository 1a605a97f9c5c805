"""The calibrated camera rig: YAML file format and :class:`Rig`.

There is no tf2 here, so the rig (camera names, intrinsics and each camera's pose in the room)
is read from a YAML file under ``config/``, published latched as ``hmocap_interfaces/msg/CameraRig``
(:mod:`hmocap_ros.io.rig_messages`) and stored once in every bag.

YAML format
-----------
::

    frame_id: room                  # the room (world) frame: metres, +Y up, floor at y = 0
    cameras:                        # one entry per camera, in rig order
      - name: cam_1                 # unique; the camera's topics live under this namespace
        frame_id: cam_1_optical_frame   # optional, default <name>_optical_frame
        # ---- the keys of a ROS camera_calibration_parsers file (paste one here) ----
        image_width: 640
        image_height: 480
        camera_name: cam_1          # optional, ignored (calibration files carry it)
        camera_matrix: {rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}
        distortion_model: plumb_bob # or rational_polynomial
        distortion_coefficients: {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}
        rectification_matrix: {rows: 3, cols: 3, data: [...]}   # optional, default identity
        projection_matrix: {rows: 3, cols: 4, data: [...]}      # optional, default [K | 0]
        # ---- extrinsics: the camera optical frame (x right, y down, z forward) in the room ----
        pose:
          position: [x, y, z]       # camera centre, metres
          orientation: [x, y, z, w] # unit quaternion rotating optical-frame vectors into the room

Errors (a missing key, a matrix of the wrong size, a non-unit quaternion, a duplicate name, an
unknown key) raise :class:`RigError` naming the file, the camera and the field.
``config/rig_example.yaml`` is a complete example (four cameras in a 6 x 5 m room).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import yaml

from hmocap_ros.geometry.distortion import DISTORTION_MODELS
from hmocap_ros.geometry.pinhole_camera import PinholeCamera
from hmocap_ros.geometry.projection import Projection, project_points

__all__ = [
    "RigError",
    "Rig",
    "camera_arrays",
    "load_rig",
    "save_rig",
    "rig_from_dict",
    "rig_to_dict",
    "FlowList",
    "RigDumper",
    "matrix_entry",
    "read_matrix_entry",
    "read_vector_entry",
]


_CAMERA_KEYS = {
    "name", "frame_id", "image_width", "image_height", "camera_name", "camera_matrix",
    "distortion_model", "distortion_coefficients", "rectification_matrix", "projection_matrix", "pose",
}
_TOP_KEYS = {"frame_id", "cameras"}


class RigError(ValueError):
    """A rig file or message is malformed; the message names the source, camera and field."""


@dataclass(frozen=True, eq=False)
class Rig:
    """A calibrated multi-camera rig: the room ``frame_id`` and its cameras, in order.

    Behaves as a sequence of :class:`PinholeCamera` (``len``, iteration, ``rig[0]``) that can
    also be indexed by camera name (``rig["cam_2"]``, ``"cam_2" in rig``), so it can be passed
    wherever the camera-model functions take a list of cameras.
    """

    frame_id: str
    cameras: tuple[PinholeCamera, ...]

    def __post_init__(self) -> None:
        if not isinstance(self.frame_id, str) or not self.frame_id:
            raise RigError(f"rig frame_id must be a non-empty string, got {self.frame_id!r}")
        cameras = tuple(self.cameras)
        for camera in cameras:
            if not isinstance(camera, PinholeCamera):
                raise RigError(f"rig cameras must be PinholeCamera, got {type(camera).__name__}")
        names = [c.name for c in cameras]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise RigError(f"duplicate camera names in rig: {', '.join(duplicates)}")
        object.__setattr__(self, "cameras", cameras)

    @property
    def names(self) -> tuple[str, ...]:
        """Camera names in rig order."""
        return tuple(c.name for c in self.cameras)

    def __len__(self) -> int:
        return len(self.cameras)

    def __iter__(self) -> Iterator[PinholeCamera]:
        return iter(self.cameras)

    def __contains__(self, name: object) -> bool:
        return name in self.names

    def __getitem__(self, key: int | str) -> PinholeCamera:
        if isinstance(key, str):
            return self.cameras[self.index(key)]
        return self.cameras[key]

    def index(self, name: str) -> int:
        """Position of the camera called ``name``; ``KeyError`` listing the names if absent."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no camera {name!r} in rig (cameras: {', '.join(self.names)})") from None

    def scaled(self, factor: float) -> "Rig":
        """The rig at another working resolution (see :meth:`PinholeCamera.scaled`)."""
        return Rig(self.frame_id, tuple(c.scaled(factor) for c in self.cameras))

    def project(self, points_world, **kwargs) -> Projection:
        """:func:`~hmocap_ros.geometry.project_points` with this rig's cameras."""
        return project_points(self.cameras, points_world, **kwargs)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(K (M, 3, 3), R (M, 3, 3), t (M, 3), D (M, 8))``: the cameras stacked for the
        batched projectors of :mod:`hmocap_ros.render` (distortion padded to 8 coefficients)."""
        return camera_arrays(self.cameras)

    def isclose(self, other: "Rig", atol: float = 1e-9) -> bool:
        """Same frame, names and camera parameters within ``atol``."""
        return (
            isinstance(other, Rig)
            and self.frame_id == other.frame_id
            and self.names == other.names
            and all(a.isclose(b, atol=atol) for a, b in zip(self.cameras, other.cameras))
        )

    def __repr__(self) -> str:
        return f"Rig(frame_id={self.frame_id!r}, cameras={list(self.names)})"


def camera_arrays(cameras) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cameras (a Rig or a sequence of PinholeCamera) stacked as ``(K, R, t, D)``, float64,
    with the OpenCV distortion padded to 8 coefficients: the arguments of
    :func:`hmocap_ros.geometry.projection.project_batch` and the tracker's kernels."""
    cams = list(cameras)
    return (np.stack([np.asarray(c.K, np.float64) for c in cams]),
            np.stack([np.asarray(c.R, np.float64) for c in cams]),
            np.stack([np.asarray(c.t, np.float64).ravel() for c in cams]),
            np.stack([c.distortion8 for c in cams]))


# --------------------------------------------------------------------------------------------
# dict / YAML
# --------------------------------------------------------------------------------------------


def read_matrix_entry(entry: Any, where: str, field: str, rows: int | None, cols: int | None) -> np.ndarray:
    """Parse ``{rows, cols, data}`` into a ``(rows, cols)`` float array, checking the sizes."""
    if not isinstance(entry, dict) or not {"rows", "cols", "data"} <= set(entry):
        raise RigError(f"{where}: field {field!r} must be a mapping with rows, cols and data")
    try:
        r, c = int(entry["rows"]), int(entry["cols"])
        data = np.asarray(entry["data"], dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as error:
        raise RigError(f"{where}: field {field!r}: {error}") from None
    if (rows is not None and r != rows) or (cols is not None and c != cols):
        raise RigError(
            f"{where}: field {field!r} must be {rows if rows is not None else 'n'}x"
            f"{cols if cols is not None else 'n'}, got {r}x{c}"
        )
    if data.size != r * c:
        raise RigError(f"{where}: field {field!r} has {data.size} values for {r}x{c}")
    if not np.all(np.isfinite(data)):
        raise RigError(f"{where}: field {field!r} has non-finite values")
    return data.reshape(r, c)


def read_vector_entry(entry: Any, where: str, field: str, size: int) -> np.ndarray:
    """Parse a list of ``size`` finite numbers into a float array; RigError naming ``where``
    and ``field`` otherwise."""
    try:
        vector = np.asarray(entry, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        vector = np.zeros(0)
    if vector.shape != (size,) or not np.all(np.isfinite(vector)):
        raise RigError(f"{where}: field {field!r} must be a list of {size} finite numbers, got {entry!r}")
    return vector


def _camera_from_dict(entry: Any, index: int, source: str) -> PinholeCamera:
    if not isinstance(entry, dict):
        raise RigError(f"{source}: camera #{index} must be a mapping, got {type(entry).__name__}")
    name = entry.get("name")
    if not isinstance(name, str) or not name:
        raise RigError(f"{source}: camera #{index}: field 'name' is missing or not a string")
    where = f"{source}: camera {name!r}"
    unknown = sorted(set(entry) - _CAMERA_KEYS)
    if unknown:
        raise RigError(f"{where}: unknown field(s) {', '.join(map(repr, unknown))} "
                       f"(allowed: {', '.join(sorted(_CAMERA_KEYS))})")
    for field in ("image_width", "image_height", "camera_matrix", "distortion_model", "distortion_coefficients",
                  "pose"):
        if field not in entry:
            raise RigError(f"{where}: missing field {field!r}")
    size = {}
    for field in ("image_width", "image_height"):
        value = entry[field]
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            raise RigError(f"{where}: field {field!r} must be a positive integer, got {value!r}")
        size[field] = value
    model = entry["distortion_model"]
    if model not in DISTORTION_MODELS:
        raise RigError(f"{where}: field 'distortion_model' must be one of {', '.join(DISTORTION_MODELS)}, "
                       f"got {model!r}")
    K = read_matrix_entry(entry["camera_matrix"], where, "camera_matrix", 3, 3)
    D = read_matrix_entry(entry["distortion_coefficients"], where, "distortion_coefficients", 1, None).reshape(-1)
    if D.size > DISTORTION_MODELS[model]:
        raise RigError(f"{where}: field 'distortion_coefficients' has {D.size} values, "
                       f"{model} takes {DISTORTION_MODELS[model]}")
    rect = None
    if entry.get("rectification_matrix") is not None:
        rect = read_matrix_entry(entry["rectification_matrix"], where, "rectification_matrix", 3, 3)
    proj = None
    if entry.get("projection_matrix") is not None:
        proj = read_matrix_entry(entry["projection_matrix"], where, "projection_matrix", 3, 4)
    pose = entry["pose"]
    if not isinstance(pose, dict) or set(pose) != {"position", "orientation"}:
        raise RigError(f"{where}: field 'pose' must be a mapping with exactly position and orientation")
    position = read_vector_entry(pose["position"], where, "pose.position", 3)
    orientation = read_vector_entry(pose["orientation"], where, "pose.orientation", 4)
    norm = float(np.linalg.norm(orientation))
    if abs(norm - 1.0) > 1e-3:
        raise RigError(f"{where}: field 'pose.orientation' is not a unit quaternion (x, y, z, w): norm {norm:.6g}")
    frame_id = entry.get("frame_id") or ""
    if not isinstance(frame_id, str):
        raise RigError(f"{where}: field 'frame_id' must be a string, got {frame_id!r}")
    try:
        return PinholeCamera.from_pose(
            name=name, width=size["image_width"], height=size["image_height"], K=K,
            position=position, quaternion_xyzw=orientation, D=D, distortion_model=model,
            frame_id=frame_id, rectification=rect, projection=proj,
        )
    except ValueError as error:
        raise RigError(f"{where}: {error}") from None


def rig_from_dict(data: Any, source: str = "<rig>") -> Rig:
    """Build a :class:`Rig` from the parsed YAML structure (module docstring); ``source`` names
    the file in error messages."""
    if not isinstance(data, dict):
        raise RigError(f"{source}: a rig must be a mapping with frame_id and cameras, got {type(data).__name__}")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise RigError(f"{source}: unknown top-level field(s) {', '.join(map(repr, unknown))} "
                       "(allowed: frame_id, cameras)")
    for field in ("frame_id", "cameras"):
        if field not in data:
            raise RigError(f"{source}: missing top-level field {field!r}")
    frame_id = data["frame_id"]
    if not isinstance(frame_id, str) or not frame_id:
        raise RigError(f"{source}: field 'frame_id' must be a non-empty string, got {frame_id!r}")
    entries = data["cameras"]
    if not isinstance(entries, list) or not entries:
        raise RigError(f"{source}: field 'cameras' must be a non-empty list")
    cameras = tuple(_camera_from_dict(entry, i, source) for i, entry in enumerate(entries))
    names = [c.name for c in cameras]
    for name in names:
        if names.count(name) > 1:
            raise RigError(f"{source}: camera {name!r}: field 'name' is duplicated")
    return Rig(frame_id, cameras)


class FlowList(list):
    """A list dumped in YAML flow style (``[1, 2, 3]``)."""


class RigDumper(yaml.SafeDumper):
    """The YAML dumper of rig files: :class:`FlowList` values in flow style."""


RigDumper.add_representer(
    FlowList, lambda dumper, data: dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=True))


def matrix_entry(array: np.ndarray) -> dict:
    """An array as the ``{rows, cols, data}`` mapping of a rig file (the inverse of
    :func:`read_matrix_entry`)."""
    array = np.atleast_2d(np.asarray(array, dtype=np.float64))
    return {"rows": int(array.shape[0]), "cols": int(array.shape[1]), "data": FlowList(float(x) for x in array.ravel())}


def rig_to_dict(rig: Rig) -> dict:
    """The YAML structure of ``rig`` (plain Python types), inverse of :func:`rig_from_dict`."""
    cameras = []
    for camera in rig.cameras:
        assert camera.rectification is not None and camera.projection is not None  # filled by __post_init__
        cameras.append({
            "name": camera.name,
            "frame_id": camera.frame_id,
            "image_width": camera.width,
            "image_height": camera.height,
            "camera_matrix": matrix_entry(camera.K),
            "distortion_model": camera.distortion_model,
            "distortion_coefficients": matrix_entry(camera.D[None, :]),
            "rectification_matrix": matrix_entry(camera.rectification),
            "projection_matrix": matrix_entry(camera.projection),
            "pose": {
                "position": FlowList(float(x) for x in camera.position),
                "orientation": FlowList(float(x) for x in camera.pose_quaternion()),
            },
        })
    return {"frame_id": rig.frame_id, "cameras": cameras}


def load_rig(path: str | Path) -> Rig:
    """Read a rig YAML file (format in the module docstring); errors are :class:`RigError`."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as error:
        raise RigError(f"{path}: cannot read rig file: {error.strerror or error}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise RigError(f"{path}: invalid YAML: {error}") from None
    return rig_from_dict(data, source=str(path))


def save_rig(rig: Rig, path: str | Path, header: str | None = None) -> None:
    """Write ``rig`` as YAML (numbers in full precision, so :func:`load_rig` gives it back).

    ``header`` is written first as ``#`` comment lines.
    """
    lines = [] if header is None else [f"# {line}".rstrip() for line in header.splitlines()]
    body = yaml.dump(rig_to_dict(rig), Dumper=RigDumper, sort_keys=False, default_flow_style=False, width=120)
    Path(path).write_text("\n".join(lines + [body]))
