"""Other tools' calibration files: readers, writers, and the way into the package's room frame.

Formats (:data:`FORMATS`, one entry each; :func:`detect_format` tells them apart by content):

===========  =========================================================  ==========  ===========
name         files                                                       world up    unit
===========  =========================================================  ==========  ===========
``rig``      this package's rig YAML (:mod:`hmocap_ros.geometry.rig`)             +Y          metre
``toml``     Pose2Sim / Anipose ``Calib.toml`` (:mod:`.toml_format`)     guessed     guessed
``qca``      Qualisys ``.qca`` XML (:mod:`.qca_format`)                  +Z          millimetre
``opencv``   OpenCV FileStorage ``intri.yml`` + ``extri.yml``,           guessed     guessed
             EasyMocap's layout (:mod:`.opencv_format`)
``ros``      a folder of ROS camera_info YAML files with poses           +Z          metre
             (:mod:`.ros_format`)
===========  =========================================================  ==========  ===========

:func:`load_calibration_rig` reads any of them into a :class:`~hmocap_ros.geometry.rig.Rig` in the room
frame (:mod:`.world_frame`: the up axis and unit the file states, the caller gives, or the
cameras tell); :func:`save_calibration_rig` writes a rig in any of them. ``hmocap rig convert``
and ``hmocap import videos`` are built on these two.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from hmocap_ros.calibration.formats.foreign import CalibrationFormatError, ForeignCalibration, ForeignCamera
from hmocap_ros.calibration.formats.opencv_format import find_pair, read_opencv, write_opencv
from hmocap_ros.calibration.formats.qca_format import read_qca, write_qca
from hmocap_ros.calibration.formats.ros_format import is_camera_info, read_ros, write_ros
from hmocap_ros.calibration.formats.toml_format import read_toml, write_toml
from hmocap_ros.calibration.formats.world_frame import AXES, UNITS, calibration_from_rig, calibration_to_rig, parse_axis

__all__ = ["AXES", "FORMATS", "UNITS", "CalibrationFormat", "CalibrationFormatError",
           "ForeignCalibration", "ForeignCamera", "detect_format", "load_calibration_rig",
           "read_calibration", "save_calibration_rig"]


def _read_rig(path) -> ForeignCalibration:
    from hmocap_ros.geometry.rig import RigError, load_rig

    try:
        rig = load_rig(path)
    except RigError as error:
        raise CalibrationFormatError(str(error)) from None
    return calibration_from_rig(rig, up="+Y", metres_per_unit=1.0, format="rig", source=str(path))


def _write_rig(calibration: ForeignCalibration, path) -> list[Path]:
    from hmocap_ros.geometry.rig import save_rig

    rig, _ = calibration_to_rig(calibration)
    save_rig(rig, path, header=f"camera rig converted from {calibration.source} by hmocap rig convert")
    return [Path(path)]


@dataclass(frozen=True)
class CalibrationFormat:
    """A calibration format: its reader, its writer, and the world its writer writes (up axis,
    metres per unit)."""

    name: str
    description: str
    read: Callable[[Path], ForeignCalibration]
    write: Callable[[ForeignCalibration, Path], list]
    up: str
    metres_per_unit: float


#: The formats by name (module docstring).
FORMATS = {f.name: f for f in (
    CalibrationFormat("rig", "hmocap_ros rig YAML", _read_rig, _write_rig, "+Y", 1.0),
    CalibrationFormat("toml", "Pose2Sim / Anipose TOML", read_toml, write_toml, "+Z", 1.0),
    CalibrationFormat("qca", "Qualisys QCA (XML)", read_qca, write_qca, "+Z", 0.001),
    CalibrationFormat("opencv", "OpenCV FileStorage intri/extri (EasyMocap)", read_opencv,
                      write_opencv, "+Z", 1.0),
    CalibrationFormat("ros", "ROS camera_info YAML per camera, with poses", read_ros, write_ros,
                      "+Z", 1.0),
)}


def _sniff(path: Path) -> str:
    try:
        with open(path, "rb") as handle:
            return handle.read(4096).decode("utf-8", errors="replace")
    except OSError as error:
        raise CalibrationFormatError(f"{path}: cannot read: {error.strerror or error}") from None


def detect_format(path: str | Path) -> str:
    """The name of the format of ``path`` (a file or a folder), from its content;
    ``CalibrationFormatError`` for a path in none of them."""
    import yaml

    path = Path(path)
    if not path.exists():
        raise CalibrationFormatError(f"{path}: no such file or folder")
    if find_pair(path) is not None:
        return "opencv"
    if path.is_dir():
        try:
            read_ros(path)
        except CalibrationFormatError:
            raise CalibrationFormatError(
                f"{path}: a folder with neither intri.yml + extri.yml (OpenCV) nor camera_info "
                f"YAML files (ROS)") from None
        return "ros"
    head = _sniff(path).lstrip("\ufeff \t\r\n")
    if head.startswith("<?xml") or head.startswith("<"):
        return "qca" if "<calibration" in head else _unknown(path, "an XML file that is not a "
                                                             "Qualisys calibration")
    if head.startswith("%YAML:1.0"):
        return _unknown(path, "an OpenCV FileStorage file without its intri/extri partner")
    if path.suffix == ".toml":
        return "toml"
    try:
        data = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError, OSError):
        data = None
    if isinstance(data, dict) and "cameras" in data:
        return "rig"
    if is_camera_info(data):
        return "ros"
    try:
        import tomllib

        tomllib.loads(path.read_text())
        return "toml"
    except (tomllib.TOMLDecodeError, UnicodeDecodeError):
        pass
    return _unknown(path, "not a calibration in any known format")


def _unknown(path: Path, what: str) -> str:
    raise CalibrationFormatError(f"{path}: {what} (formats: rig YAML, Pose2Sim/Anipose TOML, "
                                 f"Qualisys .qca, OpenCV intri.yml + extri.yml, ROS camera_info "
                                 f"YAML)")


def read_calibration(path: str | Path, format: str | None = None) -> ForeignCalibration:
    """The cameras of ``path`` in its own world (``format``: a name of :data:`FORMATS`, or None
    to detect it)."""
    name = format or detect_format(path)
    if name not in FORMATS:
        raise CalibrationFormatError(f"unknown calibration format {name!r} (formats: "
                                     f"{', '.join(FORMATS)})")
    return FORMATS[name].read(Path(path))


def load_calibration_rig(path: str | Path, *, format: str | None = None, up: str | None = None,
                         units: str | None = None, floor: float = 0.0, sizes: dict | None = None,
                         frame_id: str = "room"):
    """A calibration file of any format as a room-frame :class:`~hmocap_ros.geometry.rig.Rig`, and the
    notes on what was guessed (:func:`.world_frame.calibration_to_rig`). ``units``: a key of
    :data:`UNITS` overriding the file's (or the guess)."""
    calibration = read_calibration(path, format)
    scale = None
    if units is not None:
        if units not in UNITS:
            raise CalibrationFormatError(f"units must be one of {', '.join(UNITS)}, got {units!r}")
        scale = UNITS[units]
    return calibration_to_rig(calibration, up=None if up is None else parse_axis(up),
                              metres_per_unit=scale, floor=floor, sizes=sizes, frame_id=frame_id)


def save_calibration_rig(rig, path: str | Path, format: str, *, up: str | None = None,
                         units: str | None = None) -> list[Path]:
    """Write a room-frame rig in ``format`` (its world: ``up`` and ``units``, by default the
    format's); returns the files written."""
    if format not in FORMATS:
        raise CalibrationFormatError(f"unknown calibration format {format!r} (formats: "
                                     f"{', '.join(FORMATS)})")
    spec = FORMATS[format]
    scale = spec.metres_per_unit if units is None else UNITS[units]
    calibration = calibration_from_rig(rig, up=spec.up if up is None else parse_axis(up),
                                       metres_per_unit=scale, format=format, source=str(path))
    try:
        return spec.write(calibration, Path(path))
    except OSError as error:
        raise CalibrationFormatError(f"{path}: cannot write: {error.strerror or error}") from None
