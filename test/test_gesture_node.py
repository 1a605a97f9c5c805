"""gesture_detection over DDS: the shipped depth bag replayed through the node (one GestureArray per
frame with the input stamps, gestures found where the ground truth says), and bad input survived:
a corrupt model file, wrong encodings, short data, NaN depth, no camera_info."""

from __future__ import annotations

import sys

import numpy as np

from hmocap_ros.demo import GESTURE_BAG
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.conversions import image_to_numpy
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.processes import NodeProcess, loopback_dds_env, replay_through_nodes

NODE = ("gesture_detection", "hmocap_ros.nodes.gesture_detection",
        ["--ros-args", "-p", "publish_probability:=false", "-p", "latest_only:=false"],
        "detecting gestures")


def test_gestures_and_a_probability_image_for_every_frame_with_input_stamps(tmp_path):
    out = tmp_path / "gestures.mcap"
    node = (NODE[0], NODE[1], ["--ros-args", "-p", "publish_probability:=true", "-p", "latest_only:=false"],
            NODE[3])
    with BagReader(GESTURE_BAG) as reader:
        truth = {stamp_to_ns(m.msg.header.stamp): m.msg for m in reader.messages([topics.GT_GESTURES])}
        depth = {stamp_to_ns(m.msg.header.stamp): m.msg for m in reader.messages([topics.DEPTH_IMAGE])}
        width = reader.first(topics.DEPTH_INFO).width
    procs = replay_through_nodes(GESTURE_BAG, [node], ["/gestures", "/gestures/probability"], out,
                                 loopback_dds_env(), tmp_path / "logs",
                                 replay_topics=[topics.DEPTH_IMAGE, topics.DEPTH_INFO],
                                 expect={"/gestures/probability": len(depth)}, settle=2.0)
    log = procs["gesture_detection"].output()
    assert "Traceback" not in log and "error" not in log.lower(), log
    with BagReader(out) as reader:
        got = {stamp_to_ns(m.msg.header.stamp): m.msg for m in reader.messages(["/gestures"])}
        prob = {stamp_to_ns(m.msg.header.stamp): m.msg for m in reader.messages(["/gestures/probability"])}
    assert set(got) == set(truth)  # one answer per depth frame, with the frame's stamp
    radius = 10.0 * width / 640.0
    found = false = labelled = 0
    for stamp, gt in truth.items():
        det = got[stamp].gestures
        assert got[stamp].header.frame_id == "depth_optical_frame"
        for g in gt.gestures:
            if g.position_valid:
                labelled += 1
                found += any(d.class_id == g.class_id and np.hypot(d.u - g.u, d.v - g.v) <= radius for d in det)
        false += sum(not any(d.class_id == g.class_id for g in gt.gestures) for d in det)
        for d in det:  # camera_info came with the frames: every gesture has its 3D point
            assert d.position_valid and d.position.z > 0.3
    assert labelled > 20
    assert found >= 0.6 * labelled, (found, labelled)
    assert false <= 0.1 * len(truth), false
    # the debug density: one image per depth frame, with its stamp, high where a gesture is found
    assert set(prob) == set(depth) == set(got)
    peaks = []
    for stamp, msg in prob.items():
        assert msg.encoding == "mono8" and msg.header.frame_id == depth[stamp].header.frame_id
        image = image_to_numpy(msg)
        assert 0 < msg.width <= depth[stamp].width and 0 < msg.height <= depth[stamp].height
        peaks.append(int(image.max()))
        for g in got[stamp].gestures:  # a detection lies on a high density
            u = int(g.u * msg.width / depth[stamp].width)
            v = int(g.v * msg.height / depth[stamp].height)
            patch = image[max(v - 2, 0):v + 3, max(u - 2, 0):u + 3]
            assert patch.max() > 0, (stamp, g.name)
    assert max(peaks) > 100  # the held gestures show as densities near 1, not an empty image


BAD_INPUT_PUBLISHER = r"""
import sys, time, numpy as np, rclpy
from rclpy.qos import QoSProfile
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from sensor_msgs.msg import Image
from hmocap_ros.io.conversions import numpy_to_image
from hmocap_ros.io.msg_factory import RclpyFactory
good_model = sys.argv[1]
rclpy.init()
node = rclpy.create_node("bad_input")
pub = node.create_publisher(Image, "/depth/image_raw", QoSProfile(depth=50))
end = time.monotonic() + 30
while pub.get_subscription_count() < 1 and time.monotonic() < end:
    time.sleep(0.05)
time.sleep(0.5)
f = RclpyFactory()
stamp = 1
def send(img, enc):
    global stamp
    msg = numpy_to_image(img, enc, stamp, "depth_optical_frame", f)
    pub.publish(msg); stamp += 1; time.sleep(0.05)
    return msg
scene = np.full((120, 160), 2500, np.uint16)
send(scene, "16UC1")                                 # no usable forest yet: dropped, logged
client = node.create_client(SetParameters, "/gesture_detection/set_parameters")
assert client.wait_for_service(timeout_sec=20)
def set_model(path):
    value = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=path)
    future = client.call_async(SetParameters.Request(parameters=[Parameter(name="model_file", value=value)]))
    rclpy.spin_until_future_complete(node, future, timeout_sec=60)
    return future.result().results[0]
r = set_model("/nonexistent/forest.npz")
print("refused" if not r.successful else "accepted", r.reason, flush=True)
r = set_model(good_model)
print("loaded" if r.successful else "failed " + r.reason, flush=True)
send(np.zeros((120, 160, 3), np.uint8), "rgb8")      # wrong encoding
short = numpy_to_image(scene, "16UC1", stamp, "depth_optical_frame", f)
short.data = short.data[:100]                        # data shorter than step * height
pub.publish(short); stamp += 1; time.sleep(0.05)
send(np.full((120, 160), np.nan, np.float32), "32FC1")   # NaN everywhere: no valid depth
for _ in range(5):                                   # valid frames without camera_info
    send(scene, "16UC1")
print("sent", flush=True)
time.sleep(1.5)
"""


