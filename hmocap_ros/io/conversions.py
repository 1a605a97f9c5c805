"""Message <-> numpy conversions: Image, CompressedImage, CameraInfo, PointCloud2, JointState.

The one place that knows the wire layout of these messages (STYLE habit 5: cv_bridge and
ros2_numpy are unavailable and break on NumPy 2).

* Decoders (``image_to_numpy``, ``pointcloud2_to_array``, ...) read any object with the
  message's attributes, so rclpy messages and rosbags dataclasses both work. They honour
  ``step``/``row_step`` padding and ``is_bigendian``, and always return a fresh, writeable,
  C-contiguous, native-endian array that shares no memory with the message.
* Encoders (``numpy_to_image``, ``array_to_pointcloud2``, ...) take ``factory=None`` (the shared
  :class:`~hmocap_ros.io.msg_factory.RosbagsFactory`) or a
  :class:`~hmocap_ros.io.msg_factory.RclpyFactory`, and write little-endian, unpadded data.
* Malformed input raises :class:`ConversionError` (a ``ValueError``) whose message names the
  field at fault, so a node can log it and drop the message.

Layouts follow sensor_msgs (``image_encodings.hpp``; ``point_cloud2.py`` of sensor_msgs_py for
structured dtypes) and image_transport's compressed / compressedDepth plugins.
"""

from __future__ import annotations

import re
from typing import Any, NamedTuple

import cv2
import numpy as np

from hmocap_ros.io.msg_factory import make_header, resolve_factory, stamp_to_ns

__all__ = [
    "CAMERA_INFO_KEYS",
    "CameraInfoConversionError",
    "CompressedImageError",
    "ConversionError",
    "ImageConversionError",
    "JointStateConversionError",
    "PointCloudConversionError",
    "camera_info_to_dict",
    "compressed_to_numpy",
    "depth_image_to_metres",
    "dict_to_camera_info",
    "encoding_layout",
    "image_to_numpy",
    "image_to_rgb",
    "joint_state_to_dict",
    "make_joint_state",
    "numpy_to_compressed",
    "numpy_to_image",
    "array_to_pointcloud2",
    "pointcloud2_dtype",
    "pointcloud2_to_array",
    "pointcloud2_to_xyz",
    "xyz_to_pointcloud2",
]


class ConversionError(ValueError):
    """A message could not be converted to or from numpy (malformed message or array)."""


class ImageConversionError(ConversionError):
    """Bad ``sensor_msgs/Image``: unknown encoding, inconsistent sizes, wrong array dtype."""


class CompressedImageError(ImageConversionError):
    """Bad ``sensor_msgs/CompressedImage``: unknown format or data that does not decode."""


class CameraInfoConversionError(ConversionError):
    """Bad ``sensor_msgs/CameraInfo`` or camera dict: wrong matrix sizes or values."""


class PointCloudConversionError(ConversionError):
    """Bad ``sensor_msgs/PointCloud2``: unknown datatype, overlapping fields, short data."""


class JointStateConversionError(ConversionError):
    """Bad ``sensor_msgs/JointState``: array lengths that do not match the names."""


# ---------------------------------------------------------------------------------------------
# Image
# ---------------------------------------------------------------------------------------------


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
    data = _as_bytes_array(msg.data)
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


# ---------------------------------------------------------------------------------------------
# CompressedImage
# ---------------------------------------------------------------------------------------------

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_COMPRESSED_DEPTH_HEADER = 12  # compressed_depth_image_transport ConfigHeader: int32 + 2 float32


def compressed_to_numpy(msg: Any) -> np.ndarray:
    """Decode a ``sensor_msgs/CompressedImage`` (image_transport "compressed"/"compressedDepth").

    ``format`` may be a bare codec (``"jpeg"``, ``"png"``) or image_transport's
    ``"<encoding>; <codec> compressed <encoding>"`` / ``"<encoding>; compressedDepth png"``.
    Colour images come back as ``HxWx3`` RGB (``HxWx4`` RGBA) ``uint8`` whatever the stated
    order, mono as ``HxW``; 16-bit PNGs stay ``uint16``. A compressedDepth 32FC1 image is
    de-quantised to ``float32`` metres (NaN where no depth).

    Raises:
        CompressedImageError: empty or undecodable data, unsupported codec.
    """
    fmt = str(msg.format).strip()
    data = _as_bytes_array(msg.data)
    if data.size == 0:
        raise CompressedImageError(f"compressed image ({fmt!r}) has no data")
    lowered = fmt.lower()
    source_encoding = fmt.split(";", 1)[0].strip() if ";" in fmt else ""
    if "compresseddepth" in lowered:
        return _decode_compressed_depth(data, fmt, source_encoding)
    if any(codec in lowered for codec in ("theora", "rvl", "h264", "ffmpeg")):
        raise CompressedImageError(f"unsupported compressed image format {fmt!r}")
    image = _imdecode(data, fmt)
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2RGBA)
    return image


