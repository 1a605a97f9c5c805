"""image_transport's ``compressed`` transport end to end: decoding, bags, offline tracking, a node.

- :mod:`hmocap_ros.io.image_codec` decodes JPEG and PNG CompressedImage (at a reduced size too),
  reads a compressed image's size and encoding from its header, and refuses corrupt data with a
  CompressedImageError;
- a bag whose cameras are compressed reads under the raw topic names
  (:class:`~hmocap_ros.io.bag_reader.BagReader`), ``hmocap track`` gives the same poses from a
  lossless (PNG) copy of the demo bag as from the raw one, and ``hmocap eval mocap`` tracks a
  JPEG 90 copy in every frame (its error against raw at 160x120 and at 640x480:
  docs/real_sensors.md, "Compressed cameras");
- foreground_segmentation with ``image_transport:=compressed`` segments a JPEG copy of the demo
  bag as well as the raw one, publishes its masks as PNG on ``<camera>/foreground/compressed``,
  and logs a corrupt JPEG without stopping; body_tracker tracks on PNG masks; gesture_detection
  takes compressedDepth depth images; an unknown transport stops a node with one line.
"""
from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from hmocap_ros.cli import main
from hmocap_ros.demo import DEMO_BAG
from hmocap_ros.io.bag_images import compress_bag_images
from hmocap_ros.io.bag_reader import BagReader, BagReadError
from hmocap_ros.io.compressed_images import numpy_to_compressed
from hmocap_ros.io.conversion_errors import CompressedImageError
from hmocap_ros.io.image_codec import (
    check_transport,
    decoded_image,
    decoded_mono,
    decoded_rgb,
    image_encoding,
    image_size,
    reduction_for,
    transport_topic,
)
from hmocap_ros.io.images import image_to_numpy, numpy_to_image
from hmocap_ros.io.msg_factory import RosbagsFactory, stamp_to_ns
from hmocap_ros.io.typestore import hmocap_typestore
from hmocap_ros.processes import NodeProcess, loopback_dds_env, replay_through_nodes
from hmocap_ros.segmentation import mask_scores

CAMERAS = ["cam_1", "cam_2", "cam_3", "cam_4"]


def _picture(height: int = 48, width: int = 64) -> np.ndarray:
    y, x = np.mgrid[:height, :width]
    return np.stack([x * 4 % 256, y * 5 % 256, (x + y) * 2 % 256], axis=2).astype(np.uint8)


@pytest.fixture(scope="module")
def factory():
    return RosbagsFactory(hmocap_typestore())


def test_jpeg_and_png_decode_to_the_image(factory):
    rgb = _picture()
    png = numpy_to_compressed(rgb, "png", 5, "cam", factory)
    jpeg = numpy_to_compressed(rgb, "jpeg", 5, "cam", factory, quality=95)
    np.testing.assert_array_equal(decoded_rgb(png), rgb)
    assert np.abs(decoded_rgb(jpeg).astype(int) - rgb).mean() < 4
    assert decoded_rgb(numpy_to_image(rgb, "rgb8", 5, "cam", factory)).tolist() == rgb.tolist()
    # the same pixels from a raw bgr8 Image
    bgr = numpy_to_image(np.ascontiguousarray(rgb[..., ::-1]), "bgr8", 5, "cam", factory)
    np.testing.assert_array_equal(decoded_rgb(bgr), rgb)


def test_reduced_decoding_halves_the_size(factory):
    rgb = _picture(96, 128)
    jpeg = numpy_to_compressed(rgb, "jpeg", 0, "cam", factory)
    assert decoded_rgb(jpeg, reduction=2).shape == (48, 64, 3)
    assert decoded_rgb(jpeg, reduction=8).shape == (12, 16, 3)
    assert decoded_rgb(numpy_to_image(rgb, "rgb8", 0, "cam", factory), reduction=4).shape == (24, 32, 3)
    mask = numpy_to_compressed((rgb[..., 0] > 128).astype(np.uint8) * 255, "png", 0, "cam", factory)
    assert decoded_mono(mask, reduction=2).shape == (48, 64)
    assert reduction_for(1920, 320) == 4 and reduction_for(640, 640) == 1 and reduction_for(640, 0) == 1
    with pytest.raises(ValueError):
        decoded_rgb(jpeg, reduction=3)


