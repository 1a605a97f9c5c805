#!/usr/bin/env python3
"""Full-size frames over DDS: how many of the frames a camera publishes each node answers.

A camera driver is played by this script: it publishes ``--frames`` 640x480 images at
``--rate`` Hz (rgb8 on ``/cam_1/image_raw`` or 16UC1 on ``/depth/image_raw``) with a reliable
or a best-effort publisher (``--publisher``, keep last 10, as common drivers offer), into one
node started as its own process, and counts the node's answers: ``/cam_1/foreground`` of
``foreground_segmentation``, ``/cam_1/camera_info`` of ``camera_rig_publisher``, ``/gestures``
of ``gesture_detection``. A frame is answered when an output with its stamp arrives. Every
condition runs in a fresh process pair, with or without the package's Fast DDS profile
(``config/fastdds_local.xml``, ``--profile local|none``) and with the node's image QoS
(``--reliability``, ``--queue-depth``; default: the node's own parameters).

``--compare`` runs the table of the README's figures: per node and stream, the frames
answered with the nodes' former QoS (best effort, no profile) and with the shipped defaults
(profile and parameters). Without options it runs that table at 5 Hz only.

Run: ``.venv/bin/python benchmarks/bench_dds_frames.py [--compare] [--node NAME --rate HZ
--frames N --publisher reliable|best_effort --profile local|none --reliability R]``.
DDS stays on loopback (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) in a domain of its own.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

NODES = {
    "foreground_segmentation": ("rgb8", "/cam_1/image_raw", "/cam_1/foreground", "best_effort",
                                ["-p", "cameras:=[cam_1]", "-p", "learn_frames:=5"], "segmenting"),
    "camera_rig_publisher": ("rgb8", "/cam_1/image_raw", "/cam_1/camera_info", "reliable",
                             ["-p", f"rig_file:={ROOT / 'config' / 'rig_example.yaml'}", "-p", "cameras:=[cam_1]"],
                             "serving rig"),
    "gesture_detection": ("16UC1", "/depth/image_raw", "/gestures", "reliable",
                          ["-p", "publish_probability:=false"], "detecting gestures"),
}


def _image(encoding: str):
    import numpy as np

    from hmocap_ros.io.conversions import numpy_to_image
    from hmocap_ros.io.msg_factory import RclpyFactory

    rng = np.random.default_rng(0)
    if encoding == "rgb8":
        pixels = rng.integers(60, 200, (480, 640, 3), dtype=np.uint8)
    else:
        pixels = (2500 + rng.integers(-20, 20, (480, 640))).astype(np.uint16)
    return numpy_to_image(pixels, encoding, 0, "cam_1", RclpyFactory())


def worker(args) -> dict:
    """One condition: the node in its own process, this process as camera and counter."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from hmocap_ros.io import msg_factory
    from hmocap_ros.nodes.common import message_class
    from hmocap_ros.processes import NodeProcess

    encoding, in_topic, out_topic, out_reliability, node_args, ready = NODES[args.node]
    params = list(node_args)
    if args.reliability:
        params += ["-p", f"image_reliability:={args.reliability}"]
    if args.queue_depth:
        params += ["-p", f"queue_depth:={args.queue_depth}"]
    logs = Path(tempfile.mkdtemp(prefix="bench_dds_"))
    node_proc = NodeProcess.module(args.node, f"hmocap_ros.nodes.{args.node}", ["--ros-args", *params],
                                   os.environ, logs)
    rclpy.init()
    node = rclpy.create_node("bench_camera")
    reliability = {"reliable": ReliabilityPolicy.RELIABLE, "best_effort": ReliabilityPolicy.BEST_EFFORT}
    pub = node.create_publisher(message_class("sensor_msgs/msg/Image"), in_topic,
                                QoSProfile(depth=10, reliability=reliability[args.publisher]))
    stamps: set[int] = set()
    out_cls = message_class({"/cam_1/foreground": "sensor_msgs/msg/Image",
                             "/cam_1/camera_info": "sensor_msgs/msg/CameraInfo",
                             "/gestures": "hmocap_interfaces/msg/GestureArray"}[out_topic])
    node.create_subscription(out_cls, out_topic, lambda m: stamps.add(msg_factory.stamp_to_ns(m.header.stamp)),
                             QoSProfile(depth=1000, reliability=reliability[out_reliability]))
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    result = {"node": args.node, "encoding": encoding, "rate": args.rate, "sent": args.frames,
              "publisher": args.publisher, "profile": args.profile, "reliability": args.reliability or "default"}
    try:
        if not node_proc.wait_for_output(ready, 120):
            raise RuntimeError(f"{args.node} did not start:\n{node_proc.output()}")
        end = time.monotonic() + 60
        while time.monotonic() < end and (pub.get_subscription_count() < 1 or node.count_publishers(out_topic) < 1):
            executor.spin_once(timeout_sec=0.05)
        matched = pub.get_subscription_count() >= 1
        result["matched"] = matched
        settle_end = time.monotonic() + 1.5  # both sides of discovery
        while time.monotonic() < settle_end:
            executor.spin_once(timeout_sec=0.05)
        msg = _image(encoding)
        t0 = time.monotonic()
        for i in range(args.frames):
            msg.header.stamp.sec, msg.header.stamp.nanosec = 1000 + i, 0
            pub.publish(msg)
            next_t = t0 + (i + 1) / args.rate
            while time.monotonic() < next_t:
                executor.spin_once(timeout_sec=max(0.0, next_t - time.monotonic()))
        result["publish_s"] = round(time.monotonic() - t0, 2)
        last, quiet = len(stamps), time.monotonic()
        while len(stamps) < args.frames and time.monotonic() - quiet < args.drain:
            executor.spin_once(timeout_sec=0.1)
            if len(stamps) != last:
                last, quiet = len(stamps), time.monotonic()
        result["answered"] = len(stamps)
    finally:
        node_proc.stop()
        node.destroy_node()
        rclpy.try_shutdown()
    for line in node_proc.output().splitlines():
        if "frames segmented" in line:
            result["node_log"] = line.split("]: ", 1)[-1]
    return result


