"""package.xml declares what the package needs at run time: every module that hmocap_ros/**/*.py, hmocap_sim/**/*.py,
launch/*.py and examples/*.py import (at the top or inside a function) outside the standard library and the
packages themselves, and every ROS package whose message types they build by name
(``"std_msgs/msg/Header"`` for a message factory), each by its rosdep key.

A Python module is mapped to its rosdep key by :data:`MODULE_KEYS`; a ROS interface package
(``*_msgs``, ``*_srvs``, ``*_interfaces``) and the ROS Python packages of :data:`ROS_PYTHON`
are their own key. A module with no known key fails the check until it is added here with
its key, and to package.xml.
"""

from __future__ import annotations

import ast
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "hmocap_ros"

#: Python module (top level) -> rosdep key. Keys without a distribution package install
#: with pip through rosdep (``*-pip`` keys and ``mcap-ros2-support``); docs/development.md
#: lists them with their pip names.
MODULE_KEYS = {
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "cv2": "python3-opencv",
    "yaml": "python3-yaml",
    "numba": "python3-numba",
    "tqdm": "python3-tqdm",
    "matplotlib": "python3-matplotlib",
    "rosbags": "python3-rosbags-pip",     # pip: rosbags
    "mcap": "mcap-ros2-support",          # pip: mcap, no key of its own; comes with mcap-ros2-support
    "mcap_ros2": "mcap-ros2-support",     # pip: mcap-ros2-support
    "ai_edge_litert": "python3-ai-edge-litert-pip",  # pip: ai-edge-litert
    "imageio_ffmpeg": "python3-imageio-ffmpeg-pip",  # pip: imageio-ffmpeg
}
#: Modules that no rosdep key installs, imported only by a command a ROS install has its own
#: tool for (pip name; the venv installs them from requirements.txt). ``foxglove``: ``hmocap
#: view``, where a ROS install runs foxglove_bridge (ros-jazzy-foxglove-bridge). Documented in
#: docs/development.md; each is imported inside the function that needs it.
PIP_ONLY_MODULES = {"foxglove": "foxglove-sdk"}
#: ROS packages of Python code whose module and rosdep key are the package name.
ROS_PYTHON = {"rclpy", "launch", "launch_ros", "ament_index_python"}
#: The keys that install with pip (rosdep pip rules) and their pip names.
PIP_KEYS = {"python3-rosbags-pip": "rosbags", "mcap-ros2-support": "mcap-ros2-support",
            "python3-ai-edge-litert-pip": "ai-edge-litert", "python3-imageio-ffmpeg-pip": "imageio-ffmpeg"}

_TYPE_NAME = re.compile(r"^([a-z][a-z0-9_]*)/(msg|srv|action)/[A-Z]\w*$")


def source_files() -> list[Path]:
    return (sorted((ROOT / PACKAGE).rglob("*.py")) + sorted((ROOT / "hmocap_sim").rglob("*.py"))
            + sorted((ROOT / "launch").glob("*.py"))
            + sorted((ROOT / "examples").glob("*.py")))


def imported_modules(path: Path) -> set[str]:
    """Top-level names of the absolute imports of a Python file."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def type_name_packages(path: Path) -> set[str]:
    """ROS packages of the message type names (``pkg/msg/Name``) written as strings in a file."""
    return {m.group(1) for node in ast.walk(ast.parse(path.read_text(), str(path)))
            if isinstance(node, ast.Constant) and isinstance(node.value, str)
            and (m := _TYPE_NAME.match(node.value))}


def rosdep_key(module: str) -> str | None:
    """The rosdep key of a third-party or ROS module, None when it is not known."""
    if module in MODULE_KEYS:
        return MODULE_KEYS[module]
    if module in ROS_PYTHON or module.endswith(("_msgs", "_srvs", "_interfaces")):
        return module
    return None


def declared_keys() -> set[str]:
    """Run-time dependencies of package.xml (``depend`` and ``exec_depend``)."""
    root = ET.parse(ROOT / "package.xml").getroot()
    return {e.text.strip() for tag in ("depend", "exec_depend") for e in root.iter(tag)}


def required_keys() -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """``({key: importing files}, {unmapped module: importing files})``."""
    needed: dict[str, set[str]] = {}
    unknown: dict[str, set[str]] = {}
    for path in source_files():
        rel = str(path.relative_to(ROOT))
        for module in imported_modules(path):
            if module in sys.stdlib_module_names or module in (PACKAGE, "hmocap_sim", "hmocap_examples", "__future__",
                                                               *PIP_ONLY_MODULES):
                continue
            key = rosdep_key(module)
            (needed.setdefault(key, set()) if key else unknown.setdefault(module, set())).add(rel)
        for package in type_name_packages(path):
            needed.setdefault(package, set()).add(rel)
    return needed, unknown


def test_every_import_has_a_known_rosdep_key():
    _, unknown = required_keys()
    assert not unknown, "no rosdep key known for " + "; ".join(
        f"{m} (imported by {', '.join(sorted(files)[:3])})" for m, files in sorted(unknown.items())) + \
        ": add it to MODULE_KEYS in test/test_package_xml.py and to package.xml"


def test_package_xml_declares_every_runtime_dependency():
    needed, _ = required_keys()
    missing = {key: files for key, files in needed.items() if key not in declared_keys()}
    assert not missing, "package.xml lacks " + "; ".join(
        f"{key} (for {', '.join(sorted(files)[:3])})" for key, files in sorted(missing.items()))


def test_the_check_sees_what_the_package_needs():
    """The walk finds the imports the nodes, the CLI and the launch files are known to make."""
    needed, _ = required_keys()
    for key in ("rclpy", "python3-numba", "python3-opencv", "rcl_interfaces", "std_srvs", "tf2_msgs",
                "python3-rosbags-pip", "python3-tqdm", "launch", "launch_ros", "std_msgs", "builtin_interfaces"):
        assert key in needed, key
    assert "hmocap_ros/nodes/gesture_detection.py" in needed["rcl_interfaces"]
    assert rosdep_key("os") is None and rosdep_key("some_new_library") is None


def test_pip_only_keys_are_documented():
    declared = declared_keys()
    docs = (ROOT / "docs" / "development.md").read_text()
    xml = (ROOT / "package.xml").read_text()
    for key, pip_name in PIP_KEYS.items():
        if key in declared:
            assert key in docs and f"pip name: {pip_name}" in xml, key
            assert f"`{pip_name}`" in docs, pip_name


def test_pip_only_modules_are_documented_and_imported_lazily():
    docs = (ROOT / "docs" / "development.md").read_text()
    requirements = (ROOT / "requirements.txt").read_text()
    for module, pip_name in PIP_ONLY_MODULES.items():
        assert f"`{pip_name}`" in docs and f"{pip_name}==" in requirements, pip_name
        for path in source_files():
            tree = ast.parse(path.read_text())
            top = {a.name.split(".")[0] for node in tree.body if isinstance(node, ast.Import) for a in node.names}
            top |= {node.module.split(".")[0] for node in tree.body
                    if isinstance(node, ast.ImportFrom) and node.module and node.level == 0}
            assert module not in top, f"{path.relative_to(ROOT)} imports {module} at the top"


def test_package_xml_is_well_formed():
    root = ET.parse(ROOT / "package.xml").getroot()
    assert root.get("format") == "3" and root.findtext("name") == PACKAGE
    keys = [e.text.strip() for tag in ("depend", "exec_depend", "test_depend") for e in root.iter(tag)]
    assert len(keys) == len(set(keys)), "a dependency is declared twice"
    assert root.find("export/build_type").text == "ament_python"