def numpy_to_compressed(
    array: np.ndarray,
    fmt: str = "jpeg",
    stamp_ns: int = 0,
    frame_id: str = "",
    factory: Any = None,
    quality: int = 90,
) -> Any:
    """Encode an RGB / mono array as a ``sensor_msgs/CompressedImage`` (image_transport style).

    Args:
        array: ``HxWx3`` RGB or ``HxW`` mono ``uint8``; for ``"png"`` also ``HxWx4`` RGBA
            ``uint8`` and ``HxW`` ``uint16`` (e.g. depth in mm).
        fmt: ``"jpeg"`` (lossy) or ``"png"`` (lossless).
        quality: JPEG quality 1..100 (ignored for PNG).

    The ``format`` field is written as image_transport does, e.g.
    ``"rgb8; jpeg compressed bgr8"`` or ``"16UC1; png compressed"``.

    Raises:
        CompressedImageError: unsupported format, dtype or shape, or encoder failure.
    """
    codec = fmt.lower().strip()
    if codec in ("jpg", "jpeg"):
        codec = "jpeg"
    elif codec != "png":
        raise CompressedImageError(f"compressed format must be 'jpeg' or 'png', got {fmt!r}")
    array = np.asarray(array)
    if array.size == 0:
        raise CompressedImageError(f"cannot compress an empty image of shape {array.shape}")
    if array.dtype == np.uint8 and array.ndim == 3 and array.shape[2] == 3:
        to_encode = cv2.cvtColor(array, cv2.COLOR_RGB2BGR)
        format_string = f"rgb8; {codec} compressed bgr8"
    elif array.dtype == np.uint8 and array.ndim == 3 and array.shape[2] == 4 and codec == "png":
        to_encode = cv2.cvtColor(array, cv2.COLOR_RGBA2BGRA)
        format_string = "rgba8; png compressed bgra8"
    elif array.dtype == np.uint8 and array.ndim == 2:
        to_encode = array
        format_string = f"mono8; {codec} compressed mono8"
    elif array.dtype == np.uint16 and array.ndim == 2 and codec == "png":
        to_encode = array
        format_string = "16UC1; png compressed"
    else:
        raise CompressedImageError(
            f"cannot {codec}-compress a {array.dtype} array of shape {array.shape}: need HxWx3 "
            "RGB or HxW mono uint8 (png also: HxWx4 RGBA uint8, HxW uint16)"
        )
    if codec == "jpeg":
        params = [cv2.IMWRITE_JPEG_QUALITY, int(np.clip(quality, 1, 100))]
    else:
        params = []
    ok, encoded = cv2.imencode(f".{'jpg' if codec == 'jpeg' else 'png'}", to_encode, params)
    if not ok:
        raise CompressedImageError(f"OpenCV failed to {codec}-encode shape {array.shape}")
    factory = resolve_factory(factory)
    return factory.make(
        "sensor_msgs/msg/CompressedImage",
        header=make_header(factory, stamp_ns, frame_id),
        format=format_string,
        data=encoded.reshape(-1),
    )


def _imdecode(data: np.ndarray, fmt: str) -> np.ndarray:
    try:
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:
        image = None
        detail = f": {exc}"
    else:
        detail = ""
    if image is None:
        raise CompressedImageError(
            f"compressed image ({fmt!r}, {data.size} bytes) could not be decoded{detail}"
        )
    return image


