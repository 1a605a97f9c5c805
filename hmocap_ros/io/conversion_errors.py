"""Errors of the message <-> numpy conversions: one ``ValueError`` subclass per message type.

Each message names the field at fault, so a node can log it and drop the message.
"""

from __future__ import annotations

__all__ = [
    "CameraInfoConversionError",
    "CompressedImageError",
    "ConversionError",
    "ImageConversionError",
    "JointStateConversionError",
    "PointCloudConversionError",
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
