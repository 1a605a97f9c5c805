"""The rosbags type store of hmocap_ros: ROS 2 Jazzy standard types plus hmocap_interfaces
and REP-155's ``hri_msgs/msg/IdsList``.

Bags written by the package embed every message definition, so reading one needs no
compiled interface package. Writing the custom types needs their ``.msg`` text, found
(in this order) in the source tree (``msg_defs/msg``, ``msg_defs_hri/msg``), in an installed
``share/<package>/msg`` of any ``AMENT_PREFIX_PATH`` entry, or of this Python environment's
prefix (where ``make setup`` installs them).
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
                      "TrainerState")
#: REP-155's message types the package writes, by package (not in rosbags' Jazzy store).
REP155_MESSAGES = {"hri_msgs": ("IdsList", "NormalizedPointOfInterest2D", "NormalizedRegionOfInterest2D", "Skeleton2D")}
#: The source folder of each interface package in this repository.
SOURCE_FOLDERS = {INTERFACE_PACKAGE: "msg_defs", "hri_msgs": "msg_defs_hri"}


class InterfaceDefinitionsNotFound(RuntimeError):
    """The .msg files of hmocap_interfaces (or hri_msgs) could not be found."""


def interface_msg_dir(package: str = INTERFACE_PACKAGE, probe: str = "CameraRig.msg") -> Path:
    """Directory holding the ``.msg`` files of ``package`` (one that has ``probe``)."""
    candidates = [Path(__file__).resolve().parents[2] / SOURCE_FOLDERS[package] / "msg"]
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            candidates.append(Path(prefix) / "share" / package / "msg")
    candidates.append(Path(sys.prefix) / "share" / package / "msg")
    for path in candidates:
        if (path / probe).is_file():
            return path
    raise InterfaceDefinitionsNotFound(
        f"cannot find the {package} .msg files; looked in: "
        + ", ".join(str(p) for p in candidates)
        + ". Run `make setup` (venv) or source the colcon install (ROS)."
    )


@functools.lru_cache(maxsize=1)
def hmocap_typestore() -> Typestore:
    """A Jazzy type store with the hmocap_interfaces and REP-155 messages registered (cached)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for package, names in ((INTERFACE_PACKAGE, INTERFACE_MESSAGES), *REP155_MESSAGES.items()):
        msg_dir = interface_msg_dir(package, f"{names[0]}.msg")
        for name in names:
            text = (msg_dir / f"{name}.msg").read_text()
            types.update(get_types_from_msg(text, f"{package}/msg/{name}"))
    store.register(types)
    return store