def _decode_compressed_depth(data: np.ndarray, fmt: str, source_encoding: str) -> np.ndarray:
    """Decode compressed_depth_image_transport's ConfigHeader + PNG payload."""
    if "rvl" in fmt.lower():
        raise CompressedImageError(f"unsupported compressedDepth codec in {fmt!r} (only png)")
    if data[:8].tobytes() == _PNG_MAGIC:
        header, payload = None, data
    elif data.size > _COMPRESSED_DEPTH_HEADER and (
        data[_COMPRESSED_DEPTH_HEADER : _COMPRESSED_DEPTH_HEADER + 8].tobytes() == _PNG_MAGIC
    ):
        header, payload = data[:_COMPRESSED_DEPTH_HEADER], data[_COMPRESSED_DEPTH_HEADER:]
    else:
        raise CompressedImageError(
            f"compressedDepth image ({fmt!r}, {data.size} bytes) has no PNG payload"
        )
    image = _imdecode(payload, fmt)
    if image.dtype != np.uint16 or image.ndim != 2:
        raise CompressedImageError(
            f"compressedDepth image ({fmt!r}) decoded to {image.dtype} {image.shape}, "
            "expected a one-channel uint16 PNG"
        )
    if source_encoding != "32FC1":
        return image
    if header is None:
        raise CompressedImageError(f"32FC1 compressedDepth image ({fmt!r}) lacks its header")
    quant_a, quant_b = np.frombuffer(header[4:12].tobytes(), dtype="<f4")
    # Inverse-depth quantisation of compressed_depth_image_transport: q = A / d + B.
    depth = np.full(image.shape, np.nan, dtype=np.float32)
    valid = image != 0
    depth[valid] = quant_a / (image[valid].astype(np.float32) - quant_b)
    return depth


# ---------------------------------------------------------------------------------------------
# CameraInfo
# ---------------------------------------------------------------------------------------------

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


# ---------------------------------------------------------------------------------------------
# PointCloud2
# ---------------------------------------------------------------------------------------------

# sensor_msgs/PointField datatype codes.
_POINTFIELD_DTYPES: dict[int, np.dtype] = {
    1: np.dtype(np.int8),
    2: np.dtype(np.uint8),
    3: np.dtype(np.int16),
    4: np.dtype(np.uint16),
    5: np.dtype(np.int32),
    6: np.dtype(np.uint32),
    7: np.dtype(np.float32),
    8: np.dtype(np.float64),
}
_DTYPE_POINTFIELDS = {dtype: code for code, dtype in _POINTFIELD_DTYPES.items()}


def pointcloud2_dtype(fields: Any, point_step: int, is_bigendian: bool = False) -> np.dtype:
    """Return the structured dtype (itemsize ``point_step``) described by PointFields.

    Fields with ``count > 1`` become sub-array fields; gaps between fields stay as padding.

    Raises:
        PointCloudConversionError: unknown datatype, empty or duplicate name, a field past
            ``point_step``, or overlapping fields.
    """
    order = ">" if is_bigendian else "<"
    names, formats, offsets = [], [], []
    spans = []
    for field in fields:
        name, offset, datatype, count = (
            str(field.name), int(field.offset), int(field.datatype), int(field.count)
        )
        if datatype not in _POINTFIELD_DTYPES:
            raise PointCloudConversionError(
                f"PointCloud2 field {name!r} has unknown datatype {datatype} (expected 1..8)"
            )
        if not name or name in names:
            raise PointCloudConversionError(
                f"PointCloud2 field name {name!r} is empty or repeated"
            )
        count = max(count, 1)
        base = _POINTFIELD_DTYPES[datatype].newbyteorder(order)
        size = base.itemsize * count
        if offset < 0 or offset + size > point_step:
            raise PointCloudConversionError(
                f"PointCloud2 field {name!r} (offset {offset}, {size} bytes) does not fit "
                f"point_step {point_step}"
            )
        names.append(name)
        formats.append(base if count == 1 else np.dtype((base, (count,))))
        offsets.append(offset)
        spans.append((offset, offset + size, name))
    spans.sort()
    for (_, end, first), (start, _, second) in zip(spans, spans[1:]):
        if start < end:
            raise PointCloudConversionError(f"PointCloud2 fields {first!r} and {second!r} overlap")
    return np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step}
    )


