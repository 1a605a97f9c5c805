"""From another tool's world to the package's room frame and back.

The room frame (:mod:`hmocap_ros.geometry`): metres, right-handed, **+Y up**, the floor at
``y = 0``. Other tools' worlds are Z-up (Qualisys, Pose2Sim, REP-103 ``world``), Y-up, or the
first camera's frame (Anipose), in metres or millimetres. A calibration becomes a room-frame rig
by one similarity transform ``x_room = s A x_world - s f e_y``:

* ``A`` is the rotation that takes the world's up axis to +Y (:func:`up_rotation`: the world's
  +X stays the room's +x unless it is the up axis; a Z-up world maps ``(X, Y, Z)`` to
  ``(X, Z, -Y)``, the inverse of :data:`hmocap_ros.io.tf.Y_UP_TO_Z_UP`);
* ``s`` is the file's unit in metres;
* ``f`` is the floor's height along the up axis in the file's unit (0: the world's origin lies
  on the floor, as a Qualisys L-frame or a board laid on the floor puts it).

A camera ``x_cam = R x_world + t`` (file units) becomes, in metres,
``x_cam = (R A^T) x_room + s (t + R A^T f e_y)``.

Where the file does not say (TOML, OpenCV FileStorage):

* **up** (:func:`guess_up`): room cameras stand upright, so the mean of the cameras' image-up
  directions (minus their optical y axis) points up; the world axis nearest to it is taken when
  it lies within :data:`MAX_UP_ANGLE_DEG`, else the user must say (``--up``).
* **unit** (:func:`guess_metres_per_unit`): a room's cameras stand 1-30 m from their centroid;
  a median distance up to :data:`METRE_SPREAD_MAX` is read as metres, from
  :data:`MILLIMETRE_SPREAD_MIN` on as millimetres, and between the two the user must say
  (``--units``).
"""
from __future__ import annotations

import numpy as np

from hmocap_ros.calibration.formats.foreign import CalibrationFormatError, ForeignCalibration, ForeignCamera

__all__ = ["AXES", "MAX_UP_ANGLE_DEG", "UNITS", "calibration_from_rig", "calibration_to_rig",
           "guess_metres_per_unit", "guess_up", "parse_axis", "up_rotation"]

#: Axis names accepted for ``--up``.
AXES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
#: Length units accepted for ``--units``, in metres.
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
#: Largest angle between the cameras' mean image-up direction and a world axis taken as up.
MAX_UP_ANGLE_DEG = 30.0
#: Median distance of the cameras from their centroid (file units) read as metres up to this ...
METRE_SPREAD_MAX = 30.0
#: ... and as millimetres from this on.
MILLIMETRE_SPREAD_MIN = 300.0


def parse_axis(text: str) -> str:
    """``"z"``, ``"Z"``, ``"+z"`` -> ``"+Z"``; ``"-y"`` -> ``"-Y"``; ValueError otherwise."""
    value = str(text).strip().upper()
    if len(value) == 1:
        value = "+" + value
    if value not in AXES:
        raise ValueError(f"an up axis is one of {', '.join(AXES)}, got {text!r}")
    return value


def _axis_vector(axis: str) -> np.ndarray:
    axis = parse_axis(axis)
    vector = np.zeros(3)
    vector["XYZ".index(axis[1])] = 1.0 if axis[0] == "+" else -1.0
    return vector


def up_rotation(axis: str) -> np.ndarray:
    """The rotation ``A`` (3, 3) taking world vectors to room vectors so that the world's
    ``axis`` becomes the room's +Y; its rows are the room's x, y, z axes in world coordinates:
    y the up axis, x the world's X (the world's Y when X is up), z = x cross y."""
    up = _axis_vector(axis)
    x = np.array([1.0, 0.0, 0.0]) if up[0] == 0 else np.array([0.0, 1.0, 0.0])
    return np.stack([x, up, np.cross(x, up)])


def guess_up(cameras) -> tuple[str, float]:
    """The world axis nearest to the cameras' mean image-up direction, and the angle (deg)
    between them (module docstring). ``CalibrationFormatError`` when the cameras' up
    directions cancel out."""
    ups = np.stack([-np.asarray(c.R)[1] for c in cameras])
    mean = ups.mean(axis=0)
    norm = float(np.linalg.norm(mean))
    if norm < 1e-6:
        raise CalibrationFormatError("the cameras' image-up directions cancel out: the up axis "
                                     "cannot be told from them")
    mean /= norm
    k = int(np.argmax(np.abs(mean)))
    axis = ("+" if mean[k] > 0 else "-") + "XYZ"[k]
    angle = float(np.degrees(np.arccos(np.clip(abs(mean[k]), -1.0, 1.0))))
    return axis, angle


