"""A client for interaction apps: the room's bodies and gestures in one fixed frame.

``Room`` (rclpy, :mod:`hmocap_ros.client.room`) subscribes to the room's outputs on an app's
node and calls the app back; everything else here is plain Python and numpy, usable without
ROS (tests, offline tools): :class:`Body`, :class:`Gesture`, the geometry helpers, places and
zones from YAML, and the triggers. The API and its guarantees: docs/client.md.

An app is a node that makes a ``Room``; :func:`run_node` and :func:`declare_parameters` (from
:mod:`hmocap_ros.nodes.common`) give it ``--help``, a parameter file and a clean shutdown, as
the package's nodes have.
"""

from hmocap_ros.client.bodies import Body, Gesture
from hmocap_ros.client.geometry import (
    BoxPlace,
    PointPlace,
    joint_above,
    nearest_hand,
    pointing_angle,
    pointing_at,
    pointing_ray,
)
from hmocap_ros.client.places import PlacesFile, read_places
from hmocap_ros.client.room_state import RoomState
from hmocap_ros.client.triggers import OncePerHold, zones_containing

__all__ = ["Body", "BoxPlace", "Gesture", "OncePerHold", "PlacesFile", "PointPlace", "Room", "RoomState",
           "declare_parameters", "joint_above", "nearest_hand", "param", "pointing_angle", "pointing_at",
           "pointing_ray", "read_places", "run_node", "zones_containing"]

_RCLPY_NAMES = {"Room": "hmocap_ros.client.room", "run_node": "hmocap_ros.nodes.common",
                "declare_parameters": "hmocap_ros.nodes.common", "param": "hmocap_ros.params"}


def __getattr__(name: str):
    """``Room`` and the node helpers, imported on first use: the rest works without rclpy."""
    if name in _RCLPY_NAMES:
        import importlib

        return getattr(importlib.import_module(_RCLPY_NAMES[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