def test_size_and_encoding_come_from_the_header(factory):
    rgb = _picture(30, 50)
    for codec in ("jpeg", "png"):
        msg = numpy_to_compressed(rgb, codec, 0, "cam", factory)
        assert image_size(msg) == (50, 30)
        assert image_encoding(msg) == "rgb8"
        mono = numpy_to_compressed(rgb[..., 1], codec, 0, "cam", factory)
        msg.format = codec  # a bare format, as some drivers write it: the header says
        mono.format = codec
        assert image_encoding(msg) == "rgb8" and image_encoding(mono) == "mono8"
        assert image_size(mono) == (50, 30)
    raw = numpy_to_image(rgb, "bgr8", 0, "cam", factory)
    assert image_size(raw) == (50, 30) and image_encoding(raw) == "bgr8"


def test_corrupt_and_wrong_data_raise_a_conversion_error(factory):
    jpeg = numpy_to_compressed(_picture(), "jpeg", 0, "cam", factory)
    garbage = numpy_to_compressed(_picture(), "jpeg", 0, "cam", factory)
    garbage.data = np.frombuffer(b"\xff\xd8\xff\xe0 this is no JPEG at all", np.uint8)
    for bad in (garbage,):
        with pytest.raises(CompressedImageError):
            decoded_rgb(bad)
        with pytest.raises(CompressedImageError):
            image_size(bad)
    empty = numpy_to_compressed(_picture(), "png", 0, "cam", factory)
    empty.data = np.zeros(0, np.uint8)
    with pytest.raises(CompressedImageError):
        decoded_rgb(empty)
    with pytest.raises(CompressedImageError, match="mono8"):
        decoded_mono(jpeg)  # a colour image on a mask topic
    assert check_transport("compressed") == "compressed"
    with pytest.raises(ValueError, match="raw, compressed"):
        transport_topic("cam_1/image_raw", "theora")
    assert transport_topic("cam_1/image_raw", "compressed") == "cam_1/image_raw/compressed"


@pytest.fixture(scope="module")
def demo_copies(tmp_path_factory):
    """The demo bag with its camera images as PNG and as JPEG 90."""
    folder = tmp_path_factory.mktemp("compressed")
    png, jpeg = folder / "png.mcap", folder / "jpeg.mcap"
    compress_bag_images(DEMO_BAG, png, "png")
    stats = compress_bag_images(DEMO_BAG, jpeg, "jpeg", 90)
    return png, jpeg, stats


def test_a_compressed_bag_reads_under_the_raw_names(demo_copies):
    png, jpeg, stats = demo_copies
    assert stats.images == 4 * 28 and stats.compressed_bytes * 5 < stats.raw_bytes
    with BagReader(DEMO_BAG) as reader:
        raw = {(m.topic, stamp_to_ns(m.msg.header.stamp)): image_to_numpy(m.msg)
               for m in reader.messages([f"/{c}/image_raw" for c in CAMERAS])}
    with BagReader(png) as reader:
        stored = reader.topics()
        assert "/cam_1/image_raw" not in stored
        assert stored["/cam_1/image_raw/compressed"].msgtype == "sensor_msgs/msg/CompressedImage"
        assert reader.topics(compressed_as_raw=True)["/cam_1/image_raw"].count == 28
        got = {(m.topic, stamp_to_ns(m.msg.header.stamp)): decoded_image(m.msg)
               for m in reader.messages([f"/{c}/image_raw" for c in CAMERAS])}
        # a replay (raw CDR) sends the topics as they are stored
        with pytest.raises(BagReadError):
            next(reader.messages(["/cam_1/image_raw"], raw=True))
        assert next(reader.messages(["/cam_1/image_raw/compressed"], raw=True)).topic == \
            "/cam_1/image_raw/compressed"
    assert got.keys() == raw.keys()
    assert all(np.array_equal(got[k], raw[k]) for k in raw)


