"""The room pipeline (segmentation -> keypoints -> tracker on a frame set) and the composed node
that runs it live: the node's poses are ``hmocap track``'s on the same bag, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from hmocap_ros.body import load_body_model
from hmocap_ros.demo import DEMO_BAG, DEMO_RIG
from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.conversions import image_to_rgb
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.io.rig_messages import rig_from_msg
from hmocap_ros.processes import loopback_dds_env, replay_through_nodes
from hmocap_ros.room_pipeline import RoomPipeline
from hmocap_ros.segmentation import ForegroundParams
from hmocap_ros.tracking.params import TrackerParams

CAMERAS = ["cam_1", "cam_2", "cam_3", "cam_4"]
#: the demo bag's 8 empty frames learn the background, as ``hmocap track`` finds them
FOREGROUND = {"learn_frames": 8, "learn_from": "empty_room"}


@pytest.fixture(scope="module")
def demo():
    """The demo bag's rig and its frame sets' RGB images, in stamp order."""
    with BagReader(DEMO_BAG) as reader:
        rig = rig_from_msg(reader.first("/camera_rig"))
        sets: dict[int, dict] = {}
        for m in reader.messages([f"/{c}/image_raw" for c in CAMERAS]):
            sets.setdefault(stamp_to_ns(m.msg.header.stamp), {})[m.topic.split("/")[1]] = image_to_rgb(m.msg)
    return rig, [(stamp, [images.get(c) for c in CAMERAS]) for stamp, images in sorted(sets.items())]


def test_a_view_of_the_wrong_size_is_dropped_with_its_reason_and_the_others_tracked(demo):
    rig, frames = demo
    room = RoomPipeline(rig, TrackerParams(method="hpf-apo"), load_body_model("tracking"),
                        np.random.default_rng(0), foreground=ForegroundParams(**FOREGROUND))
    assert room.detector is None  # hpf-apo takes no detections
    for stamp, images in frames[:9]:
        step = room.step(stamp, images)
    assert all(m is not None for m in step.masks) and room.dropped == []
    small = [images[0][::2, ::2]] + images[1:]
    step = room.step(frames[9][0], small)
    assert step.masks[0] is None and all(m is not None for m in step.masks[1:])
    assert [k for k, _ in room.dropped] == [0], room.dropped
    assert set(step.seconds) == {"segmentation", "tracking"}
    with pytest.raises(ValueError, match="images or masks"):
        room.step(frames[10][0])
    masks_only = RoomPipeline(rig, TrackerParams(method="hpf-apo"), load_body_model("tracking"),
                              np.random.default_rng(0))
    with pytest.raises(ValueError, match="masks must be given"):
        masks_only.step(frames[0][0], frames[0][1])


def test_the_keypoints_of_the_last_skeleton_place_the_next_crops(demo):
    rig, frames = demo
    room = RoomPipeline(rig, TrackerParams(), load_body_model("tracking"), np.random.default_rng(0),
                        foreground=ForegroundParams(**FOREGROUND), detection=ExtremityDetectionParams())
    try:
        posed = None
        for stamp, images in frames:
            step = room.step(stamp, images)
            assert set(step.seconds) == {"segmentation", "detection", "tracking"}
            if step.results[0].has_pose:
                posed = step
                break
        assert posed is not None and posed.detections is not None and len(posed.detections.labels) >= 8
        assert room.previous is not None and {"head", "left_wrist", "right_wrist"} <= set(room.previous)
        room.reset()
        assert room.previous is None and room.people.trackers[0].state == "searching"
    finally:
        room.close()


def test_the_composed_node_publishes_what_hmocap_track_computes_on_the_same_frame_sets(tmp_path, demo):
    from hmocap_ros.eval.bag_tracking import track_to_bag

    offline = tmp_path / "track.mcap"
    track_to_bag(DEMO_BAG, offline, silhouettes="fg", learn_frames=FOREGROUND["learn_frames"],
                 learn_from=FOREGROUND["learn_from"], rig_file=str(DEMO_RIG))
    live = tmp_path / "live.mcap"
    # every frame set whole, as the bag holds it (a view is waited for 2 s on a loaded machine)
    node = ("room_pipeline", "hmocap_ros.nodes.room_pipeline",
            ["--ros-args", "-p", f"rig_file:={DEMO_RIG}", "-p", f"learn_frames:={FOREGROUND['learn_frames']}",
             "-p", "latest_only:=false", "-p", "queue_depth:=100", "-p", "max_wait_ms:=2000.0",
             "-p", "detection.keypoints.pose_rate_hz:=0.0"], "in one process")
    with BagReader(offline) as reader:
        expected = {stamp_to_ns(m.msg.header.stamp): m.msg for m in reader.messages(["/skeleton"])}
    procs = replay_through_nodes(DEMO_BAG, [node], ["/skeleton", "/extremities"], live, loopback_dds_env(),
                                 tmp_path / "logs", replay_topics=[f"/{c}/image_raw" for c in CAMERAS],
                                 replay_rate=0.5, expect={"/skeleton": len(expected)}, settle=2.0)
    log = procs["room_pipeline"].output()
    assert "Traceback" not in log and "in one process" in log, log
    with BagReader(live) as reader:
        got = {stamp_to_ns(m.msg.header.stamp): m.msg for m in reader.messages(["/skeleton"])}
        extremities = list(reader.messages(["/extremities"]))
    assert len(expected) >= 15 and set(got) == set(expected)
    assert len(extremities) >= len(got)  # kf-hpf's detections of every tracked frame set
    for stamp, msg in expected.items():  # the same code on the same frame sets: the same poses
        np.testing.assert_array_equal([[p.x, p.y, p.z] for p in got[stamp].positions],
                                      [[p.x, p.y, p.z] for p in msg.positions])