def guess_metres_per_unit(cameras) -> float | None:
    """1.0 (metres) or 0.001 (millimetres) from the cameras' spread (module docstring); None
    when the spread fits neither (or there is one camera)."""
    centres = np.stack([c.centre for c in cameras])
    if len(centres) < 2:
        return None
    spread = float(np.median(np.linalg.norm(centres - centres.mean(axis=0), axis=1)))
    if spread <= METRE_SPREAD_MAX:
        return 1.0
    if spread >= MILLIMETRE_SPREAD_MIN:
        return 0.001
    return None


def _distortion(D: np.ndarray) -> tuple[np.ndarray, str]:
    if D.size <= 5:
        return np.pad(D, (0, 5 - D.size)), "plumb_bob"
    return np.pad(D, (0, 8 - D.size)), "rational_polynomial"


def calibration_to_rig(calibration: ForeignCalibration, *, up: str | None = None,
                       metres_per_unit: float | None = None, floor: float = 0.0,
                       sizes: dict | None = None, frame_id: str = "room"):
    """The :class:`~hmocap_ros.geometry.rig.Rig` of ``calibration`` in the room frame (module
    docstring), and the notes on what was guessed.

    ``up`` and ``metres_per_unit`` override what the file says; where neither the file nor the
    caller says, they are guessed from the cameras (module docstring). ``floor``: the floor's
    height along the up axis, in the file's unit. ``sizes``: camera name -> (width, height) for
    cameras whose file gives no image size. ``CalibrationFormatError`` when something can be
    neither read nor guessed.
    """
    from hmocap_ros.geometry import PinholeCamera
    from hmocap_ros.geometry.rig import Rig

    notes = list(calibration.notes)
    source = calibration.source
    if up is None:
        up = calibration.up
    if up is None:
        up, angle = guess_up(calibration.cameras)
        if angle > MAX_UP_ANGLE_DEG:
            raise CalibrationFormatError(
                f"{source}: the cameras' mean image-up direction is {angle:.0f} deg from the "
                f"nearest world axis ({up}): give the world's up axis (--up)")
        notes.append(f"{source}: up axis {up}, from the cameras' image-up directions "
                     f"({angle:.0f} deg from it; --up to change)")
    up = parse_axis(up)
    scale = metres_per_unit if metres_per_unit is not None else calibration.metres_per_unit
    if scale is None:
        scale = guess_metres_per_unit(calibration.cameras)
        if scale is None:
            raise CalibrationFormatError(
                f"{source}: the file does not say its length unit and the cameras' spread does "
                f"not tell metres from millimetres: give --units")
        notes.append(f"{source}: lengths read as {'metres' if scale == 1.0 else 'millimetres'} "
                     f"from the cameras' spread (--units to change)")
    if not np.isfinite(scale) or scale <= 0:
        raise CalibrationFormatError(f"metres per unit must be positive, got {scale}")
    A = up_rotation(up)
    offset = np.array([0.0, float(floor), 0.0])
    cameras = []
    for camera in calibration.cameras:
        size = camera.size or (sizes or {}).get(camera.name)
        if size is None:
            raise CalibrationFormatError(f"{source}: camera {camera.name!r} has no image size in "
                                         f"the file: give it (--size WIDTHxHEIGHT)")
        R = camera.R @ A.T
        t = scale * camera.t + scale * (R @ offset)
        D, model = _distortion(camera.D)
        try:
            cameras.append(PinholeCamera(name=camera.name, width=size[0], height=size[1],
                                         K=camera.K, D=D, R=R, t=t, distortion_model=model))
        except ValueError as error:
            raise CalibrationFormatError(f"{source}: {error}") from None
    return Rig(frame_id, tuple(cameras)), notes


def calibration_from_rig(rig, *, up: str = "+Z", metres_per_unit: float = 1.0,
                         format: str = "", source: str = "<rig>") -> ForeignCalibration:
    """The cameras of a room-frame ``rig`` in a world whose up axis is ``up`` and whose unit is
    ``metres_per_unit`` metres, the floor at the origin (the inverse of
    :func:`calibration_to_rig`)."""
    up = parse_axis(up)
    A = up_rotation(up)
    cameras = []
    for camera in rig.cameras:
        D = np.asarray(camera.D, dtype=np.float64)
        cameras.append(ForeignCamera(name=camera.name, size=(camera.width, camera.height),
                                     K=np.array(camera.K), D=D, R=np.asarray(camera.R) @ A,
                                     t=np.asarray(camera.t) / metres_per_unit))
    return ForeignCalibration(tuple(cameras), up=up, metres_per_unit=metres_per_unit,
                              source=source, format=format)
