"""The node outputs beside the main ones, over DDS on the shipped bags with small settings:
foreground_segmentation's ``diagnostics`` (body_tracker's ``skeleton_markers`` and per-body
``body_shape``: test_body_tracker_node.py; gesture_detection's ``gestures/probability``:
test_gesture_node.py)."""

from __future__ import annotations

from hmocap_ros.demo import DEMO_BAG
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.processes import loopback_dds_env, replay_through_nodes


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
