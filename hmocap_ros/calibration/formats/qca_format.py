"""Qualisys Track Manager's calibration export (``.qca``, XML; Pose2Sim ships one as
``Calib.qca.txt``).

Per camera (``<calibration><cameras><camera serial=...>``):

* ``<fov_video left top right bottom>``: the video image's rectangle on the sensor (right and
  bottom are inclusive pixel indices), so the image is ``right - left + 1`` by
  ``bottom - top + 1`` pixels;
* ``<intrinsic>``: ``focalLengthU/V`` and ``centerPointU/V`` in 1/64 pixel of the sensor (U along
  the image's rows, so a portrait 1088 x 1920 sensor has ``sensorMaxU`` 1087 x 64); the principal
  point in the video image is the sensor's minus the rectangle's ``left``/``top``;
  ``radialDistortion1..3`` and ``tangentalDistortion1..2`` are OpenCV's ``k1, k2, k3`` and
  ``p1, p2`` in normalised coordinates, as they are: Pose2Sim's own scene calibration of the
  four cameras of its demo gives k1 -0.03 to -0.05 and k2 0.01 to 0.15 where their ``.qca``
  says -0.046 to -0.048 and 0.135 to 0.140 (Pose2Sim's ``read_qca`` divides them by 64 as well,
  which leaves the lenses without distortion; the landmarks below do not tell the two apart,
  the person staying near the images' centres);
* ``<transform x y z r11 .. r33>``: the camera centre ``C`` in the world in millimetres, and
  ``R_qca`` read row by row; world -> camera in OpenCV's optical frame (x right, y down,
  z forward) is ``R = diag(1, -1, -1) R_qca``, ``t = -R C`` (Qualisys' camera looks along its
  -z with y up). Checked on the first 100 frame sets of Pose2Sim's demo: BlazePose's landmarks
  seen by all four views, triangulated, reproject with a median of 12-19 px per view at
  1088 x 1920; without the flip, or with ``R_qca`` transposed, 45-436 px.

The world is Z-up, in millimetres.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from hmocap_ros.calibration.formats.foreign import CalibrationFormatError, ForeignCalibration, ForeignCamera

__all__ = ["QCA_UNITS_PER_PIXEL", "read_qca", "write_qca"]

#: Sub-pixel unit of the ``<intrinsic>`` focal lengths and principal points.
QCA_UNITS_PER_PIXEL = 64.0
#: Qualisys' camera frame (y up, looking along -z) -> OpenCV's optical frame.
_FLIP = np.diag([1.0, -1.0, -1.0])


def _attributes(element, names, where: str) -> list[float]:
    values = []
    for name in names:
        text = element.get(name)
        try:
            values.append(float(text))
        except (TypeError, ValueError):
            raise CalibrationFormatError(f"{where}: <{element.tag}> {name}={text!r} is not a "
                                         f"number") from None
    if not np.all(np.isfinite(values)):
        raise CalibrationFormatError(f"{where}: <{element.tag}> has non-finite values")
    return values


def _child(camera, tag: str, where: str):
    element = camera.find(tag)
    if element is None:
        raise CalibrationFormatError(f"{where}: no <{tag}>")
    return element


def read_qca(path: str | Path) -> ForeignCalibration:
    """The cameras of a QTM calibration file (module docstring), in file order, named by their
    ``serial``."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except OSError as error:
        raise CalibrationFormatError(f"{path}: cannot read: {error.strerror or error}") from None
    except ET.ParseError as error:
        raise CalibrationFormatError(f"{path}: not valid XML ({error})") from None
    if root.tag != "calibration":
        raise CalibrationFormatError(f"{path}: the XML root is <{root.tag}>, a Qualisys "
                                     f"calibration's is <calibration>")
    cameras, notes = [], []
    for index, camera in enumerate(root.findall("cameras/camera")):
        name = camera.get("serial") or f"camera_{index + 1}"
        where = f"{path}: camera {name!r}"
        left, top, right, bottom = _attributes(_child(camera, "fov_video", where),
                                               ("left", "top", "right", "bottom"), where)
        intrinsic = _child(camera, "intrinsic", where)
        fu, fv, cu, cv = (v / QCA_UNITS_PER_PIXEL for v in _attributes(
            intrinsic, ("focalLengthU", "focalLengthV", "centerPointU", "centerPointV"), where))
        k1, k2, k3, p1, p2 = _attributes(
            intrinsic, ("radialDistortion1", "radialDistortion2", "radialDistortion3",
                        "tangentalDistortion1", "tangentalDistortion2"), where)
        transform = _child(camera, "transform", where)
        x, y, z, *r = _attributes(transform, ("x", "y", "z", "r11", "r12", "r13", "r21", "r22",
                                              "r23", "r31", "r32", "r33"), where)
        R = _FLIP @ np.asarray(r, dtype=np.float64).reshape(3, 3)
        if camera.get("viewrotation", "0") not in ("0", ""):
            notes.append(f"{where}: viewrotation {camera.get('viewrotation')} (the calibration "
                         f"is of the sensor's image; a video turned by QTM needs --rotate)")
        K = np.array([[fu, 0.0, cu - left], [0.0, fv, cv - top], [0.0, 0.0, 1.0]])
        cameras.append(ForeignCamera(
            name=name, size=(int(right - left + 1), int(bottom - top + 1)), K=K,
            D=np.array([k1, k2, p1, p2, k3]), R=R, t=-R @ np.array([x, y, z])))
    if not cameras:
        raise CalibrationFormatError(f"{path}: no <cameras><camera> in the calibration")
    return ForeignCalibration(tuple(cameras), up="+Z", metres_per_unit=0.001, source=str(path),
                              format="qca", notes=tuple(notes))