def run_condition(node: str, rate: float, frames: int, publisher: str, profile: str,
                  reliability: str = "", queue_depth: int = 0, drain: float = 5.0) -> dict:
    """Run one condition in a fresh process (the profile is read when DDS starts)."""
    from hmocap_ros.processes import dds_profile_env, loopback_dds_env

    env = loopback_dds_env()
    env.setdefault("ROS_DOMAIN_ID", str(102 + os.getpid() % 120))  # apart from the tests' 1-101
    env.pop("FASTRTPS_DEFAULT_PROFILES_FILE", None)
    env.pop("FASTDDS_DEFAULT_PROFILES_FILE", None)
    if profile != "none":
        env = dds_profile_env(env, profile)
    cmd = [sys.executable, __file__, "--worker", "--node", node, "--rate", str(rate), "--frames", str(frames),
           "--publisher", publisher, "--profile", profile, "--drain", str(drain)]
    if reliability:
        cmd += ["--reliability", reliability]
    if queue_depth:
        cmd += ["--queue-depth", str(queue_depth)]
    out = subprocess.run(cmd, check=False, env=env, capture_output=True, text=True, timeout=600)
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
    if out.returncode != 0 or not lines:
        raise RuntimeError(f"condition failed:\n{out.stdout}\n{out.stderr}")
    return json.loads(lines[-1])


#: (node, rate Hz, frames) of the table: rgb8 at 5 and 25 Hz, 16UC1 at 5 and 30 Hz.
TABLE = [("foreground_segmentation", 5, 30), ("foreground_segmentation", 25, 50),
         ("camera_rig_publisher", 5, 30), ("camera_rig_publisher", 25, 50),
         ("gesture_detection", 5, 30), ("gesture_detection", 30, 60)]


def compare(rates: set[float] | None) -> list[dict]:
    rows = []
    for node, rate, frames in TABLE:
        if rates and rate not in rates:
            continue
        for publisher in ("reliable", "best_effort"):
            before = run_condition(node, rate, frames, publisher, "none", reliability="best_effort")
            after = run_condition(node, rate, frames, publisher, "local")
            rows.append({"node": node, "rate": rate, "publisher": publisher, "sent": frames,
                         "before": before["answered"], "after": after["answered"]})
            print(f"{node:24s} {NODES[node][0]:6s} {rate:4g} Hz  {publisher:11s} publisher: "
                  f"former QoS {before['answered']:3d}/{frames}, shipped defaults {after['answered']:3d}/{frames}",
                  flush=True)
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--node", choices=sorted(NODES), default="foreground_segmentation")
    parser.add_argument("--rate", type=float, default=5.0)
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--publisher", choices=["reliable", "best_effort"], default="reliable")
    parser.add_argument("--profile", choices=["local", "room", "none"], default="local")
    parser.add_argument("--reliability", choices=["reliable", "best_effort"], default="")
    parser.add_argument("--queue-depth", type=int, default=0)
    parser.add_argument("--drain", type=float, default=5.0, help="seconds without an answer that end a condition")
    parser.add_argument("--compare", action="store_true", help="the table at 5 Hz and full rate")
    parser.add_argument("--json", type=Path, help="write the results here")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args)), flush=True)
        return 0
    if args.compare or argv is None and len(sys.argv) == 1:
        rows = compare(None if args.compare else {5})
    else:
        rows = [run_condition(args.node, args.rate, args.frames, args.publisher, args.profile,
                              args.reliability, args.queue_depth, args.drain)]
        print(json.dumps(rows[0]))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