def pointcloud2_to_array(msg: Any, organized: bool = False) -> np.ndarray:
    """Decode a ``sensor_msgs/PointCloud2`` into a structured array, one record per point.

    Honours the fields' datatypes, counts and offsets, ``point_step``, ``row_step`` (padded
    rows) and ``is_bigendian`` (converted to native order). The dtype keeps the message's
    offsets and ``itemsize = point_step`` (padding included), so
    :func:`array_to_pointcloud2` reproduces the layout. Always a copy.

    Args:
        organized: return shape ``(height, width)`` instead of ``(height * width,)``.

    Raises:
        PointCloudConversionError: bad fields, ``row_step < width * point_step`` or short data.
    """
    height, width = int(msg.height), int(msg.width)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    wire_dtype = pointcloud2_dtype(msg.fields, point_step, bool(msg.is_bigendian))
    native_dtype = wire_dtype.newbyteorder("=")
    if height * width == 0:
        return np.zeros((height, width) if organized else (0,), dtype=native_dtype)
    if point_step <= 0 or row_step < width * point_step:
        raise PointCloudConversionError(
            f"PointCloud2 row_step {row_step} < width {width} x point_step {point_step}"
        )
    data = _as_bytes_array(msg.data)
    needed = (height - 1) * row_step + width * point_step
    if data.size < needed:
        raise PointCloudConversionError(
            f"PointCloud2 data has {data.size} bytes, expected at least {needed} for "
            f"{height}x{width} points (row_step {row_step}, point_step {point_step})"
        )
    view = np.ndarray(
        shape=(height, width), dtype=wire_dtype, buffer=data, strides=(row_step, point_step)
    )
    points = view.astype(native_dtype, order="C", copy=True)
    return points if organized else points.reshape(-1)


def array_to_pointcloud2(
    points: np.ndarray,
    stamp_ns: int = 0,
    frame_id: str = "",
    factory: Any = None,
    is_dense: bool | None = None,
) -> Any:
    """Encode a structured array as a ``sensor_msgs/PointCloud2`` (little-endian, no row padding).

    A 1-D array gives an unorganised cloud (height 1), a 2-D one an organised cloud. Field
    offsets and padding of the dtype are kept; sub-array fields become ``count > 1``.

    Args:
        is_dense: ``None`` computes it (True iff every floating-point value is finite).

    Raises:
        PointCloudConversionError: non-structured array, >2 dimensions, or a field type that
            PointField cannot express (int64, bool, nested records, ...).
    """
    points = np.asarray(points)
    if points.dtype.names is None:
        raise PointCloudConversionError(
            f"array_to_pointcloud2 needs a structured array, got {points.dtype}; use "
            "xyz_to_pointcloud2 for an Nx3 array"
        )
    if points.ndim not in (1, 2):
        raise PointCloudConversionError(f"point array must be 1-D or 2-D, got {points.shape}")
    height, width = (1, points.shape[0]) if points.ndim == 1 else points.shape
    factory = resolve_factory(factory)
    fields = []
    little_fields = {}
    for name in points.dtype.names:
        field_dtype, offset = points.dtype.fields[name][:2]
        base, shape = field_dtype.base, field_dtype.shape
        code = _DTYPE_POINTFIELDS.get(base.newbyteorder("="))
        if code is None or base.names is not None:
            raise PointCloudConversionError(
                f"field {name!r} has dtype {field_dtype}, which PointField cannot express "
                "(int8..uint32, float32, float64 only)"
            )
        count = int(np.prod(shape)) if shape else 1
        fields.append(
            factory.make(
                "sensor_msgs/msg/PointField",
                name=name,
                offset=int(offset),
                datatype=code,
                count=count,
            )
        )
        little = base.newbyteorder("<")
        little_fields[name] = (little if not shape else np.dtype((little, shape)), offset)
    little_dtype = np.dtype(
        {
            "names": list(little_fields),
            "formats": [fmt for fmt, _ in little_fields.values()],
            "offsets": [off for _, off in little_fields.values()],
            "itemsize": points.dtype.itemsize,
        }
    )
    # A zero-filled buffer so the padding bytes are deterministic (not leftover memory).
    wire = np.zeros(points.shape, dtype=little_dtype)
    for name in points.dtype.names:
        wire[name] = points[name]
    if is_dense is None:
        is_dense = all(
            bool(np.all(np.isfinite(points[name])))
            for name in points.dtype.names
            if points.dtype.fields[name][0].base.kind == "f"
        )
    point_step = points.dtype.itemsize
    return factory.make(
        "sensor_msgs/msg/PointCloud2",
        header=make_header(factory, stamp_ns, frame_id),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=False,
        point_step=point_step,
        row_step=point_step * width,
        data=wire.reshape(-1).view(np.uint8),
        is_dense=bool(is_dense),
    )


_XYZ_DTYPE = np.dtype({"names": ["x", "y", "z"], "formats": [np.float32] * 3})


