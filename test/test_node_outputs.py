"""The node outputs beside the main ones, over DDS on the shipped bags with small settings:
body_tracker's ``skeleton_markers`` and per-body ``humans/bodies/<id>/body_shape`` and
foreground_segmentation's ``diagnostics`` (gesture_detection's ``gestures/probability``:
test_gesture_node.py)."""

from __future__ import annotations

import numpy as np

from hmocap_ros.demo import DEMO_BAG, DEMO_RIG
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.processes import loopback_dds_env, replay_through_nodes

CAMERAS = ["cam_1", "cam_2", "cam_3", "cam_4"]
SMALL_TRACKER = ["-p", "filter.particles:=60", "-p", "filter.layers:=0", "-p", "startup.particles:=40",
                 "-p", "startup.frames:=2"]


def _stamps(reader: BagReader, topic: str) -> list[int]:
    return [stamp_to_ns(m.msg.header.stamp) for m in reader.messages([topic])]


def test_body_tracker_markers_and_per_body_shape(tmp_path):
    # The ground-truth silhouettes straight into the tracker (no foreground node), two body slots.
    remaps = [a for c in CAMERAS for a in ("-r", f"/{c}/foreground:=/ground_truth/{c}/silhouette")]
    node = ("body_tracker", "hmocap_ros.nodes.body_tracker",
            ["--ros-args", "-p", f"rig_file:={DEMO_RIG}", "-p", "method:=hpf-apo", "-p", "queue_depth:=100",
             "-p", "latest_only:=false", "-p", "max_people:=2", *SMALL_TRACKER, *remaps],
            "kernels ready")
    with BagReader(DEMO_BAG) as reader:
        person = set(_stamps(reader, "/ground_truth/skeleton"))
    out = tmp_path / "out.mcap"
    result = replay_through_nodes(
        DEMO_BAG, [node], ["/skeleton", "/skeleton_markers", "/humans/bodies/b0/body_shape"], out,
        loopback_dds_env(), tmp_path / "logs", replay_topics=[f"/ground_truth/{c}/silhouette" for c in CAMERAS],
        replay_rate=0.5, expect={"/skeleton_markers": len(person) - 2}, settle=2.0)
    log = result["body_tracker"].output()
    assert "Traceback" not in log, log
    with BagReader(out) as reader:
        skeletons = {stamp_to_ns(m.msg.header.stamp): m.msg for m in reader.messages(["/skeleton"])}
        markers = {stamp_to_ns(m.msg.markers[0].header.stamp): m.msg
                   for m in reader.messages(["/skeleton_markers"])}
        shapes = [m.msg for m in reader.messages(["/humans/bodies/b0/body_shape"])]
        shape_latched = reader.topics()["/humans/bodies/b0/body_shape"].latched
    assert len(markers) >= len(person) - 2 and set(markers) == set(skeletons)
    for stamp, array in markers.items():
        spheres, bones = array.markers
        sk = skeletons[stamp]
        assert (spheres.type, bones.type) == (spheres.SPHERE_LIST, bones.LINE_LIST)
        assert spheres.ns == bones.ns == sk.body_id == "b0"
        assert spheres.header.frame_id == bones.header.frame_id == "room"
        assert stamp_to_ns(bones.header.stamp) == stamp
        np.testing.assert_allclose([[p.x, p.y, p.z] for p in spheres.points],
                                   [[p.x, p.y, p.z] for p in sk.positions])
        bone_count = sum(1 for parent in sk.parents if parent >= 0)
        assert len(bones.points) == 2 * bone_count
    assert shape_latched and shapes
    shape = shapes[-1]
    assert shape.body_id == "b0" and stamp_to_ns(shape.header.stamp) in skeletons
    assert len(shape.entity_names) > 0 and len(shape.bone_scale) > 0
    assert 1.0 < shape.height < 2.3 and shape.global_scale > 0


def test_foreground_diagnostics_count_frames_per_camera(tmp_path):
    node = ("foreground_segmentation", "hmocap_ros.nodes.foreground_segmentation",
            ["--ros-args", "-p", "cameras:=[cam_1,cam_2]", "-p", "learn_frames:=8", "-p", "latest_only:=false",
             "-p", "diagnostics_period:=0.2"], "segmenting")
    cameras = ["cam_1", "cam_2"]
    with BagReader(DEMO_BAG) as reader:
        frames = reader.topics()["/cam_1/image_raw"].count
    out = tmp_path / "out.mcap"
    result = replay_through_nodes(DEMO_BAG, [node], [*(f"/{c}/foreground" for c in cameras), "/diagnostics"], out,
                                  loopback_dds_env(), tmp_path / "logs",
                                  replay_topics=[f"/{c}/image_raw" for c in cameras], replay_rate=0.5,
                                  expect={f"/{c}/foreground": frames for c in cameras}, settle=1.0)
    log = result["foreground_segmentation"].output()
    assert "Traceback" not in log, log
    with BagReader(out) as reader:
        diags = [m.msg for m in reader.messages(["/diagnostics"])]
    ours = [d for d in diags if d.status and d.status[0].name.startswith("foreground_segmentation")]
    assert ours, diags
    for d in ours:
        assert [s.name for s in d.status] == [f"foreground_segmentation: {c}" for c in cameras]
        assert [s.hardware_id for s in d.status] == cameras
    last = {s.hardware_id: {kv.key: kv.value for kv in s.values} for s in ours[-1].status}
    assert all(int(last[c]["frames"]) == frames and float(last[c]["ms_per_frame"]) > 0 for c in cameras), last
    assert {s.message for s in ours[-1].status} == {"segmenting"}
