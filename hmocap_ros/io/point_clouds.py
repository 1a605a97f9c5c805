"""``sensor_msgs/PointCloud2`` <-> numpy structured arrays (the layout of sensor_msgs_py's
``point_cloud2.py``): one record per point, fields at their wire offsets.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from hmocap_ros.io.conversion_errors import PointCloudConversionError
from hmocap_ros.io.message_data import as_bytes_array
from hmocap_ros.io.msg_factory import make_header, resolve_factory

__all__ = [
    "array_to_pointcloud2",
    "pointcloud2_dtype",
    "pointcloud2_to_array",
    "pointcloud2_to_xyz",
    "xyz_to_pointcloud2",
]

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
    order: Literal[">", "<"] = ">" if is_bigendian else "<"
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
    data = as_bytes_array(msg.data)
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
    fields, little_dtype = _pointfields(points.dtype, factory)
    # A zero-filled buffer so the padding bytes are deterministic (not leftover memory).
    wire = np.zeros(points.shape, dtype=little_dtype)
    for name in points.dtype.names:
        wire[name] = points[name]
    if is_dense is None:
        is_dense = _all_finite(points)
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


def _pointfields(dtype: np.dtype, factory: Any) -> tuple[list, np.dtype]:
    """PointField messages of a structured dtype, and the same layout in little-endian order.

    Raises:
        PointCloudConversionError: a field type that PointField cannot express.
    """
    assert dtype.names is not None and dtype.fields is not None  # the caller checked it is structured
    fields = []
    little_fields = {}
    for name in dtype.names:
        field_dtype, offset = dtype.fields[name][:2]
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
            "itemsize": dtype.itemsize,
        }
    )
    return fields, little_dtype


def _all_finite(points: np.ndarray) -> bool:
    """True iff every floating-point value of the structured array is finite (``is_dense``)."""
    names, fields = points.dtype.names, points.dtype.fields
    assert names is not None and fields is not None  # a structured array
    return all(
        bool(np.all(np.isfinite(points[name])))
        for name in names
        if fields[name][0].base.kind == "f"
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
