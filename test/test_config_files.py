"""Every config/<node>.yaml loads and holds exactly the parameters its node declares, at their
defaults, under ``/**`` (so a node in a namespace or under another name reads it); the launch
file compiles and starts the pipeline, every node with its YAML.

A node declares each leaf of its parameter dataclasses by its dotted name
(:func:`hmocap_ros.params.flat_fields`); a YAML file nests the groups (``filter: sweeps: 2``
is the parameter ``filter.sweeps``).
"""

import ast
import importlib
import py_compile
import re
import sys
import types
from pathlib import Path

import pytest
import yaml

from hmocap_ros.params import flat_fields

ROOT = Path(__file__).resolve().parents[1]
# node name -> (module, config dataclass[, module, dataclass ...]): every dataclass the node declares
NODE_CONFIGS = {
    "camera_rig_publisher": ("hmocap_ros.nodes.camera_rig_publisher", "CameraRigPublisherConfig"),
    "foreground_segmentation": ("hmocap_ros.nodes.foreground_segmentation", "ForegroundNodeConfig",
                                "hmocap_ros.segmentation", "ForegroundParams"),
    "gesture_detection": ("hmocap_ros.nodes.gesture_detection", "GestureNodeConfig", "hmocap_ros.gestures",
                          "DetectorParams"),
    "gesture_trainer": ("hmocap_ros.nodes.gesture_trainer", "TrainerNodeConfig", "hmocap_ros.gestures.trainer",
                        "TrainerParams"),
    "body_tracker": ("hmocap_ros.nodes.body_tracker", "BodyTrackerNodeConfig", "hmocap_ros.tracking.params",
                     "TrackerParams"),
    "extremity_detection": ("hmocap_ros.nodes.extremity_detection", "ExtremityNodeConfig",
                            "hmocap_ros.detection.extremity_pipeline", "ExtremityDetectionParams"),
    "room_pipeline": ("hmocap_ros.nodes.body_tracker", "BodyTrackerNodeConfig", "hmocap_ros.nodes.room_pipeline",
                      "RoomStagesConfig", "hmocap_ros.segmentation", "ForegroundParams", "hmocap_ros.tracking.params",
                      "TrackerParams"),
    # the example apps (examples/, installed as hmocap_examples; APP_NODES)
    "light_switch": ("hmocap_examples.light_switch", "LightSwitchConfig"),
    "presence": ("hmocap_examples.presence", "PresenceConfig"),
}
#: The example apps: started by hand next to the pipeline (``ros2 run``), not by a launch file.
APP_NODES = {"light_switch", "presence"}
#: config/*.yaml that are not a node's parameters: rigs, and the example room's places and zones
NOT_NODE_YAMLS = ("rig", "places")


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
    node_yamls = {p.stem for p in (ROOT / "config").glob("*.yaml") if not p.stem.startswith(NOT_NODE_YAMLS)}
    assert node_yamls == set(NODE_CONFIGS)


@pytest.mark.parametrize("node", sorted(NODE_CONFIGS))
def test_node_yaml_matches_declared_parameters(node):
    data = yaml.safe_load((ROOT / "config" / f"{node}.yaml").read_text())
    assert list(data) == ["/**"]  # every node name and namespace
    params = dotted(data["/**"]["ros__parameters"])
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
    tree = data["/**"]["ros__parameters"]
    assert tree["filter"]["sweeps"] == TrackerParams().filter.sweeps  # nested, not dotted


@pytest.mark.parametrize("node", sorted(NODE_CONFIGS))
def test_node_yaml_holds_every_parameter_at_its_default(node):
    """config/<node>.yaml holds each parameter the node declares, at the dataclass default
    (an empty list, which has no type in ROS YAML, is left out)."""
    params = dotted(yaml.safe_load((ROOT / "config" / f"{node}.yaml").read_text())["/**"]["ros__parameters"])
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


#: Nodes outside the room's running pipeline, each with the launch file that starts it.
SESSION_NODES = {"gesture_trainer": "gesture_trainer.launch.py"}


def test_launch_file_starts_every_node_with_its_config():
    """launch/hmocap.launch.py starts each node executable of setup.py (every one but the
    ``hmocap`` tool and the session nodes, which their own launch files start), under its own
    name, with its config/<node>.yaml; the example apps are console scripts of their own package."""
    setup_py = (ROOT / "setup.py").read_text()
    scripts = set(re.findall(r'^\s*"(\w+) = hmocap_ros\.nodes\.\w+:main",', setup_py, re.M))
    assert scripts == set(NODE_CONFIGS) - APP_NODES
    apps = set(re.findall(r'^\s*"(\w+) = hmocap_examples\.(\w+):main",', setup_py, re.M))
    assert apps == {(name, name) for name in APP_NODES}
    launched = _launched_nodes(ROOT / "launch" / "hmocap.launch.py")
    assert set(launched) == scripts - set(SESSION_NODES)
    for executable, launch_file in SESSION_NODES.items():  # started for a session, with their own launch file
        launched[executable] = _launched_nodes(ROOT / "launch" / launch_file)[executable]
    for executable, node in launched.items():
        assert node["package"] == "hmocap_ros" and node["name"] == executable
        assert node["configs"] == [f"{executable}.yaml"], node


