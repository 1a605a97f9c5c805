"""The shipped viewer layouts show what the demo's bag holds, in the fixed frame the rig publisher puts at the root.

``config/hmocap.rviz`` (RViz 2) and ``config/hmocap_foxglove.json`` (Foxglove) are read as data:
every topic they display must be one the body demo records (:func:`hmocap_ros.demo.body_topics`),
the fixed frame must be ``camera_rig_publisher``'s default, and each camera image must have its
calibration (camera_info) beside it, so the skeleton can be drawn over it.
"""
from __future__ import annotations

import json
from pathlib import Path

import yaml

from hmocap_ros.demo import DEMO_BAG, _cameras, body_topics
from hmocap_ros.io.tf import DEFAULT_FIXED_FRAME
from hmocap_ros.nodes.camera_rig_publisher import CameraRigPublisherConfig

ROOT = Path(__file__).resolve().parents[1]


def _rviz_topics(display: dict) -> list[str]:
    topic = display.get("Topic")
    return [topic["Value"]] if isinstance(topic, dict) else []


def foxglove_topics(layout: dict) -> set[str]:
    """Every topic a Foxglove layout names: panels' topic settings, image and calibration
    topics, message paths (``/topic.field``)."""
    found: set[str] = set()

    def walk(node):
        if isinstance(node, dict):
            for key, value in node.items():
                if key == "topics" and isinstance(value, dict):
                    found.update(k for k in value if k.startswith("/"))
                elif key in ("imageTopic", "calibrationTopic", "topicPath", "topic") and isinstance(value, str) \
                        and value.startswith("/"):
                    found.add(value.split(".", 1)[0].split("{", 1)[0])
                else:
                    walk(value)
        elif isinstance(node, list):
            for item in node:
                walk(item)

    walk(layout["configById"])
    return found


def test_rviz_config_shows_the_demo_bag_in_the_world_frame():
    config = yaml.safe_load((ROOT / "config" / "hmocap.rviz").read_text())["Visualization Manager"]
    assert config["Global Options"]["Fixed Frame"] == DEFAULT_FIXED_FRAME == CameraRigPublisherConfig().fixed_frame
    displays = config["Displays"]
    recorded = set(body_topics(_cameras(DEMO_BAG)))
    shown = {t for d in displays for t in _rviz_topics(d)}
    assert shown <= recorded, shown - recorded
    classes = {d["Class"] for d in displays}
    assert {"rviz_default_plugins/Grid", "rviz_default_plugins/TF", "rviz_default_plugins/MarkerArray",
            "rviz_default_plugins/Camera", "rviz_default_plugins/Image"} <= classes
    cameras = [d for d in displays if d["Class"] == "rviz_default_plugins/Camera"]
    # a Camera display reads <image topic's namespace>/camera_info: recorded too
    assert all(_rviz_topics(d)[0].rsplit("/", 1)[0] + "/camera_info" in recorded for d in cameras)
    assert all(d["Visibility"]["Skeleton (skeleton_markers)"] for d in cameras)
    # images published by the nodes are reliable, camera images may be best effort
    for d in displays:
        if d.get("Topic", {}).get("Value", "").endswith("/foreground"):
            assert d["Topic"]["Reliability Policy"] == "Reliable"


def test_foxglove_layout_shows_the_skeleton_over_every_camera_of_the_demo():
    layout = json.loads((ROOT / "config" / "hmocap_foxglove.json").read_text())
    panels = layout["configById"]
    recorded = set(body_topics(_cameras(DEMO_BAG)))
    images = {k: v for k, v in panels.items() if k.startswith("Image!")}
    for panel in images.values():
        mode = panel["imageMode"]
        assert mode["imageTopic"] in recorded
        if "calibrationTopic" in mode:
            assert mode["calibrationTopic"] in recorded
            assert panel["topics"]["/skeleton_markers"]["visible"]
    overlaid = {p["imageMode"]["imageTopic"] for p in images.values() if "calibrationTopic" in p["imageMode"]}
    assert overlaid == {f"/{c}/image_raw" for c in _cameras(DEMO_BAG)}
    scene = panels["3D!room"]
    assert scene["followTf"] == DEFAULT_FIXED_FRAME and scene["topics"]["/skeleton_markers"]["visible"]
    assert scene["layers"]["grid"]["frameId"] == DEFAULT_FIXED_FRAME

    assert foxglove_topics(layout) <= recorded, foxglove_topics(layout) - recorded

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])

    assert sorted(leaves(layout["layout"])) == sorted(panels)  # every panel placed, none missing