def xyz_to_pointcloud2(
    points: np.ndarray, stamp_ns: int = 0, frame_id: str = "", factory: Any = None
) -> Any:
    """Encode an ``Nx3`` array of x, y, z as a float32 ``PointCloud2`` (point_step 12).

    Raises:
        PointCloudConversionError: if ``points`` is not ``Nx3``.
    """
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] != 3:
        raise PointCloudConversionError(f"xyz points must be Nx3, got shape {points.shape}")
    cloud = np.empty(points.shape[0], dtype=_XYZ_DTYPE)
    cloud["x"], cloud["y"], cloud["z"] = points.astype(np.float32, copy=False).T
    return array_to_pointcloud2(cloud, stamp_ns, frame_id, factory)


def pointcloud2_to_xyz(msg: Any, skip_nans: bool = False) -> np.ndarray:
    """Return the ``x``, ``y``, ``z`` fields of a ``PointCloud2`` as an ``Nx3`` float32 array.

    Raises:
        PointCloudConversionError: if the cloud lacks an x, y or z field.
    """
    points = pointcloud2_to_array(msg)
    missing = [axis for axis in "xyz" if axis not in (points.dtype.names or ())]
    if missing:
        raise PointCloudConversionError(
            f"PointCloud2 lacks field(s) {missing}; it has {list(points.dtype.names or ())}"
        )
    xyz = np.stack([points[axis].astype(np.float32) for axis in "xyz"], axis=1)
    if skip_nans:
        xyz = xyz[np.all(np.isfinite(xyz), axis=1)]
    return xyz


# ---------------------------------------------------------------------------------------------
# JointState
# ---------------------------------------------------------------------------------------------


def joint_state_to_dict(msg: Any) -> dict[str, Any]:
    """Return a ``sensor_msgs/JointState`` as ``{name, position, velocity, effort, stamp_ns,
    frame_id}``: a list of str, three float64 arrays (copies), an int and a str.

    Raises:
        JointStateConversionError: if a non-empty position/velocity/effort array's length
            differs from the number of names (JointState allows empty arrays).
    """
    names = [str(name) for name in msg.name]
    arrays = {}
    for key in ("position", "velocity", "effort"):
        values = np.array(getattr(msg, key), dtype=np.float64, copy=True).reshape(-1)
        if values.size not in (0, len(names)):
            raise JointStateConversionError(
                f"JointState {key} has {values.size} values for {len(names)} joint names"
            )
        arrays[key] = values
    return {
        "name": names,
        **arrays,
        "stamp_ns": stamp_to_ns(msg.header.stamp),
        "frame_id": str(msg.header.frame_id),
    }


def make_joint_state(
    names: Any,
    positions: Any,
    stamp_ns: int = 0,
    frame_id: str = "",
    velocity: Any = None,
    effort: Any = None,
    factory: Any = None,
) -> Any:
    """Build a ``sensor_msgs/JointState``; ``velocity``/``effort`` ``None`` are left empty.

    Raises:
        JointStateConversionError: repeated names, or an array whose length is not
            ``len(names)`` (``positions`` may be empty).
    """
    names = [str(name) for name in names]
    if len(set(names)) != len(names):
        raise JointStateConversionError(f"JointState joint names repeat: {names}")
    arrays = {}
    for key, values in (("position", positions), ("velocity", velocity), ("effort", effort)):
        values = np.zeros(0) if values is None else values
        flat = np.array(values, dtype=np.float64, copy=True).reshape(-1)
        if flat.size not in (0, len(names)):
            raise JointStateConversionError(
                f"JointState {key} has {flat.size} values for {len(names)} joint names"
            )
        arrays[key] = flat
    factory = resolve_factory(factory)
    return factory.make(
        "sensor_msgs/msg/JointState",
        header=make_header(factory, stamp_ns, frame_id),
        name=names,
        **arrays,
    )


# ---------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------


def _as_bytes_array(data: Any) -> np.ndarray:
    """Return message ``data`` (ndarray, ``array.array``, bytes, list) as a 1-D uint8 array.

    Buffers are viewed, not copied; callers copy what they return.
    """
    if isinstance(data, np.ndarray):
        flat = data.reshape(-1)
        return flat if flat.dtype == np.uint8 else np.ascontiguousarray(flat).view(np.uint8)
    try:
        return np.frombuffer(data, dtype=np.uint8)
    except (TypeError, ValueError):
        # Lists of ints, or lists of 1-byte ``bytes`` (octet sequences).
        values = list(data)
        if values and isinstance(values[0], bytes):
            return np.frombuffer(b"".join(values), dtype=np.uint8)
        return np.asarray(values, dtype=np.uint8).reshape(-1)
