"""Every config/<node>.yaml loads and holds exactly the parameters its node declares, at their
defaults; the launch file compiles and starts every node with its YAML.

A node declares each leaf of its parameter dataclasses by its dotted name
(:func:`hmocap_ros.params.flat_fields`); a YAML file nests the groups (``filter: sweeps: 2``
is the parameter ``filter.sweeps``).
"""

import ast
import importlib
import py_compile
import re
from pathlib import Path

import pytest
import yaml

from hmocap_ros.params import flat_fields

ROOT = Path(__file__).resolve().parents[1]
# node name -> (module, config dataclass[, module, dataclass ...]): every dataclass the node declares
NODE_CONFIGS = {
    "camera_rig_publisher": ("hmocap_ros.nodes.camera_rig_publisher", "CameraRigPublisherConfig"),
    "foreground_segmentation": ("hmocap_ros.nodes.foreground_segmentation", "ForegroundNodeConfig", "hmocap_ros.segmentation", "ForegroundParams"),
    "gesture_detection": ("hmocap_ros.nodes.gesture_detection", "GestureNodeConfig", "hmocap_ros.gestures", "DetectorParams"),
    "body_tracker": ("hmocap_ros.nodes.body_tracker", "BodyTrackerNodeConfig", "hmocap_ros.tracking.params", "TrackerParams"),
}


def dotted(tree: dict, prefix: str = "") -> dict:
    """A YAML mapping of parameters as ``{dotted name: value}`` (nested groups joined)."""
    out = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            out.update(dotted(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def test_every_node_yaml_is_known():
    node_yamls = {p.stem for p in (ROOT / "config").glob("*.yaml") if not p.stem.startswith("rig")}
    assert node_yamls == set(NODE_CONFIGS)


@pytest.mark.parametrize("node", sorted(NODE_CONFIGS))
def test_node_yaml_matches_declared_parameters(node):
    data = yaml.safe_load((ROOT / "config" / f"{node}.yaml").read_text())
    assert list(data) == [node]
    params = dotted(data[node]["ros__parameters"])
    spec = NODE_CONFIGS[node]
    fields = {}
    for module, cls_name in zip(spec[::2], spec[1::2], strict=True):
        cls = getattr(importlib.import_module(module), cls_name)
        leaves = {name: (f, default) for name, f, default, _ in flat_fields(cls)}
        assert not set(leaves) & set(fields), f"{cls_name} declares a name twice"
        fields.update(leaves)
    assert set(params) <= set(fields), f"unknown parameters in {node}.yaml: {set(params) - set(fields)}"
    for name, value in params.items():
        default = fields[name][1]
        expected = float if isinstance(default, float) else type(default)
        if isinstance(default, (list, tuple)):
            expected = (list, tuple)
        assert isinstance(value, expected), f"{name}: {value!r} is not a {expected}"
    assert all(f.metadata.get("description") for f, _ in fields.values()), \
        "every parameter needs a description"


def test_body_tracker_yaml_nests_groups():
    from hmocap_ros.tracking.params import TrackerParams

    data = yaml.safe_load((ROOT / "config" / "body_tracker.yaml").read_text())
    tree = data["body_tracker"]["ros__parameters"]
    assert tree["filter"]["sweeps"] == TrackerParams().filter.sweeps  # nested, not dotted


@pytest.mark.parametrize("node", sorted(NODE_CONFIGS))
def test_node_yaml_holds_every_parameter_at_its_default(node):
    """config/<node>.yaml holds each parameter the node declares, at the dataclass default
    (an empty list, which has no type in ROS YAML, is left out)."""
    params = dotted(yaml.safe_load((ROOT / "config" / f"{node}.yaml").read_text())[node]["ros__parameters"])
    spec = NODE_CONFIGS[node]
    for module, cls_name in zip(spec[::2], spec[1::2], strict=True):
        for name, _, default, _ in flat_fields(getattr(importlib.import_module(module), cls_name)):
            if isinstance(default, (list, tuple)) and not default:
                assert name not in params, f"{node}.yaml: {name} (an empty list) is set"
            else:
                assert name in params, f"{node}.yaml lacks {name} (default {default!r})"
                value = params[name]
                if isinstance(default, (list, tuple)):
                    value, default = list(value), list(default)
                assert value == default, f"{node}.yaml: {name} is {value!r}, the default is {default!r}"


def test_launch_files_compile(tmp_path):
    for path in (ROOT / "launch").glob("*.py"):
        py_compile.compile(str(path), cfile=str(tmp_path / "x.pyc"), doraise=True)


def _launched_nodes(path: Path) -> dict[str, dict]:
    """The ``Node(...)`` actions of a launch file, read with ast (no launch package here):
    executable -> {"name": ..., "package": ..., "configs": [YAML file names among its parameters]}."""
    nodes = {}
    for call in ast.walk(ast.parse(path.read_text())):
        if not (isinstance(call, ast.Call) and getattr(call.func, "id", None) == "Node"):
            continue
        kwargs = {k.arg: k.value for k in call.keywords}
        executable = ast.literal_eval(kwargs["executable"])
        configs = [c.value for c in ast.walk(kwargs.get("parameters", ast.List(elts=[])))
                   if isinstance(c, ast.Constant) and isinstance(c.value, str) and c.value.endswith(".yaml")]
        nodes[executable] = {"name": ast.literal_eval(kwargs["name"]),
                             "package": ast.literal_eval(kwargs["package"]), "configs": configs}
    return nodes


def test_launch_file_starts_every_node_with_its_config():
    """launch/hmocap.launch.py starts each node executable of setup.py (every one but the
    ``hmocap`` tool), under its own name, with its config/<node>.yaml."""
    setup_py = (ROOT / "setup.py").read_text()
    scripts = set(re.findall(r'^\s*"(\w+) = hmocap_ros\.nodes\.\w+:main",', setup_py, re.M))
    assert scripts == set(NODE_CONFIGS)
    launched = _launched_nodes(ROOT / "launch" / "hmocap.launch.py")
    assert set(launched) == scripts
    for executable, node in launched.items():
        assert node["package"] == "hmocap_ros" and node["name"] == executable
        assert node["configs"] == [f"{executable}.yaml"], node
