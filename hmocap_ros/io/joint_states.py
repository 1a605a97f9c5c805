"""``sensor_msgs/JointState`` <-> names and float64 arrays (pose parameters, one per DoF)."""

from __future__ import annotations

from typing import Any

import numpy as np

from hmocap_ros.io.conversion_errors import JointStateConversionError
from hmocap_ros.io.msg_factory import make_header, resolve_factory, stamp_to_ns

__all__ = ["joint_state_to_dict", "make_joint_state"]


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
