"""The rosbags type store of hmocap_ros: ROS 2 Jazzy standard types plus hmocap_interfaces.

Bags written by the package embed every message definition, so reading one needs no
compiled interface package. Writing the custom types needs their ``.msg`` text, found
(in this order) in the source tree (``msg_defs/msg``), in an installed
``share/hmocap_interfaces/msg`` of any ``AMENT_PREFIX_PATH`` entry, or of this
Python environment's prefix (where ``make setup`` installs it).
"""

from __future__ import annotations

import functools
import os
import sys
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

INTERFACE_PACKAGE = "hmocap_interfaces"
#: The custom message names, in dependency order (GestureArray needs Gesture).
INTERFACE_MESSAGES = ("Skeleton", "Extremities", "Gesture", "GestureArray", "BodyShape", "CameraRig",
                      "IdsList", "TrainerState")


class InterfaceDefinitionsNotFound(RuntimeError):
    """The .msg files of hmocap_interfaces could not be found."""


def interface_msg_dir() -> Path:
    """Directory holding the ``.msg`` files of hmocap_interfaces."""
    candidates = [Path(__file__).resolve().parents[2] / "msg_defs" / "msg"]
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            candidates.append(Path(prefix) / "share" / INTERFACE_PACKAGE / "msg")
    candidates.append(Path(sys.prefix) / "share" / INTERFACE_PACKAGE / "msg")
    for path in candidates:
        if (path / "CameraRig.msg").is_file():
            return path
    raise InterfaceDefinitionsNotFound(
        f"cannot find the {INTERFACE_PACKAGE} .msg files; looked in: "
        + ", ".join(str(p) for p in candidates)
        + ". Run `make setup` (venv) or source the colcon install (ROS)."
    )


@functools.lru_cache(maxsize=1)
def hmocap_typestore() -> Typestore:
    """A Jazzy type store with the hmocap_interfaces messages registered (cached)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    msg_dir = interface_msg_dir()
    types = {}
    for name in INTERFACE_MESSAGES:
        text = (msg_dir / f"{name}.msg").read_text()
        types.update(get_types_from_msg(text, f"{INTERFACE_PACKAGE}/msg/{name}"))
    store.register(types)
    return store
