"""Build ROS 2 messages as rosbags dataclasses or as rclpy message objects, with one API.

The conversion functions in :mod:`hmocap_ros.io.conversions` read messages by duck typing and
build them through a *factory*, so the same code serves a live node (rclpy messages) and bag
tools or tests that run without a ROS install (rosbags dataclasses):

* :class:`RosbagsFactory` wraps a ``rosbags.typesys`` typestore (ROS 2 Jazzy by default) and
  returns its dataclasses; primitive sequences become numpy arrays of the field's dtype.
* :class:`RclpyFactory` imports the generated message module (``sensor_msgs.msg``, ...) lazily
  and returns rclpy message objects; numpy arrays become ``array.array`` (variable-length
  numeric sequences) or ``numpy.ndarray`` (fixed-size numeric arrays), the types the generated
  setters store, so that no element-wise Python conversion happens even with
  ``ROS_PYTHON_CHECK_FIELDS=1``.

Both factories accept missing fields (left at the message's default) and nested messages given
as objects already built by the same factory. This module never imports rclpy.
"""

from __future__ import annotations

import array
import importlib
import re
from typing import Any

import numpy as np

__all__ = [
    "RclpyFactory",
    "RosbagsFactory",
    "MessageFactoryError",
    "default_factory",
    "make_header",
    "normalize_typename",
    "resolve_factory",
    "ns_to_stamp",
    "stamp_to_ns",
    "typename_of",
]

NS_PER_S = 1_000_000_000

# ROS 2 primitive type name -> numpy dtype, as spelled by rosbags (idl names) and by the
# rosidl-generated Python classes ("double", "float", "octet", "boolean").
_PRIMITIVE_DTYPES: dict[str, np.dtype] = {
    "bool": np.dtype(np.bool_),
    "boolean": np.dtype(np.bool_),
    "byte": np.dtype(np.uint8),
    "octet": np.dtype(np.uint8),
    "char": np.dtype(np.uint8),
    "int8": np.dtype(np.int8),
    "uint8": np.dtype(np.uint8),
    "int16": np.dtype(np.int16),
    "uint16": np.dtype(np.uint16),
    "int32": np.dtype(np.int32),
    "uint32": np.dtype(np.uint32),
    "int64": np.dtype(np.int64),
    "uint64": np.dtype(np.uint64),
    "float32": np.dtype(np.float32),
    "float": np.dtype(np.float32),
    "float64": np.dtype(np.float64),
    "double": np.dtype(np.float64),
}

# array.array type codes used by rosidl_generator_py for numeric sequences.
_ARRAY_TYPECODES: dict[str, str] = {
    "int8": "b",
    "uint8": "B",
    "int16": "h",
    "uint16": "H",
    "int32": "i",
    "uint32": "I",
    "int64": "q",
    "uint64": "Q",
    "float": "f",
    "double": "d",
}

_RCLPY_SEQUENCE = re.compile(r"^sequence<([^,>]+)(?:,\s*(\d+))?>$")
_RCLPY_FIXED_ARRAY = re.compile(r"^([a-z0-9_]+)\[(\d+)\]$")


class MessageFactoryError(ValueError):
    """A message could not be built: unknown type, unknown field or a value of the wrong shape."""


def normalize_typename(typename: str) -> str:
    """Return ``"pkg/msg/Name"`` for ``"pkg/msg/Name"`` or ``"pkg/Name"``.

    Raises:
        MessageFactoryError: if the name has another form.
    """
    parts = typename.strip("/").split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or not all(parts):
        raise MessageFactoryError(
            f"message type name {typename!r} is not of the form 'pkg/msg/Name'"
        )
    return "/".join(parts)


def typename_of(msg: Any) -> str:
    """Return the ``"pkg/msg/Name"`` type name of a message instance or class of either flavour.

    rosbags dataclasses carry ``__msgtype__``; rclpy classes live in ``pkg.msg._module`` and
    the name is derived from the module's package and the class name.

    Raises:
        MessageFactoryError: if ``msg`` is neither a rosbags nor an rclpy message.
    """
    msgtype = getattr(msg, "__msgtype__", None)
    if isinstance(msgtype, str):
        return msgtype
    cls = msg if isinstance(msg, type) else type(msg)
    module = cls.__module__.split(".")
    if len(module) >= 2 and module[1] in ("msg", "srv", "action") and hasattr(
        cls, "get_fields_and_field_types"
    ):
        return f"{module[0]}/{module[1]}/{cls.__name__}"
    raise MessageFactoryError(
        f"{cls.__module__}.{cls.__qualname__} is not a ROS message (no __msgtype__ and not "
        "an rclpy generated message class)"
    )