def _tracked(bag, out) -> dict:
    assert main(["track", str(bag), "--out", str(out), "--quiet"]) == 0
    with BagReader(out) as reader:
        return {stamp_to_ns(m.msg.header.stamp): np.array([[p.x, p.y, p.z] for p in m.msg.positions])
                for m in reader.messages(["/skeleton"])}


def test_hmocap_track_gives_the_same_poses_from_lossless_compressed_images(demo_copies, tmp_path, capsys):
    png, _, _ = demo_copies
    raw = _tracked(DEMO_BAG, tmp_path / "raw.mcap")
    lossless = _tracked(png, tmp_path / "png.mcap")
    capsys.readouterr()
    assert raw and lossless.keys() == raw.keys()
    assert all(np.array_equal(lossless[s], raw[s]) for s in raw)


def _mean_error(bag, out) -> float:
    assert main(["eval", "mocap", str(bag), "--json", str(out)]) == 0
    result = json.loads(out.read_text())["methods"]
    (method,) = result.values()
    assert method["frames_with_pose"] >= method["frames"] - 2
    return float(method["mean_mm"])


def test_a_jpeg_bag_evaluates_like_a_raw_one(demo_copies, tmp_path, capsys):
    _, jpeg, _ = demo_copies
    lossy = _mean_error(jpeg, tmp_path / "jpeg.json")
    capsys.readouterr()
    # 160x120 views: the person is some 60 pixels tall, and JPEG's 8x8 blocks cost the keypoint
    # network accuracy (38.8 mm raw, 55.4 mm JPEG 90 when measured); the A-pose is 179 mm away
    assert lossy < 80.0, lossy


def test_foreground_node_segments_compressed_images(demo_copies, tmp_path):
    _, jpeg, _ = demo_copies
    node = ("foreground_segmentation", "hmocap_ros.nodes.foreground_segmentation",
            ["--ros-args", "-p", "learn_frames:=8", "-p", "latest_only:=false", "-p", "min_blob_area:=10",
             "-p", "image_transport:=compressed"], "segmenting")
    out = tmp_path / "fg.mcap"
    procs = replay_through_nodes(jpeg, [node], [f"/{c}/foreground/compressed" for c in CAMERAS], out,
                                 loopback_dds_env(), tmp_path / "logs",
                                 replay_topics=[f"/{c}/image_raw/compressed" for c in CAMERAS], replay_rate=0.5,
                                 expect={f"/{c}/foreground/compressed": 28 for c in CAMERAS})
    log = procs["foreground_segmentation"].output()
    assert "Traceback" not in log, log
    with BagReader(DEMO_BAG) as reader:
        truth = {(m.topic.split("/")[2], stamp_to_ns(m.msg.header.stamp)): image_to_numpy(m.msg) > 0
                 for m in reader.messages([f"/ground_truth/{c}/silhouette" for c in CAMERAS])}
    with BagReader(out) as reader:
        formats = {m.msg.format for m in reader.messages()}
        masks = {(m.topic.split("/")[1], stamp_to_ns(m.msg.header.stamp)): decoded_mono(m.msg) > 0
                 for m in reader.messages()}
    assert formats == {"mono8; png compressed mono8"}
    assert set(masks) == set(truth)  # one mask per image, with its stamp
    judged = [k for k in masks if truth[k].sum() > 30]
    scores = mask_scores(np.stack([masks[k] for k in judged]), np.stack([truth[k] for k in judged]))
    assert float(np.mean(scores.f1)) > 0.75, scores.f1


