"""``sensor_msgs/Image`` <-> numpy: raw colour, mono and depth images.

Encodings follow sensor_msgs ``image_encodings.hpp``; depth units follow REP 118. Decoders honour
``step`` padding and ``is_bigendian`` and return fresh native-endian arrays; encoders write
little-endian, unpadded data through a message factory (:mod:`hmocap_ros.io.msg_factory`).
"""

from __future__ import annotations

import re
from typing import Any, NamedTuple

import numpy as np

from hmocap_ros.io.conversion_errors import ImageConversionError
from hmocap_ros.io.message_data import as_bytes_array
from hmocap_ros.io.msg_factory import make_header, resolve_factory

__all__ = [
    "EncodingLayout",
    "depth_image_to_metres",
    "encoding_layout",
    "image_to_numpy",
    "image_to_rgb",
    "numpy_to_image",
]


class EncodingLayout(NamedTuple):
    """Memory layout of one pixel: element dtype (native order) and channels per pixel."""

    dtype: np.dtype
    channels: int

    @property
    def pixel_size(self) -> int:
        """Bytes per pixel."""
        return self.dtype.itemsize * self.channels


_NAMED_ENCODINGS: dict[str, tuple[type, int]] = {
    "rgb8": (np.uint8, 3),
    "bgr8": (np.uint8, 3),
    "rgba8": (np.uint8, 4),
    "bgra8": (np.uint8, 4),
    "mono8": (np.uint8, 1),
    "rgb16": (np.uint16, 3),
    "bgr16": (np.uint16, 3),
    "rgba16": (np.uint16, 4),
    "bgra16": (np.uint16, 4),
    "mono16": (np.uint16, 1),
}
# OpenCV-style generic encodings "<bits><U|S|F>C<channels>", e.g. 16UC1, 32FC1, 8UC3.
_CV_ENCODING = re.compile(r"^(8|16|32|64)([USF])C([1-4])$")
_CV_DEPTHS = {
    ("8", "U"): np.uint8,
    ("8", "S"): np.int8,
    ("16", "U"): np.uint16,
    ("16", "S"): np.int16,
    ("32", "S"): np.int32,
    ("32", "F"): np.float32,
    ("64", "F"): np.float64,
}


def encoding_layout(encoding: str) -> EncodingLayout:
    """Return the :class:`EncodingLayout` of a ``sensor_msgs/Image`` encoding string.

    Supports rgb8, bgr8, rgba8, bgra8, mono8, their 16-bit variants, and the generic
    ``<8|16|32|64><U|S|F>C<1..4>`` types (8UC1, 8UC3, 16UC1 = depth in mm, 32FC1 = depth in m).

    Raises:
        ImageConversionError: for any other encoding (Bayer, YUV, ...).
    """
    named = _NAMED_ENCODINGS.get(encoding)
    if named is not None:
        return EncodingLayout(np.dtype(named[0]), named[1])
    match = _CV_ENCODING.match(encoding)
    if match and (match.group(1), match.group(2)) in _CV_DEPTHS:
        dtype = _CV_DEPTHS[(match.group(1), match.group(2))]
        return EncodingLayout(np.dtype(dtype), int(match.group(3)))
    supported = ", ".join(sorted(_NAMED_ENCODINGS)) + ", 8UC1..64FC4"
    raise ImageConversionError(
        f"unsupported image encoding {encoding!r} (supported: {supported})"
    )


def image_to_numpy(msg: Any) -> np.ndarray:
    """Decode a ``sensor_msgs/Image`` into an ``HxW`` (one channel) or ``HxWxC`` array.

    Honours ``step`` (rows may be padded), ``is_bigendian`` (multi-byte data is converted to
    native order), ``height``/``width``. Channel order is the encoding's (``bgr8`` stays BGR;
    see :func:`image_to_rgb`). The result is always a copy: writeable, C-contiguous and
    independent of the message buffer (which rclpy may reuse and rosbags may map read-only).

    Raises:
        ImageConversionError: unknown encoding, zero size, ``step < width * pixel_size`` or
            ``len(data) < step * height``.
    """
    encoding = str(msg.encoding)
    layout = encoding_layout(encoding)
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    if height <= 0 or width <= 0:
        raise ImageConversionError(f"{encoding} image has zero size ({width}x{height})")
    row_bytes = width * layout.pixel_size
    if step < row_bytes:
        raise ImageConversionError(
            f"{encoding} image step {step} < width {width} x {layout.pixel_size} bytes per "
            f"pixel = {row_bytes}"
        )
    data = as_bytes_array(msg.data)
    if data.size < step * height:
        raise ImageConversionError(
            f"{encoding} image data has {data.size} bytes, expected step {step} x height "
            f"{height} = {step * height}"
        )
    wire_dtype = layout.dtype.newbyteorder(">" if msg.is_bigendian else "<")
    # A strided view honours the row padding; astype then makes the one copy (and swaps bytes
    # if the wire order differs from the native order).
    view = np.ndarray(
        shape=(height, width, layout.channels),
        dtype=wire_dtype,
        buffer=data,
        strides=(step, layout.pixel_size, layout.dtype.itemsize),
    )
    image = view.astype(layout.dtype, order="C", copy=True)
    return image[:, :, 0] if layout.channels == 1 else image


