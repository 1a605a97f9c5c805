"""The shipped viewer layouts show what the demo's bag holds, in the fixed frame the rig publisher puts at the root.

``config/hmocap.rviz`` (RViz 2) and ``config/hmocap_foxglove.json`` (Foxglove) are read as data:
every topic they display must be one the body demo records from its bag
(:func:`hmocap_ros.demo.body_topics` of :data:`hmocap_ros.demo.BODY_BAG`: the camera images in
the bag's transport), the fixed frame must be ``camera_rig_publisher``'s default, and each
camera image must have its calibration (camera_info), so the skeleton can be drawn over it.
RViz's Camera display reads the camera_info beside its image topic
(``image_transport::getCameraInfoTopic``: ``/cam_1/image_raw/compressed`` ->
``/cam_1/image_raw/camera_info``); where that is not the recorded ``/cam_1/camera_info``,
docs/viewing.md's ``ros2 bag play`` remaps it there.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import yaml

from hmocap_ros.demo import BODY_BAG, body_topics, camera_images
from hmocap_ros.io import topics
from hmocap_ros.io.image_codec import transport_topic
from hmocap_ros.io.tf import DEFAULT_FIXED_FRAME
from hmocap_ros.nodes.camera_rig_publisher import CameraRigPublisherConfig

ROOT = Path(__file__).resolve().parents[1]


def _recorded() -> set[str]:
    return set(body_topics(*camera_images(BODY_BAG)))


def rviz_camera_info_topic(image_topic: str) -> str:
    """The camera_info topic RViz 2's Camera display subscribes for ``image_topic``: beside it,
    as ``image_transport::getCameraInfoTopic`` names it."""
    return image_topic.rsplit("/", 1)[0] + "/camera_info"


def _viewing_remaps() -> set[tuple[str, str]]:
    """The ``old:=new`` topic remaps of docs/viewing.md (its ``ros2 bag play`` for RViz)."""
    text = (ROOT / "docs" / "viewing.md").read_text()
    return set(re.findall(r"(/[\w/]+):=(/[\w/]+)", text))


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
    recorded = _recorded()
    shown = {t for d in displays for t in _rviz_topics(d)}
    assert shown <= recorded, shown - recorded
    classes = {d["Class"] for d in displays}
    assert {"rviz_default_plugins/Grid", "rviz_default_plugins/TF", "rviz_default_plugins/MarkerArray",
            "rviz_default_plugins/Camera", "rviz_default_plugins/Image"} <= classes
    cameras = [d for d in displays if d["Class"] == "rviz_default_plugins/Camera"]
    # a Camera display reads the camera_info beside its image topic: recorded, or the recorded
    # <camera>/camera_info remapped there by the playback that docs/viewing.md gives
    remaps = _viewing_remaps()
    for d in cameras:
        image = _rviz_topics(d)[0]
        info = rviz_camera_info_topic(image)
        camera = image.strip("/").split("/")[0]
        assert info in recorded or (f"/{camera}/camera_info", info) in remaps, (image, info)
        assert f"/{camera}/camera_info" in recorded
    assert all(d["Visibility"]["Skeleton (skeleton_markers)"] for d in cameras)
    # images published by the nodes are reliable, camera images may be best effort
    for d in displays:
        if d.get("Topic", {}).get("Value", "").endswith("/foreground"):
            assert d["Topic"]["Reliability Policy"] == "Reliable"


def test_foxglove_layout_shows_the_skeleton_over_every_camera_of_the_demo():
    layout = json.loads((ROOT / "config" / "hmocap_foxglove.json").read_text())
    panels = layout["configById"]
    recorded = _recorded()
    images = {k: v for k, v in panels.items() if k.startswith("Image!")}
    for panel in images.values():
        mode = panel["imageMode"]
        assert mode["imageTopic"] in recorded
        if "calibrationTopic" in mode:
            assert mode["calibrationTopic"] in recorded
            assert panel["topics"]["/skeleton_markers"]["visible"]
    overlaid = {p["imageMode"]["imageTopic"] for p in images.values() if "calibrationTopic" in p["imageMode"]}
    cameras, transport = camera_images(BODY_BAG)
    assert overlaid == {transport_topic(topics.camera_image(c), transport) for c in cameras}
    scene = panels["3D!room"]
    assert scene["followTf"] == DEFAULT_FIXED_FRAME and scene["topics"]["/skeleton_markers"]["visible"]
    assert scene["layers"]["grid"]["frameId"] == DEFAULT_FIXED_FRAME

    assert foxglove_topics(layout) <= recorded, foxglove_topics(layout) - recorded

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])

    assert sorted(leaves(layout["layout"])) == sorted(panels)  # every panel placed, none missing