def write_qca(calibration: ForeignCalibration, path: str | Path) -> list[Path]:
    """Write ``calibration`` (a Z-up world in millimetres) as a QTM calibration file; returns the
    files written. Distortion beyond ``k1, k2, p1, p2, k3`` cannot be written."""
    root = ET.Element("calibration", {"source": "hmocap_ros", "type": "regular"})
    ET.SubElement(root, "results", {"std-dev": "0.", "min-max-diff": "0."})
    cameras = ET.SubElement(root, "cameras")
    for camera in calibration.cameras:
        D = np.pad(camera.D, (0, max(0, 5 - camera.D.size)))
        if np.any(D[5:] != 0):
            raise CalibrationFormatError(f"camera {camera.name!r}: the rational distortion "
                                         f"terms (k4-k6) have no place in a .qca file")
        if camera.K[0, 1] != 0:
            raise CalibrationFormatError(f"camera {camera.name!r}: a skewed camera matrix has no "
                                         f"place in a .qca file")
        if camera.size is None:
            raise CalibrationFormatError(f"camera {camera.name!r}: a .qca file needs the image size")
        w, h = camera.size
        element = ET.SubElement(cameras, "camera", {"active": "1", "serial": camera.name,
                                                    "model": "none", "viewrotation": "0"})
        box = {"left": "0", "top": "0", "right": str(w - 1), "bottom": str(h - 1)}
        for tag in ("fov_marker", "fov_marker_max", "fov_video", "fov_video_max"):
            ET.SubElement(element, tag, box)
        R_qca = _FLIP @ camera.R
        centre = camera.centre
        transform = {"x": repr(float(centre[0])), "y": repr(float(centre[1])),
                     "z": repr(float(centre[2]))}
        for i in range(3):
            for j in range(3):
                transform[f"r{i + 1}{j + 1}"] = repr(float(R_qca[i, j]))
        ET.SubElement(element, "transform", transform)
        K = camera.K
        ET.SubElement(element, "intrinsic", {
            "focalLengthU": repr(float(K[0, 0] * QCA_UNITS_PER_PIXEL)),
            "focalLengthV": repr(float(K[1, 1] * QCA_UNITS_PER_PIXEL)),
            "centerPointU": repr(float(K[0, 2] * QCA_UNITS_PER_PIXEL)),
            "centerPointV": repr(float(K[1, 2] * QCA_UNITS_PER_PIXEL)),
            "sensorMinU": "0", "sensorMinV": "0",
            "sensorMaxU": repr(float((w - 1) * QCA_UNITS_PER_PIXEL)),
            "sensorMaxV": repr(float((h - 1) * QCA_UNITS_PER_PIXEL)),
            "skew": "0",
            "radialDistortion1": repr(float(D[0])), "radialDistortion2": repr(float(D[1])),
            "radialDistortion3": repr(float(D[4])),
            "tangentalDistortion1": repr(float(D[2])), "tangentalDistortion2": repr(float(D[3]))})
    ET.indent(root)
    path = Path(path)
    ET.ElementTree(root).write(path, encoding="ASCII", xml_declaration=True)
    return [path]
