"""``sensor_msgs/CompressedImage`` <-> numpy, as image_transport's "compressed" (JPEG, PNG)
and "compressedDepth" (PNG with compressed_depth_image_transport's header) plugins write them.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from hmocap_ros.io.conversion_errors import CompressedImageError
from hmocap_ros.io.message_data import as_bytes_array
from hmocap_ros.io.msg_factory import make_header, resolve_factory

__all__ = ["compressed_to_numpy", "numpy_to_compressed"]

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
    data = as_bytes_array(msg.data)
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
            ``uint8`` and ``HxW`` ``uint16`` (e.g. depth in mm); for ``"compressedDepth"`` an
            ``HxW`` ``uint16`` depth image in mm.
        fmt: ``"jpeg"`` (lossy), ``"png"`` (lossless) or ``"compressedDepth"``
            (compressed_depth_image_transport's: its 12-byte header, then a 16-bit PNG).
        quality: JPEG quality 1..100 (ignored for PNG).

    The ``format`` field is written as image_transport does, e.g.
    ``"rgb8; jpeg compressed bgr8"``, ``"16UC1; png compressed"`` or
    ``"16UC1; compressedDepth png"``.

    Raises:
        CompressedImageError: unsupported format, dtype or shape, or encoder failure.
    """
    codec = fmt.lower().strip()
    if codec == "compresseddepth":
        return _compressed_depth(np.asarray(array), stamp_ns, frame_id, factory)
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


def _compressed_depth(depth: np.ndarray, stamp_ns: int, frame_id: str, factory: Any) -> Any:
    """A 16UC1 depth image (mm) as compressed_depth_image_transport writes it."""
    if depth.dtype != np.uint16 or depth.ndim != 2 or depth.size == 0:
        raise CompressedImageError(f"compressedDepth takes an HxW uint16 depth image (mm), got {depth.dtype} "
                                   f"{depth.shape}")
    ok, encoded = cv2.imencode(".png", depth)
    if not ok:
        raise CompressedImageError(f"OpenCV failed to png-encode shape {depth.shape}")
    # ConfigHeader: the format (INV_DEPTH = 0) and the two quantisation parameters, which a
    # 16UC1 image does not use
    header = np.frombuffer(np.int32(0).tobytes() + np.zeros(2, "<f4").tobytes(), np.uint8)
    factory = resolve_factory(factory)
    return factory.make(
        "sensor_msgs/msg/CompressedImage",
        header=make_header(factory, stamp_ns, frame_id),
        format="16UC1; compressedDepth png",
        data=np.concatenate([header, encoded.reshape(-1)]),
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