def stamp_to_ns(stamp: Any) -> int:
    """Return a ``builtin_interfaces/Time`` (or a ``Header``, via its ``stamp``) as integer ns."""
    if not hasattr(stamp, "sec") and hasattr(stamp, "stamp"):
        stamp = stamp.stamp
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def ns_to_stamp(ns: int, factory: Any = None) -> Any:
    """Build a ``builtin_interfaces/msg/Time`` for integer nanoseconds ``ns``.

    Negative times follow the ROS convention ``sec = floor(ns / 1e9)``, ``0 <= nanosec < 1e9``.
    ``factory=None`` uses :func:`default_factory`.
    """
    ns = int(ns)
    sec, nanosec = divmod(ns, NS_PER_S)
    if not -(2**31) <= sec < 2**31:
        raise MessageFactoryError(
            f"stamp {ns} ns does not fit builtin_interfaces/Time (int32 sec)"
        )
    return resolve_factory(factory).make("builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec)


def make_header(factory: Any = None, stamp_ns: int = 0, frame_id: str = "") -> Any:
    """Build a ``std_msgs/msg/Header`` with ``stamp_ns`` (integer ns) and ``frame_id``."""
    factory = resolve_factory(factory)
    return factory.make(
        "std_msgs/msg/Header", stamp=ns_to_stamp(stamp_ns, factory), frame_id=str(frame_id)
    )


class RosbagsFactory:
    """Build rosbags dataclass messages from a ``rosbags.typesys`` typestore.

    Args:
        typestore: a typestore; ``None`` uses :func:`hmocap_ros.io.typestore.hmocap_typestore`
            (ROS 2 Jazzy plus the ``hmocap_interfaces`` messages).
    """

    flavour = "rosbags"

    def __init__(self, typestore: Any = None) -> None:
        if typestore is None:
            from hmocap_ros.io.typestore import hmocap_typestore

            typestore = hmocap_typestore()
        self.typestore = typestore

    def __repr__(self) -> str:
        return f"RosbagsFactory({len(self.typestore.types)} types)"

    def message_class(self, typename: str) -> type:
        """Return the dataclass for ``typename`` ("pkg/msg/Name")."""
        typename = normalize_typename(typename)
        try:
            return self.typestore.types[typename]
        except KeyError:
            raise MessageFactoryError(
                f"message type {typename!r} is not in the rosbags typestore; register its "
                "definition first (typestore.register(get_types_from_msg(...)))"
            ) from None

    def make(self, typename: str, **fields: Any) -> Any:
        """Return a ``typename`` dataclass; missing fields get the message's default value.

        Numeric sequences and arrays may be given as numpy arrays, lists, ``bytes`` or
        ``array.array``; they are stored as 1-D numpy arrays of the field's dtype (rosbags'
        serialiser requires that). A 1-D C-contiguous ndarray that already has that dtype is
        stored as is, without a copy (the message then shares its memory, as rosbags'
        deserialiser does with its buffer); anything else is converted into a new array.
        Fixed-size arrays are checked for length.

        Raises:
            MessageFactoryError: unknown type or field, or a fixed array of the wrong length.
        """
        typename = normalize_typename(typename)
        cls = self.message_class(typename)
        _, fielddefs = self.typestore.fielddefs[typename]
        known = {name for name, _ in fielddefs}
        unknown = sorted(set(fields) - known)
        if unknown:
            raise MessageFactoryError(
                f"{typename} has no field(s) {unknown}; its fields are {sorted(known)}"
            )
        values = {}
        for name, fdef in fielddefs:
            if name in fields:
                values[name] = self._coerce(typename, name, fdef, fields[name])
            else:
                values[name] = self._default(fdef)
        return cls(**values)

    # rosbags field definitions: (Nodetype, detail) with Nodetype BASE=1, NAME=2, ARRAY=3,
    # SEQUENCE=4; BASE detail is (primitive, string bound), ARRAY/SEQUENCE detail is
    # (element definition, length or bound).
    def _default(self, fdef: tuple) -> Any:
        kind, detail = int(fdef[0]), fdef[1]
        if kind == 1:
            return _primitive_default(detail[0])
        if kind == 2:
            return self.make(detail)
        element, length = detail
        dtype = _element_dtype(element)
        if kind == 3:
            if dtype is not None:
                return np.zeros(length, dtype=dtype)
            return [self._default(element) for _ in range(length)]
        if dtype is not None:
            return np.empty(0, dtype=dtype)
        return []

    def _coerce(self, typename: str, name: str, fdef: tuple, value: Any) -> Any:
        kind, detail = int(fdef[0]), fdef[1]
        if kind == 1:
            return _coerce_scalar(detail[0], value)
        if kind == 2:
            return value
        element, length = detail
        dtype = _element_dtype(element)
        if dtype is None:
            value = list(value)
        else:
            value = _as_flat_array(value, dtype, f"{typename}.{name}", copy=False)
        if kind == 3 and len(value) != length:
            raise MessageFactoryError(
                f"{typename}.{name} is a fixed array of {length} elements, got {len(value)}"
            )
        if kind == 4 and length and len(value) > length:
            raise MessageFactoryError(
                f"{typename}.{name} is bounded to {length} elements, got {len(value)}"
            )
        return value


class RclpyFactory:
    """Build rclpy message objects (the generated ``pkg.msg`` classes, imported lazily).

    Numeric sequences given as numpy arrays, ``bytes`` or lists are stored as ``array.array``
    with the generated type code (one memcpy, where passing the ndarray itself is converted
    element by element: docs/development.md, "Costs the code is shaped by"); fixed-size
    numeric arrays as ``float64``/... ndarrays; numpy scalars as Python scalars.
    """

    flavour = "rclpy"

    def __init__(self) -> None:
        self._classes: dict[str, type] = {}

    def __repr__(self) -> str:
        return "RclpyFactory()"

    def message_class(self, typename: str) -> Any:
        """Return the rclpy class for ``typename`` ("pkg/msg/Name"), importing its module (a
        generated class: the interface packages carry no type information)."""
        typename = normalize_typename(typename)
        cls = self._classes.get(typename)
        if cls is None:
            package, interface, name = typename.split("/")
            try:
                module = importlib.import_module(f"{package}.{interface}")
                cls = getattr(module, name)
            except (ImportError, AttributeError) as exc:
                raise MessageFactoryError(
                    f"cannot import rclpy message {typename!r} ({exc}); is the package built "
                    "and sourced?"
                ) from exc
            self._classes[typename] = cls
        return cls

    def make(self, typename: str, **fields: Any) -> Any:
        """Return an rclpy ``typename`` message; see :meth:`RosbagsFactory.make`.

        Raises:
            MessageFactoryError: unknown type or field, or a fixed array of the wrong length.
        """
        cls = self.message_class(typename)
        field_types = cls.get_fields_and_field_types()
        unknown = sorted(set(fields) - set(field_types))
        if unknown:
            raise MessageFactoryError(
                f"{normalize_typename(typename)} has no field(s) {unknown}; its fields are "
                f"{sorted(field_types)}"
            )
        msg = cls()
        for name, value in fields.items():
            setattr(msg, name, _rclpy_value(f"{typename}.{name}", field_types[name], value))
        return msg


def _rclpy_value(where: str, field_type: str, value: Any) -> Any:
    """Convert ``value`` to what the generated setter for ``field_type`` stores."""
    if field_type in _PRIMITIVE_DTYPES:
        return _coerce_scalar(field_type, value)
    sequence = _RCLPY_SEQUENCE.match(field_type)
    if sequence:
        element, bound = sequence.group(1), sequence.group(2)
        if bound is not None and len(value) > int(bound):
            raise MessageFactoryError(f"{where} is bounded to {bound} elements, got {len(value)}")
        typecode = _ARRAY_TYPECODES.get(element)
        if typecode is not None:
            if isinstance(value, array.array) and value.typecode == typecode:
                return value
            flat = _as_flat_array(value, _PRIMITIVE_DTYPES[element], where, copy=False)
            out = array.array(typecode)  # frombytes copies: the message owns its data
            out.frombytes(flat.view(np.uint8).data)
            return out
        if element == "octet" and isinstance(value, (bytes, bytearray, np.ndarray)):
            raw = _as_flat_array(value, np.dtype(np.uint8), where).tobytes()
            return list(memoryview(raw).cast("c"))
        if element == "boolean" and isinstance(value, np.ndarray):
            return [bool(v) for v in value.reshape(-1).tolist()]
        return value
    fixed = _RCLPY_FIXED_ARRAY.match(field_type)
    if fixed and fixed.group(1) in _ARRAY_TYPECODES:
        flat = _as_flat_array(value, _PRIMITIVE_DTYPES[fixed.group(1)], where)
        if flat.size != int(fixed.group(2)):
            raise MessageFactoryError(
                f"{where} is a fixed array of {fixed.group(2)} elements, got {flat.size}"
            )
        return flat
    return value


def _primitive_default(primitive: str) -> Any:
    if primitive == "string":
        return ""
    dtype = _PRIMITIVE_DTYPES.get(primitive)
    if dtype is None:
        raise MessageFactoryError(f"unknown primitive type {primitive!r}")
    return dtype.type(0).item()


def _coerce_scalar(primitive: str, value: Any) -> Any:
    """Turn numpy scalars into the Python scalar the messages expect."""
    if primitive in ("string", "wstring") or primitive.startswith("string<"):
        return str(value)
    dtype = _PRIMITIVE_DTYPES.get(primitive)
    if dtype is None:
        return value
    if dtype.kind == "b":
        return bool(value)
    if dtype.kind == "f":
        return float(value)
    return int(value)


def _element_dtype(element: tuple) -> np.dtype | None:
    """Return the numpy dtype of a rosbags sequence element, or None if not numeric."""
    if int(element[0]) != 1:
        return None
    return _PRIMITIVE_DTYPES.get(element[1][0])


def _as_flat_array(value: Any, dtype: np.dtype, where: str, copy: bool = True) -> np.ndarray:
    """Return ``value`` as a 1-D, C-contiguous, native-order array of ``dtype``.

    With ``copy=False`` an ndarray that already qualifies is returned as is (a view).
    """
    if isinstance(value, (bytes, bytearray, memoryview)):
        raw = np.frombuffer(value, dtype=np.uint8)
        if raw.size % dtype.itemsize:
            raise MessageFactoryError(
                f"{where}: {raw.size} bytes is not a whole number of {dtype} elements"
            )
        return raw.view(dtype).copy()
    if (
        not copy
        and isinstance(value, np.ndarray)
        and value.ndim == 1
        and value.dtype == dtype
        and value.flags.c_contiguous
    ):
        return value
    try:
        flat = np.array(value, dtype=dtype, copy=True, order="C").reshape(-1)
    except (TypeError, ValueError, OverflowError) as exc:
        raise MessageFactoryError(f"{where}: cannot convert value to {dtype} ({exc})") from exc
    return flat


def resolve_factory(factory: Any = None) -> Any:
    """Return ``factory``, or the shared default :class:`RosbagsFactory` when it is None."""
    return default_factory() if factory is None else factory


_DEFAULT_FACTORY: RosbagsFactory | None = None


def default_factory() -> RosbagsFactory:
    """Return the shared :class:`RosbagsFactory` (Jazzy + hmocap_interfaces), created on first use."""
    global _DEFAULT_FACTORY
    if _DEFAULT_FACTORY is None:
        _DEFAULT_FACTORY = RosbagsFactory()
    return _DEFAULT_FACTORY


def __getattr__(name: str) -> Any:
    # ``DEFAULT_FACTORY``, the shared factory as a module attribute, is created on first
    # access (an import that needs no message does not build the Jazzy typestore);
    # ``default_factory()`` is the API.
    if name == "DEFAULT_FACTORY":
        return default_factory()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
