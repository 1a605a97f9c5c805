"""ROS ``camera_info`` YAML, one file per camera, with the camera's pose.

The intrinsics are the keys of a ``camera_calibration_parsers`` file (what ROS camera drivers
load through ``camera_info_url``, and what ``cameracalibrator`` writes): ``image_width``,
``image_height``, ``camera_name``, ``camera_matrix``, ``distortion_model``,
``distortion_coefficients``, ``rectification_matrix``, ``projection_matrix``. Those files carry
no pose, so the pose rides along under one more key, which ROS's parsers ignore:

.. code-block:: yaml

    pose:                       # the optical frame (x right, y down, z forward) in the world
      position: [x, y, z]       # metres
      orientation: [x, y, z, w] # unit quaternion, optical frame -> world

in a REP-103 world: metres, **+Z up** (``--up`` for another). A calibration is a folder of such
files (``<camera_name>.yaml``, one camera each, in name order) or a single file.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from hmocap_ros.calibration.formats.foreign import CalibrationFormatError, ForeignCalibration, ForeignCamera

__all__ = ["is_camera_info", "read_ros", "write_ros"]

_INTRINSIC_KEYS = ("image_width", "image_height", "camera_matrix", "distortion_coefficients")


def is_camera_info(data) -> bool:
    """Whether a parsed YAML document is a camera_calibration_parsers file."""
    return isinstance(data, dict) and all(key in data for key in _INTRINSIC_KEYS)


def _load(path: Path):
    try:
        return yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError) as error:
        raise CalibrationFormatError(f"{path}: cannot read: {error}") from None
    except yaml.YAMLError as error:
        raise CalibrationFormatError(f"{path}: invalid YAML ({str(error).splitlines()[0]})") from None


def _camera(path: Path, data) -> ForeignCamera:
    from hmocap_ros.geometry import quaternion_to_matrix
    from hmocap_ros.geometry.rig import RigError, read_matrix_entry, read_vector_entry

    name = str(data.get("camera_name") or path.stem)
    where = f"{path}: camera {name!r}"
    try:
        K = read_matrix_entry(data["camera_matrix"], where, "camera_matrix", 3, 3)
        D = read_matrix_entry(data["distortion_coefficients"], where, "distortion_coefficients", 1, None)
        pose = data.get("pose")
        if not isinstance(pose, dict) or not {"position", "orientation"} <= set(pose):
            raise CalibrationFormatError(
                f"{where}: no pose (add 'pose: {{position: [x, y, z], orientation: [x, y, z, w]}}', "
                f"the optical frame in the world, metres, +Z up)")
        position = read_vector_entry(pose["position"], where, "pose.position", 3)
        R_wc = quaternion_to_matrix(read_vector_entry(pose["orientation"], where, "pose.orientation", 4))
    except (RigError, ValueError) as error:
        if isinstance(error, CalibrationFormatError):
            raise
        raise CalibrationFormatError(str(error)) from None
    size = (data["image_width"], data["image_height"])
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in size):
        raise CalibrationFormatError(f"{where}: image_width and image_height must be integers")
    R = R_wc.T
    return ForeignCamera(name=name, size=size, K=K, D=D.ravel(), R=R, t=-R @ position)


def read_ros(path: str | Path) -> ForeignCalibration:
    """The cameras of a folder of camera_info YAML files, or of one file (module docstring)."""
    path = Path(path)
    files = sorted(p for p in path.iterdir() if p.suffix in (".yaml", ".yml")) if path.is_dir() else [path]
    cameras = []
    for file in files:
        data = _load(file)
        if is_camera_info(data):
            cameras.append(_camera(file, data))
    if not cameras:
        raise CalibrationFormatError(f"{path}: no camera_info YAML (image_width, image_height, "
                                     f"camera_matrix, distortion_coefficients)")
    return ForeignCalibration(tuple(cameras), up="+Z", metres_per_unit=1.0, source=str(path),
                              format="ros")


def write_ros(calibration: ForeignCalibration, path: str | Path) -> list[Path]:
    """One ``<name>.yaml`` per camera in the folder ``path`` (module docstring); returns the
    files written."""
    from hmocap_ros.geometry.rig import FlowList, RigDumper, matrix_entry
    from hmocap_ros.io.tf import rotation_to_quaternion

    folder = Path(path)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for camera in calibration.cameras:
        if camera.size is None:
            raise CalibrationFormatError(f"camera {camera.name!r}: a ROS camera_info file needs the image size")
        K = np.asarray(camera.K)
        D = np.pad(camera.D, (0, max(0, 5 - camera.D.size)))
        model = "plumb_bob" if D.size <= 5 else "rational_polynomial"
        R_wc = np.asarray(camera.R).T
        data = {
            "image_width": int(camera.size[0]),
            "image_height": int(camera.size[1]),
            "camera_name": camera.name,
            "camera_matrix": matrix_entry(K),
            "distortion_model": model,
            "distortion_coefficients": matrix_entry(D[None, :]),
            "rectification_matrix": matrix_entry(np.eye(3)),
            "projection_matrix": matrix_entry(np.hstack([K, np.zeros((3, 1))])),
            "pose": {"position": FlowList(float(v) for v in camera.centre),
                     "orientation": FlowList(float(v) for v in rotation_to_quaternion(R_wc))},
        }
        file = folder / f"{camera.name}.yaml"
        file.write_text(yaml.dump(data, Dumper=RigDumper, sort_keys=False, width=120))
        written.append(file)
    return written