def numpy_to_image(
    array: np.ndarray,
    encoding: str,
    stamp_ns: int = 0,
    frame_id: str = "",
    factory: Any = None,
) -> Any:
    """Encode an ``HxW`` / ``HxWxC`` array as a ``sensor_msgs/Image``.

    The array's dtype and channel count must match ``encoding`` exactly (``uint8`` for rgb8,
    ``uint16`` for 16UC1, ``float32`` for 32FC1, ...): nothing is rescaled silently. Data is
    written little-endian with ``step = width * pixel_size`` (no padding).

    Raises:
        ImageConversionError: unknown encoding, wrong dtype, wrong shape or zero size.
    """
    layout = encoding_layout(encoding)
    array = np.asarray(array)
    if array.dtype.newbyteorder("=") != layout.dtype:
        raise ImageConversionError(
            f"encoding {encoding} needs a {layout.dtype} array, got {array.dtype}"
        )
    if array.ndim == 3 and array.shape[2] == layout.channels:
        height, width = array.shape[:2]
    elif array.ndim == 2 and layout.channels == 1:
        height, width = array.shape
    else:
        expected = "HxW or HxWx1" if layout.channels == 1 else f"HxWx{layout.channels}"
        raise ImageConversionError(
            f"encoding {encoding} needs an {expected} array, got shape {array.shape}"
        )
    if height == 0 or width == 0:
        raise ImageConversionError(f"cannot encode an empty image of shape {array.shape}")
    data = np.array(array, dtype=layout.dtype.newbyteorder("<"), order="C", copy=True)
    factory = resolve_factory(factory)
    return factory.make(
        "sensor_msgs/msg/Image",
        header=make_header(factory, stamp_ns, frame_id),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=width * layout.pixel_size,
        data=data.reshape(-1).view(np.uint8),
    )


def image_to_rgb(msg: Any) -> np.ndarray:
    """Decode a colour or mono ``sensor_msgs/Image`` into an ``HxWx3`` ``uint8`` RGB array.

    rgb/bgr/rgba/bgra (8 and 16 bit; alpha dropped) and mono8/mono16/8UC1 are accepted;
    16-bit values are scaled to 8 bits by ``>> 8`` as cv_bridge does.

    Raises:
        ImageConversionError: for depth or channel-order-less encodings (16UC1, 32FC1, 8UC3,
            ...); use :func:`depth_image_to_metres` or :func:`image_to_numpy` for those.
    """
    encoding = str(msg.encoding)
    if encoding not in _NAMED_ENCODINGS and encoding != "8UC1":
        encoding_layout(encoding)  # unknown encodings get the generic message
        raise ImageConversionError(
            f"encoding {encoding!r} is not a colour or mono encoding; use "
            "depth_image_to_metres() for depth or image_to_numpy() for raw values"
        )
    image = image_to_numpy(msg)
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    if image.ndim == 2:
        return np.repeat(image[:, :, None], 3, axis=2)
    if encoding.startswith("bgr"):
        return np.ascontiguousarray(image[:, :, 2::-1])
    return np.ascontiguousarray(image[:, :, :3])


_INTEGER_DEPTH_UNIT = 0.001  # REP 118: 16UC1 depth images are in millimetres


def depth_image_to_metres(
    msg: Any, depth_unit: float | None = None, invalid_value: float | None = 0
) -> np.ndarray:
    """Decode a depth image (16UC1/mono16 or 32FC1) into an ``HxW`` ``float32`` array in metres.

    Args:
        msg: the ``sensor_msgs/Image``.
        depth_unit: metres per raw unit; ``None`` means 0.001 for integer encodings (REP 118:
            millimetres) and 1.0 for 32FC1.
        invalid_value: raw value that marks "no measurement" (REP 118: 0); ``None`` keeps it.
            Such pixels, and NaN / +-inf, become NaN.

    Raises:
        ImageConversionError: for non-depth encodings or malformed images.
    """
    encoding = str(msg.encoding)
    if encoding not in ("16UC1", "mono16", "32FC1"):
        raise ImageConversionError(
            f"depth image must be 16UC1, mono16 or 32FC1, got {encoding!r}"
        )
    raw = image_to_numpy(msg)
    if depth_unit is None:
        depth_unit = 1.0 if raw.dtype.kind == "f" else _INTEGER_DEPTH_UNIT
    depth = raw.astype(np.float32) * np.float32(depth_unit)
    invalid = ~np.isfinite(depth)
    if invalid_value is not None:
        invalid |= raw == invalid_value
    depth[invalid] = np.nan
    return depth