#: The pipeline hmocap.launch.py starts, in order.
PIPELINE = ["camera_rig_publisher", "foreground_segmentation", "extremity_detection", "body_tracker",
            "gesture_detection"]
#: ... with ``composed:=true``: the three body stages in one process
COMPOSED = ["camera_rig_publisher", "room_pipeline", "gesture_detection"]


def test_launch_file_starts_the_pipeline_in_order():
    tree = ast.parse((ROOT / "launch" / "hmocap.launch.py").read_text())
    calls = sorted((call.lineno, ast.literal_eval(k.value)) for call in ast.walk(tree)
                   if isinstance(call, ast.Call) and getattr(call.func, "id", None) == "Node"
                   for k in call.keywords if k.arg == "executable")
    assert [executable for _, executable in calls] == PIPELINE[:-1] + ["room_pipeline", PIPELINE[-1]]


class _Stub:
    """A launch action or substitution of the stub launch packages: keeps its arguments."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


class _LaunchConfiguration(_Stub):
    def perform(self, context):
        return context[self.args[0]]


def _run_launch_file(monkeypatch, path: Path, **arguments):
    """Run a launch file against stub launch/launch_ros packages (none in the venv): its declared
    arguments, and the Node actions it makes with ``arguments`` over their defaults."""
    modules = {
        "ament_index_python": types.ModuleType("ament_index_python"),
        "ament_index_python.packages": types.SimpleNamespace(get_package_share_directory=lambda _: str(ROOT)),
        "launch": types.SimpleNamespace(LaunchDescription=_Stub),
        "launch.actions": types.SimpleNamespace(DeclareLaunchArgument=_Stub, OpaqueFunction=_Stub,
                                                IncludeLaunchDescription=_Stub),
        "launch.conditions": types.SimpleNamespace(IfCondition=_Stub),
        "launch.launch_description_sources": types.SimpleNamespace(PythonLaunchDescriptionSource=_Stub),
        "launch.substitutions": types.SimpleNamespace(LaunchConfiguration=_LaunchConfiguration),
        "launch_ros": types.ModuleType("launch_ros"),
        "launch_ros.actions": types.SimpleNamespace(Node=_Stub),
    }
    for name, module in modules.items():
        monkeypatch.setitem(sys.modules, name, module)
    namespace = {"__name__": "launch_file", "__file__": str(path)}
    exec(compile(path.read_text(), str(path), "exec"), namespace)
    description = namespace["generate_launch_description"]()
    declared = {a.args[0]: a.kwargs["default_value"] for a in description.args[0]
                if a.kwargs.get("default_value") is not None}
    context = {**declared, **arguments}
    nodes = []
    for action in description.args[0]:
        if "function" in action.kwargs:
            nodes += action.kwargs["function"](context)
        elif "executable" in action.kwargs:
            nodes.append(action)
    return declared, nodes


def test_launch_file_runs_the_pipeline_from_a_rig_file(monkeypatch, tmp_path):
    """The rig's camera names reach foreground_segmentation and its path camera_rig_publisher;
    the namespace, the gesture node's depth remaps and sim time follow the arguments."""
    from hmocap_ros.geometry.rig import Rig, load_rig, save_rig

    example = load_rig(ROOT / "config" / "rig_example.yaml")
    rig_file = tmp_path / "two_cameras.yaml"
    save_rig(Rig("room", tuple(example[:2])), rig_file)
    declared, nodes = _run_launch_file(monkeypatch, ROOT / "launch" / "hmocap.launch.py", rig_file=str(rig_file),
                                       namespace="room_1", depth_namespace="/camera/camera/depth",
                                       depth_image="image_rect_raw", use_sim_time="true")
    assert {"rig_file", "namespace", "gestures", "depth_namespace", "depth_image", "use_sim_time"} <= set(declared)
    assert declared["gestures"] == "true" and declared["depth_namespace"] == "depth"
    by_name = {n.kwargs["executable"]: n.kwargs for n in nodes}
    assert list(by_name) == PIPELINE
    for executable, node in by_name.items():
        assert node["namespace"] == "room_1" and node["name"] == executable
        files = [p for p in node["parameters"] if isinstance(p, str)]
        assert files == [str(ROOT / "config" / f"{executable}.yaml")]
        assert {"use_sim_time": True} in node["parameters"]
    assert {"rig_file": str(rig_file)} in by_name["camera_rig_publisher"]["parameters"]
    assert {"cameras": list(example.names[:2])} in by_name["foreground_segmentation"]["parameters"]
    gestures = by_name["gesture_detection"]
    assert gestures["condition"].args[0].args[0] == "gestures"  # leave it out with gestures:=false
    assert dict(gestures["remappings"]) == {"depth/image_raw": "/camera/camera/depth/image_rect_raw",
                                            "depth/camera_info": "/camera/camera/depth/camera_info"}
    # the defaults: the package's example rig, the depth camera in depth/ of the namespace
    _, nodes = _run_launch_file(monkeypatch, ROOT / "launch" / "hmocap.launch.py")
    by_name = {n.kwargs["executable"]: n.kwargs for n in nodes}
    assert {"cameras": list(example.names)} in by_name["foreground_segmentation"]["parameters"]
    assert dict(by_name["gesture_detection"]["remappings"])["depth/image_raw"] == "depth/image_raw"
    assert by_name["body_tracker"]["namespace"] == ""
    # composed:=true: the body stages in one process, with its own config
    _, nodes = _run_launch_file(monkeypatch, ROOT / "launch" / "hmocap.launch.py", composed="true")
    by_name = {n.kwargs["executable"]: n.kwargs for n in nodes}
    assert list(by_name) == COMPOSED
    assert [p for p in by_name["room_pipeline"]["parameters"] if isinstance(p, str)] == [
        str(ROOT / "config" / "room_pipeline.yaml")]