CORRUPT_PUBLISHER = r"""
import time, numpy as np, rclpy
from rclpy.qos import QoSProfile
from sensor_msgs.msg import CompressedImage
from hmocap_ros.io.compressed_images import numpy_to_compressed
from hmocap_ros.io.msg_factory import RclpyFactory
rclpy.init()
node = rclpy.create_node("corrupt_input")
pub = node.create_publisher(CompressedImage, "/cam_1/image_raw/compressed", QoSProfile(depth=100))
end = time.monotonic() + 30
while pub.get_subscription_count() < 1 and time.monotonic() < end:
    time.sleep(0.05)
time.sleep(1.0)
f = RclpyFactory()
rng = np.random.default_rng(0)
for i in range(10):
    img = np.full((24, 32, 3), 90, np.uint8) + rng.integers(0, 3, (24, 32, 3), dtype=np.uint8)
    if i >= 5:
        img[8:16, 10:20] = (250, 30, 30)
    msg = numpy_to_compressed(img, "jpeg", 1 + i, "cam_1", f)
    if i == 6:
        msg.data = bytes(b"\xff\xd8\xff\xe0 corrupt")   # a corrupt JPEG among good ones
    pub.publish(msg)
    time.sleep(0.03)
print("sent", flush=True)
time.sleep(1.0)
"""


def test_a_corrupt_jpeg_is_logged_and_the_node_goes_on(tmp_path):
    env = loopback_dds_env()
    with NodeProcess.module("rec", "hmocap_ros.cli", ["record", "--out", str(tmp_path / "o.mcap"), "--progress", "0.1",
                                                      "/cam_1/foreground"], env, tmp_path) as rec, \
         NodeProcess.module("fg", "hmocap_ros.nodes.foreground_segmentation",
                            ["--ros-args", "-p", "cameras:=[cam_1]", "-p", "learn_frames:=5",
                             "-p", "latest_only:=false", "-p", "min_blob_area:=4",
                             "-p", "image_transport:=compressed"], env, tmp_path) as node:
        assert node.wait_for_output("segmenting", 60), node.output()
        assert rec.wait_for_output("receiving /cam_1/foreground from", 60), rec.output()
        with NodeProcess("pub", [sys.executable, "-c", CORRUPT_PUBLISHER], env, tmp_path) as pub:
            assert pub.wait_for_output("sent", 60), pub.output()
        assert rec.wait_for_output("written: 9 messages", 30), rec.output()
        assert node.proc.poll() is None, node.output()
        log = node.output()
    assert "cam_1/image_raw: compressed image" in log and "could not be decoded" in log, log
    assert "Traceback" not in log, log


def test_body_tracker_tracks_on_compressed_masks(tmp_path):
    """body_tracker with ``image_transport:=compressed`` on PNG masks (the demo bag's exact
    silhouettes as ``<camera>/foreground/compressed``): a pose for the frames with the person."""
    from hmocap_ros.demo import DEMO_RIG

    bag = tmp_path / "masks.mcap"
    silhouettes = [f"/ground_truth/{c}/silhouette" for c in CAMERAS]
    compress_bag_images(DEMO_BAG, bag, "png", topics=silhouettes)
    with BagReader(bag) as reader:
        assert reader.topics()[silhouettes[0] + "/compressed"].msgtype == "sensor_msgs/msg/CompressedImage"
        person = {stamp_to_ns(m.msg.header.stamp) for m in reader.messages(["/ground_truth/skeleton"])}
    remaps = [a for c in CAMERAS
              for a in ("-r", f"/{c}/foreground/compressed:=/ground_truth/{c}/silhouette/compressed")]
    node = ("body_tracker", "hmocap_ros.nodes.body_tracker",
            ["--ros-args", "-p", f"rig_file:={DEMO_RIG}", "-p", "method:=hpf-apo", "-p", "image_transport:=compressed",
             "-p", "latest_only:=false", "-p", "queue_depth:=100", "-p", "filter.particles:=120",
             "-p", "filter.layers:=0", "-p", "startup.particles:=60", "-p", "startup.frames:=2", *remaps],
            "kernels ready")
    out = tmp_path / "out.mcap"
    result = replay_through_nodes(bag, [node], ["/skeleton"], out, loopback_dds_env(), tmp_path / "logs",
                                  replay_topics=[t + "/compressed" for t in silhouettes], replay_rate=0.5,
                                  expect={"/skeleton": len(person) - 1}, settle=2.0)
    log = result["body_tracker"].output()
    assert "Traceback" not in log and "foreground:" not in log, log  # no mask refused
    with BagReader(out) as reader:
        skeletons = {stamp_to_ns(m.msg.header.stamp) for m in reader.messages(["/skeleton"])}
    assert len(skeletons) >= len(person) - 1 and skeletons <= person


