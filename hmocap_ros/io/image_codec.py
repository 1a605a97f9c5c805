"""Camera images as a node or a bag reader takes them: raw ``sensor_msgs/Image`` or
image_transport's ``compressed`` ``sensor_msgs/CompressedImage`` (JPEG, PNG), one decode each.

A camera publishes ``<camera>/image_raw`` (raw) and, through image_transport, its ``compressed``
transport on ``<camera>/image_raw/compressed`` (a depth camera: ``compressedDepth`` on
``depth/image_raw/compressedDepth``); a node takes one of them (its ``image_transport``
parameter, :data:`CAMERA_TRANSPORTS` or :data:`DEPTH_TRANSPORTS`) and every function here
accepts either message, as an rclpy message or a rosbags dataclass:

- :func:`decoded_rgb` / :func:`decoded_mono` / :func:`decoded_image`: the pixels, decoded once;
  ``reduction`` 2, 4 or 8 decodes a compressed image at that fraction of its size with libjpeg's
  scaled decoding (``cv2.IMREAD_REDUCED_*``), for a node that works at a reduced size;
- :func:`image_size` and :func:`image_encoding`: the full size and the pixel layout, for a
  compressed image read from the JPEG or PNG header without decoding it.

Bad data raises :class:`~hmocap_ros.io.conversion_errors.CompressedImageError` (or another
:class:`~hmocap_ros.io.conversion_errors.ConversionError`), which a node logs before it drops
the frame. No rclpy here.
"""

from __future__ import annotations

import struct
from typing import Any

import cv2
import numpy as np

from hmocap_ros.io.compressed_images import compressed_to_numpy
from hmocap_ros.io.conversion_errors import CompressedImageError
from hmocap_ros.io.images import image_to_numpy, image_to_rgb
from hmocap_ros.io.message_data import as_bytes_array

__all__ = [
    "CAMERA_TRANSPORTS",
    "COMPRESSED_SUFFIX",
    "DEPTH_TRANSPORTS",
    "IMAGE_TRANSPORTS",
    "REDUCTIONS",
    "check_transport",
    "decoded_image",
    "decoded_mono",
    "decoded_rgb",
    "image_encoding",
    "image_size",
    "is_compressed",
    "reduction_for",
    "transport_topic",
]

#: The transports of a camera image or mask input: ``raw`` (sensor_msgs/Image on the topic itself)
#: and image_transport's ``compressed`` (sensor_msgs/CompressedImage on ``<topic>/compressed``).
CAMERA_TRANSPORTS = ("raw", "compressed")
#: ... of a depth image input: ``raw`` and compressed_depth_image_transport's ``compressedDepth``
#: (sensor_msgs/CompressedImage, PNG with its header, on ``<topic>/compressedDepth``).
DEPTH_TRANSPORTS = ("raw", "compressedDepth")
#: Every transport a topic name is made for (:func:`transport_topic`).
IMAGE_TRANSPORTS = ("raw", "compressed", "compressedDepth")
#: image_transport's topic suffix of the ``compressed`` transport.
COMPRESSED_SUFFIX = "/compressed"
#: Size reductions libjpeg decodes directly (``cv2.IMREAD_REDUCED_*``).
REDUCTIONS = (1, 2, 4, 8)
_REDUCED_COLOR = {1: cv2.IMREAD_COLOR, 2: cv2.IMREAD_REDUCED_COLOR_2, 4: cv2.IMREAD_REDUCED_COLOR_4,
                  8: cv2.IMREAD_REDUCED_COLOR_8}
_REDUCED_GREY = {1: cv2.IMREAD_GRAYSCALE, 2: cv2.IMREAD_REDUCED_GRAYSCALE_2,
                 4: cv2.IMREAD_REDUCED_GRAYSCALE_4, 8: cv2.IMREAD_REDUCED_GRAYSCALE_8}
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: PNG colour type (IHDR) -> the encoding of its pixels
_PNG_ENCODINGS = {0: "mono8", 2: "rgb8", 3: "rgb8", 4: "mono8", 6: "rgba8"}
#: JPEG start-of-frame markers (baseline, progressive, ...): not DHT (C4), JPG (C8), DAC (CC)
_JPEG_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def check_transport(transport: str, transports: tuple = IMAGE_TRANSPORTS) -> str:
    """``transport`` when it is one of ``transports``, else ValueError naming them."""
    if transport not in transports:
        raise ValueError(f"image_transport must be one of {', '.join(transports)}, got {transport!r}")
    return transport


def transport_topic(topic: str, transport: str) -> str:
    """The topic of ``transport`` for the image topic ``topic`` (``cam_1/image_raw`` ->
    ``cam_1/image_raw/compressed``), as image_transport names it."""
    return topic if check_transport(transport) == "raw" else f"{topic}/{transport}"


def is_compressed(msg: Any) -> bool:
    """Whether ``msg`` is a ``sensor_msgs/CompressedImage`` (it has ``format``, no ``encoding``)."""
    return hasattr(msg, "format") and not hasattr(msg, "encoding")


