"""Every config/<node>.yaml loads and names only parameters its node declares; the launch file compiles."""

import dataclasses
import importlib
import py_compile
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
# node name -> (module, config dataclass[, module, dataclass ...]): every dataclass the node declares
NODE_CONFIGS = {
    "camera_rig_publisher": ("hmocap_ros.nodes.camera_rig_publisher", "CameraRigPublisherConfig"),
    "foreground_segmentation": ("hmocap_ros.nodes.foreground_segmentation", "ForegroundNodeConfig", "hmocap_ros.segmentation", "ForegroundParams"),
    "gesture_detection": ("hmocap_ros.nodes.gesture_detection", "GestureNodeConfig", "hmocap_ros.gestures", "DetectorParams"),
    "body_tracker": ("hmocap_ros.nodes.body_tracker", "BodyTrackerNodeConfig", "hmocap_ros.tracking.body_tracker", "TrackerParams"),
}


def test_every_node_yaml_is_known():
    node_yamls = {p.stem for p in (ROOT / "config").glob("*.yaml") if not p.stem.startswith("rig")}
    assert node_yamls == set(NODE_CONFIGS)


@pytest.mark.parametrize("node", sorted(NODE_CONFIGS))
def test_node_yaml_matches_declared_parameters(node):
    data = yaml.safe_load((ROOT / "config" / f"{node}.yaml").read_text())
    assert list(data) == [node]
    params = data[node]["ros__parameters"]
    spec = NODE_CONFIGS[node]
    fields = {}
    for module, cls_name in zip(spec[::2], spec[1::2], strict=True):
        cls = getattr(importlib.import_module(module), cls_name)
        fields.update({f.name: f for f in dataclasses.fields(cls)})
    assert set(params) <= set(fields), f"unknown parameters in {node}.yaml: {set(params) - set(fields)}"
    for name, value in params.items():
        default = fields[name].default
        if default is not dataclasses.MISSING:
            expected = float if isinstance(default, float) else type(default)
            assert isinstance(value, expected), f"{name}: {value!r} is not a {expected.__name__}"
    assert all(f.metadata.get("description") for f in fields.values()), "every parameter needs a description"


def test_launch_files_compile(tmp_path):
    for path in (ROOT / "launch").glob("*.py"):
        py_compile.compile(str(path), cfile=str(tmp_path / "x.pyc"), doraise=True)