@pytest.mark.parametrize("module, transport, known", [
    ("hmocap_ros.nodes.body_tracker", "theora", "raw, compressed"),
    ("hmocap_ros.nodes.foreground_segmentation", "compressedDepth", "raw, compressed"),
    ("hmocap_ros.nodes.gesture_detection", "compressed", "raw, compressedDepth")])
def test_an_unknown_transport_stops_the_node_with_one_line(module, transport, known, tmp_path):
    import subprocess

    proc = subprocess.run([sys.executable, "-m", module, "--ros-args", "-p", f"image_transport:={transport}"],
                          env=loopback_dds_env(), capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert f"image_transport must be one of {known}, got '{transport}'" in proc.stderr + proc.stdout
    assert "Traceback" not in proc.stderr + proc.stdout


def test_gesture_detection_takes_compressed_depth(tmp_path):
    """gesture_detection with ``image_transport:=compressedDepth`` on the shipped depth bag's
    frames as compressed_depth_image_transport writes them (lossless PNG): an answer per frame,
    the held gestures found where the ground truth has them."""
    from hmocap_ros.demo import GESTURE_BAG
    from hmocap_ros.io import topics

    bag = tmp_path / "depth.mcap"
    stats = compress_bag_images(GESTURE_BAG, bag, "compressedDepth", topics=[topics.DEPTH_IMAGE])
    assert stats.images == 72 and stats.compressed_bytes < stats.raw_bytes
    node = ("gesture_detection", "hmocap_ros.nodes.gesture_detection",
            ["--ros-args", "-p", "publish_probability:=false", "-p", "latest_only:=false",
             "-p", "image_transport:=compressedDepth"], "detecting gestures")
    out = tmp_path / "gestures.mcap"
    with BagReader(GESTURE_BAG) as reader:
        truth = {stamp_to_ns(m.msg.header.stamp): m.msg for m in reader.messages([topics.GT_GESTURES])}
        width = reader.first(topics.DEPTH_INFO).width
    procs = replay_through_nodes(bag, [node], ["/gestures"], out, loopback_dds_env(), tmp_path / "logs",
                                 replay_topics=[topics.DEPTH_IMAGE + "/compressedDepth", topics.DEPTH_INFO],
                                 expect={"/gestures": len(truth)}, settle=2.0)
    log = procs["gesture_detection"].output()
    assert "Traceback" not in log and "error" not in log.lower(), log
    with BagReader(out) as reader:
        got = {stamp_to_ns(m.msg.header.stamp): m.msg for m in reader.messages(["/gestures"])}
    assert set(got) == set(truth)
    radius = 10.0 * width / 640.0
    labelled = [(s, g) for s, gt in truth.items() for g in gt.gestures if g.position_valid]
    found = sum(any(d.class_id == g.class_id and np.hypot(d.u - g.u, d.v - g.v) <= radius
                    for d in got[s].gestures) for s, g in labelled)
    assert len(labelled) > 20 and found >= 0.6 * len(labelled), (found, len(labelled))