def reduction_for(width: int, working_width: int) -> int:
    """The largest of :data:`REDUCTIONS` that keeps an image of ``width`` at least
    ``working_width`` wide (1 when ``working_width`` is 0 or not smaller than ``width``)."""
    if working_width <= 0:
        return 1
    return max(r for r in REDUCTIONS if width // r >= working_width or r == 1)


def _check_reduction(reduction: int) -> None:
    if reduction not in REDUCTIONS:
        raise ValueError(f"reduction must be one of {REDUCTIONS}, got {reduction}")


def _reduced(image: np.ndarray, reduction: int) -> np.ndarray:
    """A raw image at 1/``reduction`` of its size, as libjpeg's scaled decoding rounds it."""
    if reduction == 1:
        return image
    height, width = image.shape[:2]
    size = (-(-width // reduction), -(-height // reduction))
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA)


def _imdecode(msg: Any, flags: int) -> np.ndarray:
    data = as_bytes_array(msg.data)
    if data.size == 0:
        raise CompressedImageError(f"compressed image ({str(msg.format)!r}) has no data")
    if "compresseddepth" in str(msg.format).lower():
        raise CompressedImageError(f"{str(msg.format)!r} is a depth image, not a camera image")
    try:
        image = cv2.imdecode(data, flags)
    except cv2.error as err:
        raise CompressedImageError(f"compressed image ({str(msg.format)!r}, {data.size} bytes) "
                                   f"could not be decoded: {err}") from None
    if image is None:
        raise CompressedImageError(f"compressed image ({str(msg.format)!r}, {data.size} bytes) "
                                   "could not be decoded")
    return image


def decoded_rgb(msg: Any, reduction: int = 1) -> np.ndarray:
    """The ``HxWx3`` ``uint8`` RGB image of a camera message (mono repeated to three channels,
    as :func:`~hmocap_ros.io.images.image_to_rgb`), at 1/``reduction`` of its size."""
    _check_reduction(reduction)
    if not is_compressed(msg):
        return _reduced(image_to_rgb(msg), reduction)
    image = _imdecode(msg, _REDUCED_COLOR[reduction])
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def decoded_mono(msg: Any, reduction: int = 1) -> np.ndarray:
    """The ``HxW`` one-channel image of a mask or mono message, at 1/``reduction`` of its size.

    Raises ConversionError for a colour image (a mask must be mono8)."""
    _check_reduction(reduction)
    if not is_compressed(msg):
        image = image_to_numpy(msg)
        if image.ndim != 2:
            raise CompressedImageError(f"must be mono8, got {msg.encoding}")
        return _reduced(image, reduction)
    encoding = image_encoding(msg)
    if not encoding.startswith("mono") and encoding not in ("8UC1", "16UC1"):
        raise CompressedImageError(f"must be mono8, got {encoding} ({str(msg.format)!r})")
    if reduction == 1:
        image = compressed_to_numpy(msg)
    else:
        image = _imdecode(msg, _REDUCED_GREY[reduction])
    if image.ndim != 2:
        raise CompressedImageError(f"must be mono8, got {image.shape[2]} channels ({str(msg.format)!r})")
    return image


def decoded_image(msg: Any) -> np.ndarray:
    """The pixels of an Image (as :func:`~hmocap_ros.io.images.image_to_numpy`) or of a
    CompressedImage (RGB for colour, as :func:`~hmocap_ros.io.compressed_images.compressed_to_numpy`)."""
    return compressed_to_numpy(msg) if is_compressed(msg) else image_to_numpy(msg)


def image_encoding(msg: Any) -> str:
    """The pixel encoding of a message: an Image's ``encoding``; a CompressedImage's source
    encoding as image_transport writes it in ``format`` (``"rgb8; jpeg compressed bgr8"`` ->
    ``rgb8``), else that of its JPEG or PNG header (``mono8``, ``rgb8``, ``rgba8``)."""
    if not is_compressed(msg):
        return str(msg.encoding)
    fmt = str(msg.format)
    if ";" in fmt:
        return fmt.split(";", 1)[0].strip()
    return _header(msg)[2]


def image_size(msg: Any) -> tuple[int, int]:
    """``(width, height)`` of an image message; a compressed one's from its JPEG or PNG header,
    without decoding it (CompressedImageError when the header cannot be read)."""
    if not is_compressed(msg):
        return int(msg.width), int(msg.height)
    width, height, _ = _header(msg)
    return width, height


def _header(msg: Any) -> tuple[int, int, str]:
    data = as_bytes_array(msg.data).tobytes()
    if data[:8] == _PNG_MAGIC and len(data) >= 26 and data[12:16] == b"IHDR":
        width, height = struct.unpack(">II", data[16:24])
        depth, colour = data[24], data[25]
        encoding = _PNG_ENCODINGS.get(colour, "rgb8")
        if depth == 16 and encoding == "mono8":
            encoding = "mono16"
        return width, height, encoding
    if data[:2] == b"\xff\xd8":
        found = _jpeg_frame(data)
        if found is not None:
            return found
    raise CompressedImageError(f"compressed image ({str(msg.format)!r}, {len(data)} bytes) has no "
                               "readable JPEG or PNG header")


def _jpeg_frame(data: bytes) -> tuple[int, int, str] | None:
    """Width, height and encoding from a JPEG's start-of-frame segment, or None."""
    pos = 2
    while pos + 4 <= len(data):
        if data[pos] != 0xFF:
            return None
        marker = data[pos + 1]
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        if 0xD0 <= marker <= 0xD9 or marker == 0x01:  # markers without a length
            pos += 2
            continue
        (length,) = struct.unpack(">H", data[pos + 2:pos + 4])
        if marker in _JPEG_SOF:
            if pos + 10 > len(data):
                return None
            height, width = struct.unpack(">HH", data[pos + 5:pos + 9])
            components = data[pos + 9]
            return width, height, "mono8" if components == 1 else "rgb8"
        pos += 2 + length
    return None
