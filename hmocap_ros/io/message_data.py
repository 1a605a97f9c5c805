"""The ``data`` field of a message (Image, CompressedImage, PointCloud2) as a numpy byte array."""

from __future__ import annotations

from typing import Any

import numpy as np


def as_bytes_array(data: Any) -> np.ndarray:
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
