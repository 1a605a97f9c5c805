"""OpenCV FileStorage calibrations in EasyMocap's layout: ``intri.yml`` and ``extri.yml`` (or
``.xml``) side by side.

EasyMocap's ``easymocap/mytools/camera_utils.py`` (``read_camera``, ``write_camera``):

* ``intri.yml``: ``names`` (a list of camera names), per camera ``K_<name>`` (3 x 3),
  ``dist_<name>`` (1 x 5: k1, k2, p1, p2, k3; ``D_<name>`` in some files) and optionally
  ``H_<name>`` / ``W_<name>`` (the image size);
* ``extri.yml``: ``names``, per camera ``R_<name>`` (a Rodrigues vector), ``Rot_<name>`` (the
  same rotation as a 3 x 3 matrix) and ``T_<name>`` (3 x 1), world -> camera.

The files are read and written with ``cv2.FileStorage`` (``%YAML:1.0`` with
``!!opencv-matrix`` nodes, or ``<opencv_storage>`` XML). The world's up axis and length unit are
not in the files (EasyMocap works in metres; its worlds are mostly Z-up): left to
:mod:`~hmocap_ros.calibration.formats.world_frame`. Without ``H``/``W`` the image size comes
from elsewhere (the videos of ``hmocap import videos``, ``--size``).
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from hmocap_ros.calibration.formats.foreign import CalibrationFormatError, ForeignCalibration, ForeignCamera

__all__ = ["find_pair", "read_opencv", "write_opencv"]

_SUFFIXES = (".yml", ".yaml", ".xml")


def find_pair(path: str | Path) -> tuple[Path, Path] | None:
    """``(intri, extri)`` for a folder holding both, or for one of the two files; None when
    there is no such pair."""
    path = Path(path)
    folder = path if path.is_dir() else path.parent
    suffixes = _SUFFIXES if path.is_dir() else (path.suffix,)
    if not path.is_dir() and not path.name.startswith(("intri.", "extri.")):
        return None
    for suffix in suffixes:
        intri, extri = folder / f"intri{suffix}", folder / f"extri{suffix}"
        if intri.is_file() and extri.is_file():
            return intri, extri
    return None


def _open(path: Path):
    try:
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error as error:
        reason = str(error).strip().splitlines()[-1][:160]
        raise CalibrationFormatError(f"{path}: not an OpenCV FileStorage file ({reason})") from None
    if not storage.isOpened():
        raise CalibrationFormatError(f"{path}: cannot open as an OpenCV FileStorage file")
    return storage


def _names(storage, path: Path) -> list[str]:
    node = storage.getNode("names")
    if node.empty() or not node.isSeq():
        raise CalibrationFormatError(f"{path}: no 'names' list of cameras")
    names = []
    for i in range(node.size()):
        item = node.at(i)
        names.append(item.string() if item.isString() else str(int(item.real())))
    return names


def _matrix(storage, key: str, path: Path, sizes: tuple[int, ...]) -> np.ndarray | None:
    node = storage.getNode(key)
    if node.empty():
        return None
    matrix = node.mat()
    if matrix is None or matrix.size not in sizes or not np.all(np.isfinite(matrix)):
        raise CalibrationFormatError(f"{path}: {key} must be a matrix of "
                                     f"{' or '.join(map(str, sizes))} finite values")
    return np.asarray(matrix, dtype=np.float64)


def _integer(storage, key: str) -> int | None:
    node = storage.getNode(key)
    return None if node.empty() else int(node.real())


def read_opencv(path: str | Path) -> ForeignCalibration:
    """The cameras of an EasyMocap ``intri``/``extri`` pair (module docstring): ``path`` is the
    folder or one of the two files. Cameras in the order of ``intri``'s ``names``."""
    pair = find_pair(path)
    if pair is None:
        raise CalibrationFormatError(f"{path}: no intri.yml and extri.yml (or .yaml, .xml) pair")
    intri_path, extri_path = pair
    intri, extri = _open(intri_path), _open(extri_path)
    names = _names(intri, intri_path)
    extri_names = set(_names(extri, extri_path))
    cameras = []
    for name in names:
        if name not in extri_names:
            raise CalibrationFormatError(f"{extri_path}: camera {name!r} of {intri_path.name} has "
                                         f"no extrinsics")
        K = _matrix(intri, f"K_{name}", intri_path, (9,))
        if K is None:
            raise CalibrationFormatError(f"{intri_path}: no K_{name}")
        D = _matrix(intri, f"dist_{name}", intri_path, (4, 5, 8))
        if D is None:
            D = _matrix(intri, f"D_{name}", intri_path, (4, 5, 8))
        rotation = _matrix(extri, f"Rot_{name}", extri_path, (9,))
        if rotation is None:
            rvec = _matrix(extri, f"R_{name}", extri_path, (3,))
            if rvec is None:
                raise CalibrationFormatError(f"{extri_path}: no R_{name} or Rot_{name}")
            rotation = cv2.Rodrigues(rvec.reshape(3, 1))[0]
        T = _matrix(extri, f"T_{name}", extri_path, (3,))
        if T is None:
            raise CalibrationFormatError(f"{extri_path}: no T_{name}")
        height, width = _integer(intri, f"H_{name}"), _integer(intri, f"W_{name}")
        size = (width, height) if width and height and width > 0 and height > 0 else None
        cameras.append(ForeignCamera(name=name, size=size, K=K.reshape(3, 3),
                                     D=np.zeros(0) if D is None else D.ravel(),
                                     R=rotation.reshape(3, 3), t=T.ravel()))
    intri.release()
    extri.release()
    return ForeignCalibration(tuple(cameras), source=str(intri_path.parent), format="opencv")


def _write_names(storage, names) -> None:
    storage.startWriteStruct("names", cv2.FileNode_SEQ)
    for name in names:
        storage.write("", name)
    storage.endWriteStruct()


def write_opencv(calibration: ForeignCalibration, path: str | Path) -> list[Path]:
    """Write EasyMocap's pair (module docstring) into the folder ``path`` (``intri.yml`` and
    ``extri.yml``), or beside ``path`` when it names ``intri.<suffix>`` (``.xml`` for XML);
    returns the files written."""
    path = Path(path)
    if path.name.startswith("intri.") and path.suffix in _SUFFIXES:
        folder, suffix = path.parent, path.suffix
    else:
        folder, suffix = path, ".yml"
    folder.mkdir(parents=True, exist_ok=True)
    intri_path, extri_path = folder / f"intri{suffix}", folder / f"extri{suffix}"
    intri = cv2.FileStorage(str(intri_path), cv2.FILE_STORAGE_WRITE)
    extri = cv2.FileStorage(str(extri_path), cv2.FILE_STORAGE_WRITE)
    names = list(calibration.names)
    _write_names(intri, names)
    _write_names(extri, names)
    for camera in calibration.cameras:
        D = np.pad(camera.D, (0, max(0, 5 - camera.D.size)))
        intri.write(f"K_{camera.name}", np.asarray(camera.K, dtype=np.float64))
        intri.write(f"dist_{camera.name}", D.reshape(1, -1))
        if camera.size is not None:
            intri.write(f"H_{camera.name}", int(camera.size[1]))
            intri.write(f"W_{camera.name}", int(camera.size[0]))
        R = np.asarray(camera.R, dtype=np.float64)
        extri.write(f"R_{camera.name}", cv2.Rodrigues(R)[0])
        extri.write(f"Rot_{camera.name}", R)
        extri.write(f"T_{camera.name}", np.asarray(camera.t, dtype=np.float64).reshape(3, 1))
    intri.release()
    extri.release()
    return [intri_path, extri_path]
