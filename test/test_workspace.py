"""The README's colcon and rosdep lines work for both packages of the repository.

colcon (colcon-common-extensions from the package index, in the venv) lists ``hmocap_ros`` and
``hmocap_interfaces`` from the README's paths, in a workspace whose ``src/hmocap_ros`` is this
checkout, and builds ``hmocap_ros`` (ament_python) into an install tree with its executables,
launch and config files. The rosdep keys of both ``package.xml`` files resolve for ROS 2 Jazzy on
Ubuntu 24.04: each is in ``test/data/rosdep_keys_jazzy.txt`` (the rosdistro index's keys at one
commit, written by ``tools/rosdep_keys.py``), has a pip rule in ``rosdep/hmocap_ros.yaml`` (which the README adds to
rosdep's sources first), or is a package of the workspace, which
``--ignore-src`` leaves out. (Building ``hmocap_interfaces`` needs the ROS install's CMake
packages; ``make setup`` builds it against the PyPI wheels instead.)
"""
from __future__ import annotations

import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
KEYS = ROOT / "test" / "data" / "rosdep_keys_jazzy.txt"
OWN_RULES = ROOT / "rosdep" / "hmocap_ros.yaml"
COLCON = Path(sys.executable).parent / "colcon"


def readme_lines() -> list[str]:
    """The shell lines of the README's ROS section."""
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## In a ROS 2 Jazzy install (colcon)"):]
    block = re.search(r"```sh\n(.*?)```", section, re.S).group(1)
    return [line.strip() for line in block.splitlines() if line.strip()]


def readme_paths(tool: str) -> list[str]:
    """The package paths the README's ``colcon build`` or ``rosdep install`` line names."""
    line = next(line for line in readme_lines() if line.startswith(tool))
    words = line.split("&&")[0].split()
    flag = "--paths" if tool == "colcon" else "--from-paths"
    start = words.index(flag) + 1
    out = []
    for word in words[start:]:
        if word.startswith("-"):
            break
        out.append(word)
    return out


def workspace_packages(paths: list[str]) -> dict[str, Path]:
    """Package name -> folder of the package.xml at each README path (src/hmocap_ros = ROOT)."""
    out = {}
    for path in paths:
        folder = ROOT / Path(path).relative_to("src/hmocap_ros")
        name = ET.parse(folder / "package.xml").getroot().findtext("name")
        out[name] = folder
    return out


def test_readme_names_both_packages_for_colcon_and_rosdep():
    assert readme_paths("colcon") == readme_paths("rosdep") == ["src/hmocap_ros", "src/hmocap_ros/msg_defs"]
    assert set(workspace_packages(readme_paths("colcon"))) == {"hmocap_ros", "hmocap_interfaces"}


def _colcon(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(COLCON), "--log-base", str(cwd / "log"), *args], cwd=cwd, capture_output=True,
                          text=True, timeout=600)


def test_colcon_lists_both_packages_and_builds_hmocap_ros(tmp_path):
    assert COLCON.exists(), f"{COLCON}: colcon is installed by make setup (requirements.txt)"
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "hmocap_ros").symlink_to(ROOT)
    paths = readme_paths("colcon")
    listed = _colcon(["list", "--paths", *paths], tmp_path)
    assert listed.returncode == 0, listed.stderr
    found = {line.split()[0]: line.split()[2] for line in listed.stdout.splitlines()}
    assert found == {"hmocap_ros": "(ros.ament_python)", "hmocap_interfaces": "(ros.ament_cmake)"}, listed.stdout
    # without the README's paths colcon stops at the root package: why the README names both
    alone = _colcon(["list"], tmp_path)
    assert [line.split()[0] for line in alone.stdout.splitlines()] == ["hmocap_ros"]
    built = _colcon(["build", "--paths", paths[0], "--build-base", str(tmp_path / "build"),
                     "--install-base", str(tmp_path / "install")], tmp_path)
    assert built.returncode == 0, built.stdout + built.stderr
    share = tmp_path / "install" / "hmocap_ros" / "share" / "hmocap_ros"
    for name in ("package.xml", "launch/hmocap.launch.py", "config/body_tracker.yaml", "config/hmocap.rviz",
                 "config/hmocap_foxglove.json", "config/fastdds_local.xml", "config/places_example.yaml",
                 "config/light_switch.yaml"):
        assert (share / name).is_file(), name
    bin_dir = tmp_path / "install" / "hmocap_ros" / "lib" / "hmocap_ros"  # where `ros2 run` looks
    assert {"body_tracker", "camera_rig_publisher", "foreground_segmentation", "hmocap", "light_switch",
            "presence"} <= {p.name for p in bin_dir.iterdir()}
    assert (tmp_path / "install" / "setup.bash").is_file()
    # the simulator is a package of its own, installed beside the product by the same setup.py
    site = next((tmp_path / "install" / "hmocap_ros" / "lib").glob("python3*/site-packages"))
    for package in ("hmocap_ros", "hmocap_sim", "hmocap_sim/render", "hmocap_examples"):
        assert (site / package / "__init__.py").is_file(), package


def _keys(package_xml: Path) -> set[str]:
    root = ET.parse(package_xml).getroot()
    return {e.text.strip() for tag in ("depend", "build_depend", "buildtool_depend", "exec_depend",
                                       "test_depend") for e in root.iter(tag)}


def own_pip_rules() -> dict[str, list[str]]:
    """Key -> pip packages of the rules ``rosdep/hmocap_ros.yaml`` adds for Ubuntu."""
    rules = yaml.safe_load(OWN_RULES.read_text())
    return {key: rule["ubuntu"]["pip"]["packages"] for key, rule in rules.items()}


def test_the_readme_adds_the_own_rules_to_rosdep_before_installing():
    lines = readme_lines()
    source = next(i for i, line in enumerate(lines) if "rosdep/hmocap_ros.yaml" in line)
    install = next(i for i, line in enumerate(lines) if line.startswith("rosdep install"))
    assert source < install
    assert "/etc/ros/rosdep/sources.list.d/" in lines[source] and "rosdep update" in lines[source]
    assert "yaml file://$HOME/ws/src/hmocap_ros/rosdep/hmocap_ros.yaml" in lines[source]


def test_every_rosdep_key_of_both_packages_resolves_on_jazzy():
    index = {line for line in KEYS.read_text().splitlines() if line and not line.startswith("#")}
    assert {"rclpy", "python3-numpy", "tf2_msgs", "hri_msgs"} <= index and len(index) > 1000
    own = own_pip_rules()
    assert own == {"python3-ai-edge-litert-pip": ["ai-edge-litert"], "python3-imageio-ffmpeg-pip": ["imageio-ffmpeg"]}
    assert not set(own) & index, "a rule of our own must not shadow one of the index"
    known = index | set(own)
    workspace = workspace_packages(readme_paths("rosdep"))
    for name, folder in workspace.items():
        missing = sorted(_keys(folder / "package.xml") - known - set(workspace))
        assert not missing, f"{name}: rosdep keys that do not resolve on Jazzy/noble: {missing}"
