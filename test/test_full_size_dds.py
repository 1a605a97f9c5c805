"""Full-size frames (640x480) at the camera's rate over DDS: every frame a node should see, it answers.

A camera is played by a process (test/fixtures/full_size_camera.py) that publishes 640x480
frames in real time (rgb8 at 25 Hz, 16UC1 at 30 Hz) with a reliable or a best-effort
publisher, as camera drivers do, and counts the node's answers by stamp. The nodes run with
their shipped defaults (``image_reliability`` best effort, ``queue_depth`` one second of frames)
and the one-host Fast DDS profile that conftest names (``config/fastdds_local.xml``); with Fast
DDS's default 512 KiB shared-memory segment the same streams lose a quarter to a half of the
frames (benchmarks/bench_dds_frames.py; docs/network.md).
A stall of the node (the process stopped, DDS threads and all, for 0.6 s) loses nothing either.
"""

from __future__ import annotations

import re
import signal
import sys
import time
from pathlib import Path

import pytest

from hmocap_ros.config_files import find_config_file
from hmocap_ros.nodes.common import image_qos
from hmocap_ros.processes import NodeProcess, loopback_dds_env

#: The camera process (publishes, counts the answers): test/fixtures/full_size_camera.py.
CAMERA = str(Path(__file__).resolve().parent / "fixtures" / "full_size_camera.py")

RIG = find_config_file("rig_example.yaml")


def _stream(tmp_path, node, node_args, ready, stream, stall=None):
    """Start ``node``, stream frames into it (``stream``: the camera's arguments), optionally stop
    the node for ``stall`` seconds mid-stream; (answered, sent) and the node's log."""
    env = loopback_dds_env()
    with NodeProcess.module(node, f"hmocap_ros.nodes.{node}", ["--ros-args", *node_args], env, tmp_path) as proc:
        assert proc.wait_for_output(ready, 120), proc.output()
        with NodeProcess("camera", [sys.executable, CAMERA, *map(str, stream)], env, tmp_path) as camera:
            if stall is not None:
                assert camera.wait_for_output("streaming", 90), camera.output()
                time.sleep(0.2)
                proc.proc.send_signal(signal.SIGSTOP)
                time.sleep(stall)
                proc.proc.send_signal(signal.SIGCONT)
            assert camera.wait(150) == 0, camera.output()
            found = re.search(r"answered (\d+) of (\d+)", camera.output())
            assert found, camera.output()
        log = proc.output()
    assert "Traceback" not in log, log
    return int(found.group(1)), int(found.group(2)), log


def test_foreground_segmentation_segments_every_full_size_rgb8_frame(tmp_path):
    # 640x480 rgb8 (900 KiB) at 25 Hz from a reliable publisher (most drivers' default)
    answered, sent, log = _stream(
        tmp_path, "foreground_segmentation", ["-p", "cameras:=[cam_1]", "-p", "learn_frames:=5",
                                                               "-p", "latest_only:=false"], "segmenting",
        ["/cam_1/image_raw", "rgb8", 25, 15, "reliable", "/cam_1/foreground", "sensor_msgs/msg/Image", "best_effort"])
    assert answered == sent == 15, log


def test_gesture_detection_answers_every_full_size_depth_frame(tmp_path):
    # 640x480 16UC1 (600 KiB) at 30 Hz from a best-effort publisher (sensor-data QoS drivers)
    answered, sent, log = _stream(
        tmp_path, "gesture_detection", ["-p", "publish_probability:=false", "-p", "latest_only:=false"],
        "detecting gestures",
        ["/depth/image_raw", "16UC1", 30, 15, "best_effort", "/gestures", "hmocap_interfaces/msg/GestureArray",
         "reliable"])
    assert answered == sent == 15, log


def test_a_short_stall_loses_no_full_size_frame(tmp_path):
    # The node's process stopped for 0.6 s (15 frames at 25 Hz wait in DDS and its queue of 25)
    answered, sent, log = _stream(
        tmp_path, "camera_rig_publisher", ["-p", f"rig_file:={RIG}", "-p", "cameras:=[cam_1]"], "serving rig",
        ["/cam_1/image_raw", "rgb8", 25, 25, "reliable", "/cam_1/camera_info", "sensor_msgs/msg/CameraInfo",
         "reliable"], stall=0.6)
    assert answered == sent == 25, log


def test_image_qos_reliabilities_and_their_errors():
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

    best = image_qos("best_effort", 25)
    assert (best.reliability, best.depth, best.durability) == (ReliabilityPolicy.BEST_EFFORT, 25,
                                                                DurabilityPolicy.VOLATILE)
    assert image_qos("reliable", 3).reliability == ReliabilityPolicy.RELIABLE
    with pytest.raises(ValueError, match="image_reliability must be one of best_effort, reliable"):
        image_qos("sensor_data", 5)
    with pytest.raises(ValueError, match="queue depth must be >= 1"):
        image_qos("reliable", 0)


def test_a_node_refuses_an_unknown_image_reliability_in_one_line(tmp_path):
    env = loopback_dds_env()
    with NodeProcess.module("rig", "hmocap_ros.nodes.camera_rig_publisher",
                            ["--ros-args", "-p", f"rig_file:={RIG}", "-p", "image_reliability:=sometimes"],
                            env, tmp_path) as proc:
        assert proc.wait(60) == 2, proc.output()
    out = proc.output()
    assert "cannot start: image_reliability must be one of best_effort, reliable, got 'sometimes'" in out, out
    assert "Traceback" not in out
