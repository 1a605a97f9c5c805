"""``make demo`` cannot lose its start: the replay begins once its publishers have matched every
node's image subscription (``--wait-subscribers``), with no extra wait for the other side of
discovery (``--settle 0``), and the demo's nodes subscribe reliably, so the reliable replay sends
again whatever a subscription missed while it finished matching: every frame is segmented. The
demo's background is learnt where the landmark network sees nobody, so it could not learn the
person even from frames with the person in them.
"""
from __future__ import annotations

from hmocap_ros.demo import DEMO_BAG, EXTREMITY_ARGS, FOREGROUND_ARGS, RELIABLE_IMAGES, TRACKER_ARGS, _cameras
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.processes import NodeProcess, loopback_dds_env


def _has(args: list[str], setting: str) -> bool:
    return any(a == "-p" and b == setting for a, b in zip(args, args[1:]))


def test_the_demo_nodes_take_images_reliably_and_learn_around_the_person():
    (setting,) = RELIABLE_IMAGES[1:]
    for args in (FOREGROUND_ARGS, EXTREMITY_ARGS, TRACKER_ARGS):
        assert _has(args, setting) and _has(args, "latest_only:=false")
    assert _has(FOREGROUND_ARGS, "learn_from:=person_masks")


def test_a_replay_started_at_the_match_loses_no_frame(tmp_path):
    cameras = _cameras(DEMO_BAG)[:2]
    images = [topics.camera_image(c) for c in cameras]
    with BagReader(DEMO_BAG) as reader:
        n = reader.topics()[images[0]].count
    env = loopback_dds_env()
    out = tmp_path / "masks.mcap"
    masks = [topics.camera_foreground(c) for c in cameras]
    with NodeProcess.module("rec", "hmocap_ros.cli", ["record", "--out", str(out), "--progress", "0.1", *masks],
                            env, tmp_path) as rec, \
         NodeProcess.module("fg", "hmocap_ros.nodes.foreground_segmentation",
                            ["--ros-args", "-p", f"cameras:=[{','.join(cameras)}]", "-p", "learn_frames:=8",
                             "-p", "latest_only:=false", *RELIABLE_IMAGES], env, tmp_path) as node:
        assert node.wait_for_output("segmenting", 60), node.output()
        for topic in masks:
            assert rec.wait_for_output(f"receiving {topic} from", 60), rec.output()
        with NodeProcess.module("play", "hmocap_ros.cli",
                                ["replay", str(DEMO_BAG), "--topics", *images, "--rate", "2", "--wait-subscribers",
                                 "1", "--settle", "0", "--wait-timeout", "60"], env, tmp_path) as play:
            assert play.wait(120) == 0, play.output()
        assert rec.wait_for_output(f"written: {n * len(cameras)} messages", 60), (rec.output(), node.output())
