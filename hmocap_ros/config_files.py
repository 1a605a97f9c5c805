"""Where the package's configuration files are: the source tree's ``config/`` or the ROS share dir."""

from __future__ import annotations

import os
import sys
from pathlib import Path

PACKAGE = "hmocap_ros"


def config_dirs() -> list[Path]:
    """Candidate config directories, most specific first."""
    dirs = [Path(__file__).resolve().parents[1] / "config"]
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share" / PACKAGE / "config")
    dirs.append(Path(sys.prefix) / "share" / PACKAGE / "config")
    return dirs


def find_config_file(name: str) -> Path | None:
    """The first existing ``config/<name>`` (e.g. "rig_example.yaml"), or None."""
    for d in config_dirs():
        path = d / name
        if path.is_file():
            return path
    return None


def default_config_file(node_name: str) -> Path | None:
    """``config/<node_name>.yaml``, the node's default parameters, or None."""
    return find_config_file(f"{node_name}.yaml")
