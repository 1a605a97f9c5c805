"""Image outputs by REP-2003: published reliable, so a default (reliable) subscriber receives them.

RViz's Image display and a default rclpy subscription (``QoSProfile(depth=10)``: reliable,
volatile) match only reliable publishers. foreground_segmentation's masks and
gesture_detection's probability images are published reliable (``image_output_qos``), and
their inputs subscribed best effort, so a best-effort camera still feeds them. The listener
here publishes best-effort inputs, subscribes the outputs with the default QoS and counts what
arrives; rclpy's standard ``qos_overrides`` parameters change an output's QoS.
"""
from __future__ import annotations

import json
import sys

from hmocap_ros.processes import NodeProcess, loopback_dds_env

FRAMES = 20

LISTENER = r"""
import json, sys, time, numpy as np, rclpy
from rclpy.qos import QoSProfile, qos_profile_sensor_data, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image
from hmocap_ros.io.conversions import numpy_to_image
from hmocap_ros.io.msg_factory import RclpyFactory
frames = int(sys.argv[1])
rclpy.init()
node = rclpy.create_node("default_qos_listener")
outputs = ["/cam_1/foreground", "/gestures/probability"]
got = {t: [] for t in outputs}
for topic in outputs:  # rclpy's default: reliable, volatile, keep last 10
    node.create_subscription(Image, topic, lambda m, t=topic: got[t].append(m.header.stamp.nanosec),
                             QoSProfile(depth=10))
camera = node.create_publisher(Image, "/cam_1/image_raw", qos_profile_sensor_data)
depth = node.create_publisher(Image, "/depth/image_raw", qos_profile_sensor_data)
info_pub = node.create_publisher(CameraInfo, "/depth/camera_info", qos_profile_sensor_data)
f = RclpyFactory()
end = time.monotonic() + 90
def spin(seconds):
    stop = time.monotonic() + seconds
    while time.monotonic() < stop:
        rclpy.spin_once(node, timeout_sec=0.01)
while time.monotonic() < end and not all(node.count_publishers(t) for t in outputs) \
        or min(camera.get_subscription_count(), depth.get_subscription_count()) < 1:
    spin(0.05)
spin(1.0)  # the nodes match us in turn
rng = np.random.default_rng(0)
info = CameraInfo(width=64, height=48, k=[60.0, 0, 32, 0, 60.0, 24, 0, 0, 1])
for i in range(frames):
    stamp = 1_000 + i
    img = np.full((24, 32, 3), 90, np.uint8) + rng.integers(0, 3, (24, 32, 3), dtype=np.uint8)
    camera.publish(numpy_to_image(img, "rgb8", stamp, "cam_1", f))
    depth_mm = np.full((48, 64), 2000, np.uint16)
    info.header = numpy_to_image(depth_mm, "16UC1", stamp, "depth", f).header
    info_pub.publish(info)
    depth.publish(numpy_to_image(depth_mm, "16UC1", stamp, "depth", f))
    spin(0.1)
stop = time.monotonic() + 30
while time.monotonic() < stop and min(len(v) for v in got.values()) < frames:
    spin(0.1)
qos = {t: [i.qos_profile.reliability == ReliabilityPolicy.RELIABLE
           for i in node.get_publishers_info_by_topic(t)] for t in outputs}
print("RESULT " + json.dumps({"got": {t: len(v) for t, v in got.items()}, "reliable": qos}), flush=True)
"""


def _result(output: str) -> dict:
    line = [x for x in output.splitlines() if x.startswith("RESULT ")]
    assert line, output
    return json.loads(line[-1][len("RESULT "):])


def test_a_default_reliable_subscriber_receives_masks_and_probability_images(tmp_path):
    env = loopback_dds_env()
    nodes = [NodeProcess.module("fg", "hmocap_ros.nodes.foreground_segmentation",
                                ["--ros-args", "-p", "cameras:=[cam_1]", "-p", "learn_frames:=3",
                                                                "-p", "latest_only:=false"], env, tmp_path),
             NodeProcess.module("gestures", "hmocap_ros.nodes.gesture_detection", [], env, tmp_path)]
    try:
        assert nodes[0].wait_for_output("segmenting", 120), nodes[0].output()
        assert nodes[1].wait_for_output("detecting gestures", 120), nodes[1].output()
        listener = NodeProcess("listener", [sys.executable, "-c", LISTENER, str(FRAMES)], env, tmp_path)
        assert listener.wait_for_output("RESULT", 180), listener.output()
        listener.stop()
    finally:
        for node in nodes:
            node.stop()
    result = _result(listener.output())
    assert result["reliable"] == {"/cam_1/foreground": [True], "/gestures/probability": [True]}
    # every frame, from best-effort inputs (the foreground's first learn the background)
    assert result["got"] == {"/cam_1/foreground": FRAMES, "/gestures/probability": FRAMES}, result
    for node in nodes:
        assert "Traceback" not in node.output(), node.output()


def test_qos_overrides_set_an_image_output_best_effort(tmp_path):
    """rclpy's standard parameter, not a home-made one: the masks published best effort reach
    no default (reliable) subscriber; the publisher says so."""
    env = loopback_dds_env()
    node = NodeProcess.module("fg", "hmocap_ros.nodes.foreground_segmentation",
                              ["--ros-args", "-p", "cameras:=[cam_1]", "-p", "learn_frames:=3",
                                                              "-p", "latest_only:=false", "-p",
                               "qos_overrides./cam_1/foreground.publisher.reliability:=best_effort"],
                              env, tmp_path)
    probe = r"""
import json, time, rclpy
from rclpy.qos import ReliabilityPolicy
rclpy.init()
node = rclpy.create_node("probe")
end = time.monotonic() + 60
while time.monotonic() < end and not node.get_publishers_info_by_topic("/cam_1/foreground"):
    rclpy.spin_once(node, timeout_sec=0.1)
print("RESULT " + json.dumps([i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
                              for i in node.get_publishers_info_by_topic("/cam_1/foreground")]), flush=True)
"""
    try:
        assert node.wait_for_output("segmenting", 120), node.output()
        listener = NodeProcess("probe", [sys.executable, "-c", probe], env, tmp_path)
        assert listener.wait_for_output("RESULT", 90), listener.output()
        listener.stop()
    finally:
        node.stop()
    assert _result(listener.output()) == [True]
    assert "unknown parameter" not in node.output(), node.output()
