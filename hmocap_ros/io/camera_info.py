"""``sensor_msgs/CameraInfo`` <-> the plain camera dict that
:meth:`~hmocap_ros.geometry.PinholeCamera.from_camera_info` reads.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hmocap_ros.io.conversion_errors import CameraInfoConversionError
from hmocap_ros.io.msg_factory import make_header, resolve_factory

__all__ = ["CAMERA_INFO_KEYS", "camera_info_to_dict", "dict_to_camera_info"]

CAMERA_INFO_KEYS = ("width", "height", "K", "D", "distortion_model", "R", "P", "frame_id")


def camera_info_to_dict(msg: Any) -> dict[str, Any]:
    """Return a ``sensor_msgs/CameraInfo`` as a plain dict (the PinholeCamera input).

    Keys (exactly :data:`CAMERA_INFO_KEYS`): ``width``, ``height`` (int), ``K`` (3x3),
    ``D`` (1-D), ``R`` (3x3), ``P`` (3x4), all ``float64`` copies, ``distortion_model`` and
    ``frame_id`` (str). An all-zero ``K`` (uncalibrated camera) is returned as is.

    Raises:
        CameraInfoConversionError: if k/r/p do not hold 9/9/12 finite numbers or d is not
            finite.
    """
    return {
        "width": int(msg.width),
        "height": int(msg.height),
        "K": _matrix(msg.k, (3, 3), "k"),
        "D": _matrix(msg.d, None, "d"),
        "distortion_model": str(msg.distortion_model),
        "R": _matrix(msg.r, (3, 3), "r"),
        "P": _matrix(msg.p, (3, 4), "p"),
        "frame_id": str(msg.header.frame_id),
    }


def dict_to_camera_info(d: dict[str, Any], stamp_ns: int = 0, factory: Any = None) -> Any:
    """Build a ``sensor_msgs/CameraInfo`` from a :func:`camera_info_to_dict`-style dict.

    ``width``, ``height`` and ``K`` (3x3 or 9 numbers) are required. Defaults: ``D`` empty,
    ``distortion_model`` "plumb_bob", ``R`` identity, ``P`` = ``[K | 0]``, ``frame_id`` "".

    Raises:
        CameraInfoConversionError: missing or unknown keys, non-positive size, matrices of the
            wrong size or with non-finite values.
    """
    missing = [key for key in ("width", "height", "K") if key not in d]
    if missing:
        raise CameraInfoConversionError(f"camera dict lacks required key(s) {missing}")
    unknown = sorted(set(d) - set(CAMERA_INFO_KEYS))
    if unknown:
        raise CameraInfoConversionError(
            f"camera dict has unknown key(s) {unknown}; expected {list(CAMERA_INFO_KEYS)}"
        )
    width, height = _positive_int(d["width"], "width"), _positive_int(d["height"], "height")
    k = _matrix(d["K"], (3, 3), "K")
    dist = _matrix(d.get("D", ()), None, "D")
    r = _matrix(d["R"], (3, 3), "R") if d.get("R") is not None else np.eye(3)
    if d.get("P") is not None:
        p = _matrix(d["P"], (3, 4), "P")
    else:
        p = np.hstack([k, np.zeros((3, 1))])
    factory = resolve_factory(factory)
    return factory.make(
        "sensor_msgs/msg/CameraInfo",
        header=make_header(factory, stamp_ns, str(d.get("frame_id", ""))),
        width=width,
        height=height,
        distortion_model=str(d.get("distortion_model", "plumb_bob")),
        d=dist,
        k=k.reshape(-1),
        r=r.reshape(-1),
        p=p.reshape(-1),
    )


def _matrix(values: Any, shape: tuple[int, int] | None, name: str) -> np.ndarray:
    """Return ``values`` as a finite float64 array of ``shape`` (1-D if None), as a copy."""
    try:
        flat = np.array(values, dtype=np.float64, copy=True).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise CameraInfoConversionError(f"camera {name} is not numeric: {exc}") from exc
    if shape is not None and flat.size != shape[0] * shape[1]:
        raise CameraInfoConversionError(
            f"camera {name} must have {shape[0] * shape[1]} numbers ({shape[0]}x{shape[1]}), "
            f"got {flat.size}"
        )
    if not np.all(np.isfinite(flat)):
        raise CameraInfoConversionError(f"camera {name} has non-finite values: {flat}")
    return flat if shape is None else flat.reshape(shape)


def _positive_int(value: Any, name: str) -> int:
    try:
        ok = not isinstance(value, (bool, np.bool_, str)) and int(value) == value and value > 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise CameraInfoConversionError(f"camera {name} must be a positive integer, got {value!r}")
    return int(value)