def test_launch_file_names_a_bad_rig_file_in_one_line(monkeypatch, tmp_path):
    with pytest.raises(RuntimeError, match="hmocap.launch.py: .*missing.yaml"):
        _run_launch_file(monkeypatch, ROOT / "launch" / "hmocap.launch.py", rig_file=str(tmp_path / "missing.yaml"))


def test_launch_file_gives_every_node_the_dds_profile(monkeypatch, tmp_path):
    variables = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")
    for argument, expected in (({}, ROOT / "config" / "fastdds_local.xml"),
                               ({"dds_profile": "room"}, ROOT / "config" / "fastdds_room.xml")):
        _, nodes = _run_launch_file(monkeypatch, ROOT / "launch" / "hmocap.launch.py", **argument)
        assert [n.kwargs["additional_env"] for n in nodes] == [dict.fromkeys(variables, str(expected))] * len(PIPELINE)
    _, nodes = _run_launch_file(monkeypatch, ROOT / "launch" / "hmocap.launch.py", dds_profile="none")
    assert all(n.kwargs["additional_env"] == {} for n in nodes)
    with pytest.raises(RuntimeError, match="dds_profile .*nothing.xml is not a file"):
        _run_launch_file(monkeypatch, ROOT / "launch" / "hmocap.launch.py", dds_profile=str(tmp_path / "nothing.xml"))


def test_realsense_example_feeds_gesture_detection_the_camera_depth(monkeypatch):
    _, nodes = _run_launch_file(monkeypatch, ROOT / "launch" / "realsense_gestures.launch.py")
    (node,) = [n.kwargs for n in nodes if n.kwargs.get("executable") == "gesture_detection"]
    assert dict(node["remappings"]) == {"depth/image_raw": "/camera/camera/depth/image_rect_raw",
                                        "depth/camera_info": "/camera/camera/depth/camera_info"}
    assert {"depth_unit_m": 0.0} in node["parameters"]


NAMESPACED_NODE = r"""
import sys, rclpy
from rclpy.node import Node
rclpy.init(args=["x", "--ros-args", "-r", "__ns:=/room_2", "-r", "__node:=gestures_left", "--params-file", sys.argv[1]])
node = Node("gesture_detection", automatically_declare_parameters_from_overrides=True)
print(node.get_fully_qualified_name(), node.get_parameter("stride").value, node.get_parameter("model_file").value)
node.destroy_node(); rclpy.shutdown()
"""


def test_yaml_applies_to_a_node_in_a_namespace_under_another_name(tmp_path, free_domain_id):
    import subprocess

    from hmocap_ros.processes import loopback_dds_env

    text = (ROOT / "config" / "gesture_detection.yaml").read_text()
    params = tmp_path / "gestures.yaml"
    params.write_text(re.sub(r"(?m)^(\s+stride:) \d+$", r"\1 3", text))
    res = subprocess.run([sys.executable, "-c", NAMESPACED_NODE, str(params)], capture_output=True, text=True,
                         timeout=60, env=loopback_dds_env(domain_id=free_domain_id))
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["/room_2/gestures_left", "3"], res.stdout