def test_bad_input_is_logged_and_survived(tmp_path):
    env = loopback_dds_env()
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"PK\x03\x04 not a forest")
    rec = NodeProcess.module("rec", "hmocap_ros.cli", ["record", "-o", str(tmp_path / "o.mcap"), "/gestures"],
                             env, tmp_path)
    node = NodeProcess.module("gd", "hmocap_ros.nodes.gesture_detection",
                              ["--ros-args", "-p", f"model_file:={corrupt}", "-p", "publish_probability:=false",
                               "-p", "latest_only:=false"],
                              env, tmp_path)
    assert node.wait_for_output("detecting gestures once a forest is loaded", 60), node.output()
    assert rec.wait_for_output("recording /gestures [", 30), rec.output()
    # the recorder must have discovered the node's publisher before any frame is answered
    assert rec.wait_for_output("receiving /gestures from", 60), rec.output()
    from hmocap_ros.nodes.gesture_detection import DEFAULT_MODEL

    pub = NodeProcess("pub", [sys.executable, "-c", BAD_INPUT_PUBLISHER, str(DEFAULT_MODEL)], env, tmp_path)
    assert pub.wait_for_output("sent", 120), pub.output()
    pub.stop()
    assert node.proc.poll() is None, node.output()  # still running
    log = node.output()
    node.stop()
    rec.stop()
    assert "refused cannot use the gesture forest /nonexistent/forest.npz" in pub.output(), pub.output()
    assert "loaded" in pub.output(), pub.output()
    assert f"cannot use the gesture forest {corrupt}" in log, log          # corrupt model at start
    assert "depth frames are dropped" in log, log
    assert "encoding 'rgb8'" in log, log
    assert "no valid depth" in log, log
    assert "no depth/camera_info yet" in log, log
    assert "Traceback" not in log, log
    with BagReader(tmp_path / "o.mcap") as reader:
        answers = [m.msg for m in reader.messages()]
    # the NaN frame and the 5 valid frames are answered; nothing before the forest, nor bad frames
    assert len(answers) == 6, len(answers)
    assert all(not g.position_valid for a in answers for g in a.gestures)


UNIT_PUBLISHER = r"""
import time, numpy as np, rclpy
from rclpy.qos import QoSProfile
from sensor_msgs.msg import Image
from hmocap_ros.io.conversions import numpy_to_image
from hmocap_ros.io.msg_factory import RclpyFactory
rclpy.init()
node = rclpy.create_node("unit_publisher")
pub = node.create_publisher(Image, "/depth/image_raw", QoSProfile(depth=50))
end = time.monotonic() + 30
while pub.get_subscription_count() < 1 and time.monotonic() < end:
    time.sleep(0.05)
time.sleep(0.5)
f = RclpyFactory()
scene = np.full((120, 160), 2500, np.uint16)     # 2.5 m in millimetres
scene[40:80, 60:100] = 1800
stamp = 1
for depth in [scene] * 3 + [scene * 8] * 5:      # then raw 1/8 mm values (SR305) as 16UC1
    pub.publish(numpy_to_image(depth, "16UC1", stamp * 40_000_000, "depth_optical_frame", f))
    stamp += 1
    time.sleep(0.1)
print("sent", flush=True)
time.sleep(1.0)
"""


def test_depth_in_the_wrong_unit_is_warned_of_once(tmp_path):
    env = loopback_dds_env()
    node = NodeProcess.module("gd", "hmocap_ros.nodes.gesture_detection",
                              ["--ros-args", "-p", "publish_probability:=false",
                               "-p", "latest_only:=false"], env, tmp_path)
    try:
        assert node.wait_for_output("detecting gestures with", 60), node.output()
        pub = NodeProcess("pub", [sys.executable, "-c", UNIT_PUBLISHER], env, tmp_path)
        assert pub.wait_for_output("sent", 60), pub.output()
        assert node.wait_for_output("median valid depth", 30), node.output()
        pub.stop()
        assert node.proc.poll() is None, node.output()
    finally:
        node.stop()
    log = node.output()
    warnings = [line for line in log.splitlines() if "median valid depth" in line]
    assert len(warnings) == 1, log
    assert "WARN" in warnings[0] and "median valid depth 20 m" in warnings[0], warnings[0]
    assert "depth_unit_m 0.000125 would put it at 2.50 m" in warnings[0], warnings[0]
    assert "Traceback" not in log
