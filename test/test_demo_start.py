"""``make demo`` cannot lose its start: the replay begins once its publishers have matched every
node's image subscription (``--wait-subscribers``), with no extra wait for the other side of
discovery (``--settle 0``), and the demo's nodes subscribe reliably, so the reliable replay sends
again whatever a subscription missed while it finished matching: every frame is segmented. The
demo's background is learnt where the landmark network sees nobody, so it could not learn the
person even from frames with the person in them.

The body demo's recording is JPEG (image_transport's ``compressed``) at its cameras' size, an
empty room long enough to learn the background, then at least 5 s of the person, in a few MB;
its nodes take the compressed images, and a run passes only with every frame answered and the
masks and poses near the truth.
"""
from __future__ import annotations

import math

from hmocap_ros.demo import (
    BODY_BAG,
    BODY_RIG,
    DEMO_BAG,
    EXTREMITY_ARGS,
    FOREGROUND_ARGS,
    MAX_JOINT_ERROR_MM,
    MIN_FOREGROUND_F1,
    RELIABLE_IMAGES,
    TRACKER_ARGS,
    BodyScores,
    _cameras,
    body_nodes,
    body_topics,
    camera_images,
)
from hmocap_ros.geometry.rig import load_rig
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.image_codec import image_size
from hmocap_ros.io.msg_factory import stamp_to_ns
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


def test_the_body_demo_bag_shows_five_seconds_of_motion_after_an_empty_room_in_a_few_mb():
    cameras, transport = camera_images(BODY_BAG)
    rig = load_rig(BODY_RIG)
    assert transport == "compressed" and cameras == list(rig.names) and len(cameras) == 4
    assert BODY_BAG.stat().st_size < 6_000_000
    compressed = [f"/{c}/image_raw/compressed" for c in cameras]
    with BagReader(BODY_BAG) as reader:
        first_images = {t: reader.first(t) for t in compressed}
        images = sorted(stamp_to_ns(m.msg.header.stamp) for m in reader.messages(compressed[:1]))
        person = sorted(stamp_to_ns(m.msg.header.stamp) for m in reader.messages([topics.GT_SKELETON]))
    for camera, topic in zip(rig.cameras, compressed):  # JPEG at the calibrated size
        msg = first_images[topic]
        assert "jpeg" in msg.format and image_size(msg) == (camera.width, camera.height) == (320, 240)
    period = (images[-1] - images[0]) / (len(images) - 1)
    empty = images.index(person[0])
    learn_frames = next(int(a.split(":=")[1]) for a in FOREGROUND_ARGS if a.startswith("learn_frames:="))
    assert empty >= learn_frames + 1  # the background is learnt before the person comes
    assert person == images[empty:] and (person[-1] - person[0] + period) * 1e-9 >= 5.0


def test_the_body_demo_nodes_take_the_compressed_images_and_record_them():
    cameras, transport = camera_images(BODY_BAG)
    nodes = {name: args for name, _, args, _ in body_nodes(cameras, transport, BODY_RIG)}
    for name in ("camera_rig_publisher", "foreground_segmentation", "extremity_detection"):
        assert _has(nodes[name], "image_transport:=compressed"), name
    assert not _has(nodes["body_tracker"], "image_transport:=compressed")  # the masks, raw
    recorded = body_topics(cameras, transport)
    assert all(f"/{c}/image_raw/compressed" in recorded and f"/{c}/image_raw" not in recorded for c in cameras)
    assert _cameras(DEMO_BAG) == cameras and camera_images(DEMO_BAG)[1] == "raw"


def test_a_body_demo_passes_with_every_frame_answered_near_the_truth():
    good = BodyScores(masks=75, images=75, foreground_f1=0.9, poses=65, person_frames=65, joint_errors_mm=[40.0] * 65)
    assert good.passed()
    assert not BodyScores(74, 75, 0.9, 65, 65, [40.0] * 65).passed()  # a frame not segmented
    assert not BodyScores(75, 75, 0.9, 64, 65, [40.0] * 64).passed()  # a frame without a pose
    assert not BodyScores(75, 75, MIN_FOREGROUND_F1 - 0.01, 65, 65, [40.0] * 65).passed()
    assert not BodyScores(75, 75, 0.9, 65, 65, [MAX_JOINT_ERROR_MM + 1.0] * 65).passed()
    assert not BodyScores(75, 75, math.nan, 0, 0, []).passed()
