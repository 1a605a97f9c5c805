#!/usr/bin/env python3
"""The whole room pipeline live, end to end over DDS: poses per second, latency and error.

A multi-view bag (4 cameras, 640x480, 25 fps) is replayed in real time (``--rate 1``) into
``foreground_segmentation`` -> ``extremity_detection`` -> ``body_tracker``, each its own process
over DDS on loopback with its shipped defaults (each takes the newest frame set when it falls
behind, ``latest_only``), or with ``--composed`` into ``room_pipeline``, the three stages in one
process, while a depth bag (640x480, 30 fps) is replayed into ``gesture_detection`` alongside.
A monitor in this process subscribes to the cameras' images, the depth images and every
output, and notes when each arrives. Reported:

- frame sets in, poses out, poses per second of the stream while a person is in view (and from
  the first pose on, once the start-up is over), frame sets skipped (the tracker's
  ``skipped_frame_sets`` diagnostics);
- latency (stamp to publication: an output's arrival minus the arrival of the frame set it
  was computed from) p50 / p95 / max per output topic;
- outputs that arrived after one with a newer stamp, per topic (``out_of_order``);
- CPU per node: cores (CPU seconds over the run's wall seconds) and ``core_ms_per_set``, CPU
  milliseconds per frame set the node answered (segmentation: per set of masks of the last
  camera; extremities: per ``extremities`` message; tracker: per pose; gestures: per
  ``gestures`` message), with ``core_ms_per_input_set`` per frame set that came in beside it;
- the replay's own timing (``replay_seconds``: from its first to its last publication;
  ``replay_bag_seconds``: the bag's span over the rate; ``replay_behind_max_s``,
  ``replay_behind_p95_s``: how late its messages went out; ``replay_cpu_seconds``), from the
  replay's timing line:
  a replay that keeps real time does not limit the figures above;
- the mean joint error (mm) of the published poses against the bag's ground truth, and with
  ``--offline`` the same tracker run offline on every frame set (``hmocap eval mocap``) beside
  it, on all frames and on the frames published live;
- gestures: depth frames in, frames answered per second, latency;
- ``poses_per_s_bound``: the same room pipeline's frame sets per second offline on the same bag
  (:func:`~hmocap_ros.eval.bag_tracking.track_to_bag`, the nodes' defaults, its first
  ``BOUND_FRAME_SETS`` frame sets), measured in the same run before the nodes start, and
  ``poses_per_s_of_bound``, the live poses per second over it.

Without arguments it renders its bags once into ``out/bench/`` (held-out data: the CMU wave
clip 13_26 from 4 s, simulator seed 401; gestures seed 402), which takes a few minutes.

    .venv/bin/python benchmarks/bench_pipeline.py [BAG] [--depth-bag BAG | --no-gestures] [--composed]
        [--rate 1] [--json OUT] [--offline [--offline-report JSON]] [--param NODE:KEY=VALUE ...]
    .venv/bin/hmocap bench pipeline [BAG] [--json OUT]

On a machine shared with other processes every figure here degrades: run it alone.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import threading
import time
from pathlib import Path

import numpy as np

from hmocap_ros.eval.pipeline_stats import (
    core_ms_per_set,
    frame_period_s,
    header_stamp_ns,
    latency_ms,
    latency_summary,
    pose_errors,
    process_cpu_seconds,
    replay_timing,
)
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader, BagReadError
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.processes import NodeProcess, loopback_dds_env

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DIR = ROOT / "out" / "bench"
DEFAULT_BAG = DEFAULT_DIR / "pipeline_13_26_s401_20s.mcap"
DEFAULT_DEPTH_BAG = DEFAULT_DIR / "pipeline_gestures_s402_21s.mcap"
CLIP = ROOT / "hmocap_ros" / "data" / "bvh" / "13_26.bvh"
BAG_SECONDS = 20.0
DEPTH_FPS = 30.0
THESIS_SECONDS_PER_FRAME = "14-25 s"
#: frame sets the offline bound is measured on (the bag's first ones)
BOUND_FRAME_SETS = 150


def ensure_bags(ns) -> None:
    """Render the default bags when they are not there yet (seeded: the same bags every time)."""
    if ns.bag is None:
        ns.bag = DEFAULT_BAG
        if not DEFAULT_BAG.exists():
            from hmocap_sim.mocap_dataset import MocapSimConfig, generate

            print(f"rendering {DEFAULT_BAG} (once)", flush=True)
            generate(MocapSimConfig(out=DEFAULT_BAG, bvh=CLIP, start=4.0, seconds=BAG_SECONDS, seed=401,
                                    progress=False))
    if ns.depth_bag is None and not ns.no_gestures:
        ns.depth_bag = DEFAULT_DEPTH_BAG
        if not DEFAULT_DEPTH_BAG.exists():
            from hmocap_sim.gesture_dataset import generate as generate_gestures

            print(f"rendering {DEFAULT_DEPTH_BAG} (once)", flush=True)
            generate_gestures(DEFAULT_DEPTH_BAG, seed=402, frames=int((BAG_SECONDS + 1.0) * DEPTH_FPS),
                              fps=DEPTH_FPS, progress=False)


def bag_cameras(bag: Path) -> list[str]:
    with BagReader(bag) as reader:
        return sorted(t.strip("/").split("/")[0] for t, info in reader.topics().items()
                      if t.endswith("/image_raw") and info.msgtype == "sensor_msgs/msg/Image")


def truth_skeletons(bag: Path) -> dict[int, tuple[list[str], np.ndarray]]:
    out = {}
    with BagReader(bag) as reader:
        if topics.GT_SKELETON in reader.topics():
            for m in reader.messages([topics.GT_SKELETON]):
                out[stamp_to_ns(m.msg.header.stamp)] = (list(m.msg.joint_names),
                                                       np.array([[p.x, p.y, p.z] for p in m.msg.positions]))
    return out


class Monitor:
    """An rclpy node in a thread noting, per topic, the arrival (monotonic s) of each header
    stamp; keeps the serialized skeletons and the tracker's last skipped-frame count."""

    def __init__(self, watch: dict[str, str], keep: set[str]):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        from hmocap_ros.nodes.common import message_class

        rclpy.init(args=["bench_pipeline_monitor"])
        self.node = rclpy.create_node("bench_pipeline_monitor")
        self.arrivals: dict[str, dict[int, float]] = {t: {} for t in watch}
        #: per topic, messages whose stamp is older than one that came before them
        self.out_of_order: dict[str, int] = {t: 0 for t in watch}
        self._newest: dict[str, int] = {}
        self.kept: dict[str, dict[int, bytes]] = {t: {} for t in keep}
        self.skipped = 0
        self.tracker_seconds: list[float] = []
        # Best effort matches the sensor-data publishers of images and masks as well as reliable ones.
        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.BEST_EFFORT)
        for topic, typename in watch.items():
            self.node.create_subscription(message_class(typename), topic, self._callback(topic), qos, raw=True)
        diag = message_class("diagnostic_msgs/msg/DiagnosticArray")
        self.node.create_subscription(diag, "/diagnostics", self._on_diagnostics, qos)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self._stop = False
        self.thread.start()

    def _callback(self, topic: str):
        arrivals, kept = self.arrivals[topic], self.kept.get(topic)

        def on_message(data: bytes) -> None:
            now = time.monotonic()
            stamp = header_stamp_ns(data)
            if stamp < self._newest.get(topic, stamp):
                self.out_of_order[topic] += 1
            self._newest[topic] = max(stamp, self._newest.get(topic, stamp))
            arrivals.setdefault(stamp, now)
            if kept is not None:
                kept[stamp] = data
        return on_message

    def _on_diagnostics(self, msg) -> None:
        for status in msg.status:
            if status.name.startswith(("body_tracker", "room_pipeline")):
                values = {kv.key: kv.value for kv in status.values}
                if "skipped_frame_sets" in values:
                    self.skipped = max(self.skipped, int(values["skipped_frame_sets"]))
                if "seconds_per_frame" in values and status.message not in ("searching", "waiting"):
                    self.tracker_seconds.append(float(values["seconds_per_frame"]))

    def _spin(self) -> None:
        while not self._stop:
            self.executor.spin_once(timeout_sec=0.05)

    def count(self, topic: str) -> int:
        return len(self.arrivals[topic])

    def close(self) -> None:
        import rclpy

        self._stop = True
        self.thread.join(5.0)
        self.node.destroy_node()
        rclpy.try_shutdown()


NODES = ("foreground_segmentation", "extremity_detection", "body_tracker", "room_pipeline", "gesture_detection")


def node_params(items: list[str], node: str) -> dict[str, str]:
    """``NODE:KEY=VALUE`` items of ``--param`` that are ``node``'s, as {KEY: VALUE}."""
    out = {}
    for item in items:
        name, _, kv = item.partition(":")
        if name == node:
            key, _, value = kv.partition("=")
            out[key] = value
    return out


def start_nodes(cameras: list[str], ns, env: dict, log_dir: Path) -> dict[str, NodeProcess]:
    nodes = {
        "foreground_segmentation": ("hmocap_ros.nodes.foreground_segmentation",
                                    ["-p", f"cameras:=[{','.join(cameras)}]"], "segmenting"),
        "extremity_detection": ("hmocap_ros.nodes.extremity_detection", [], "waiting for the rig"),
        "body_tracker": ("hmocap_ros.nodes.body_tracker", [], "waiting for the rig"),
    }
    if ns.composed:
        nodes = {"room_pipeline": ("hmocap_ros.nodes.room_pipeline", [], "waiting for the rig")}
    if ns.depth_bag is not None:
        nodes["gesture_detection"] = ("hmocap_ros.nodes.gesture_detection", [], "detecting gestures")
    procs = {}
    for name, (module, args, _ready) in nodes.items():
        own = [a for key, value in node_params(ns.param, name).items() for a in ("-p", f"{key}:={value}")]
        procs[name] = NodeProcess.module(name, module, ["--ros-args", *args, *own], env, log_dir)
    for name, (_module, _args, ready) in nodes.items():
        if not procs[name].wait_for_output(ready, 120.0):
            raise RuntimeError(f"{name} did not start:\n{procs[name].output()}")
    return procs


def run(ns) -> dict:
    ensure_bags(ns)
    bag = Path(ns.bag)
    cameras = bag_cameras(bag)
    if not cameras:
        raise BagReadError(f"{bag}: no <camera>/image_raw topics")
    out_dir = Path(ns.logs)
    env = loopback_dds_env(domain_id=ns.domain_id)
    # every camera's images (the replay waits for the monitor on each), the last one's counted
    watch = {**{topics.camera_image(c): "sensor_msgs/msg/Image" for c in cameras},
             "/skeleton": "hmocap_interfaces/msg/Skeleton",
             "/extremities": "hmocap_interfaces/msg/Extremities"}
    if not ns.composed:
        watch.update({topics.camera_foreground(c): "sensor_msgs/msg/Image" for c in cameras})
    if ns.depth_bag is not None:
        watch.update({topics.DEPTH_IMAGE: "sensor_msgs/msg/Image", "/gestures": "hmocap_interfaces/msg/GestureArray"})
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE") if k in env})
    bound = offline_bound(bag, ns)
    monitor = Monitor(watch, keep={"/skeleton"})
    procs: dict[str, NodeProcess] = {}
    try:
        procs = start_nodes(cameras, ns, env, out_dir)
        print(f"nodes up: {', '.join(procs)}; replaying {bag.name}"
              + (f" and {Path(ns.depth_bag).name}" if ns.depth_bag else "") + f" at rate {ns.rate:g}", flush=True)
        cpu0 = {n: process_cpu_seconds(p.proc.pid) or 0.0 for n, p in procs.items()}
        # the monitor and every node that takes the images, so none loses the first frames
        image_takers = 1 + (1 if ns.composed else 2)
        replays = [NodeProcess.module("replay", "hmocap_ros.cli",
                                      ["replay", str(bag), "--rate", str(ns.rate), "--wait-subscribers",
                                       str(image_takers),
                                       "--topics", topics.CAMERA_RIG, *(topics.camera_image(c) for c in cameras)],
                                      env, out_dir)]
        if ns.depth_bag is not None:
            replays.append(NodeProcess.module("replay_depth", "hmocap_ros.cli",
                                              ["replay", str(ns.depth_bag), "--rate", str(ns.rate),
                                               "--wait-subscribers", "2",  # the monitor, gestures
                                               "--topics", topics.DEPTH_IMAGE, topics.DEPTH_INFO], env, out_dir))
        t0 = time.monotonic()
        for r in replays:
            if r.wait(3600) != 0:
                raise RuntimeError(f"the replay failed:\n{r.output()}")
        replay = replay_timing(replays[0].output())
        # The last outputs: wait until nothing new arrives for 3 s.
        last, quiet = -1, time.monotonic()
        while time.monotonic() - quiet < 3.0 and time.monotonic() - t0 < replay["replay_seconds"] + 120:
            n = sum(monitor.count(t) for t in watch)
            if n != last:
                last, quiet = n, time.monotonic()
            time.sleep(0.1)
        wall = time.monotonic() - t0
        cpu_s = {n: (process_cpu_seconds(p.proc.pid) or 0.0) - cpu0[n] for n, p in procs.items()}
    finally:
        for p in procs.values():
            p.stop()
        monitor.close()
    out = report(ns, bag, cameras, monitor, cpu_s, wall, replay)
    out["poses_per_s_bound"] = bound
    out["poses_per_s_of_bound"] = out["poses_per_s"] / bound if bound > 0 else float("nan")
    return out


def offline_bound(bag: Path, ns) -> float:
    """Frame sets per second of the room pipeline offline on the bag's first
    :data:`BOUND_FRAME_SETS` frame sets, with the nodes' defaults and ``--param``'s settings of
    the tracker (``body_tracker`` or ``room_pipeline``)."""
    import tempfile

    from hmocap_ros.eval.bag_tracking import track_to_bag
    from hmocap_ros.eval.mocap_eval import tracker_overrides
    from hmocap_ros.params import flat_fields
    from hmocap_ros.tracking.params import TrackerParams

    node = "room_pipeline" if ns.composed else "body_tracker"
    names = {name for name, *_ in flat_fields(TrackerParams)}
    tracker = [f"{k}={v}" for k, v in node_params(ns.param, node).items() if k in names]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        counts = track_to_bag(bag, Path(tmp) / "bound.mcap", silhouettes="fg",
                              overrides=tracker_overrides(tracker), max_frames=BOUND_FRAME_SETS)
        seconds = time.perf_counter() - t0
    return counts["frame_sets"] / seconds


def offline_report(bag: Path, ns) -> dict:
    """``hmocap eval mocap``'s report of the tracker (the node's settings of ``--param``) on every
    frame set of ``bag``: read from ``--offline-report`` when it holds one made with these
    settings, else computed (and written there when it is given)."""
    from hmocap_ros.eval.mocap_eval import evaluate, tracker_overrides

    tracker = sorted(f"{k}={v}" for k, v in node_params(ns.param, "body_tracker").items() if k != "method")
    path = Path(ns.offline_report) if ns.offline_report else None
    if path is not None and path.exists():
        stored = json.loads(path.read_text())
        if stored.get("bag") == str(bag) and stored.get("bench_tracker_params") == tracker:
            return stored
    report = evaluate(bag, ["kf-hpf"], overrides=tracker_overrides(tracker), out=sys.stderr)
    report["bench_tracker_params"] = tracker
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(report))
    return report


def tracking_rate(poses: dict, inputs: dict, truth: dict, period: float) -> float:
    """Poses per second of stream time from the frame set of the first pose on: the rate once
    the start-up (visual hull, shape estimation) is over."""
    first = min((s for s in poses if s in truth), default=None)
    if first is None:
        return float("nan")
    after = [s for s in inputs if s in truth and s >= first]
    return len([s for s in poses if s in truth]) / max(len(after) * period, 1e-9)


def report(ns, bag: Path, cameras: list[str], monitor: Monitor, cpu_s: dict, wall: float,
           replay: dict) -> dict:
    from rclpy.serialization import deserialize_message

    from hmocap_ros.nodes.common import message_class

    arrivals = monitor.arrivals
    inputs = arrivals[topics.camera_image(cameras[-1])]
    truth = truth_skeletons(bag)
    period = frame_period_s(list(inputs)) if len(inputs) > 1 else 0.04
    skel_cls = message_class("hmocap_interfaces/msg/Skeleton")
    estimates = {}
    for stamp, data in monitor.kept["/skeleton"].items():
        msg = deserialize_message(data, skel_cls)
        estimates[stamp] = (list(msg.joint_names), np.array([[p.x, p.y, p.z] for p in msg.positions]))
    errors = pose_errors(estimates, truth)
    person_in = [s for s in inputs if s in truth]
    poses = arrivals["/skeleton"]
    answered = ({"room_pipeline": len(poses)} if ns.composed else
                {"foreground_segmentation": len(arrivals[topics.camera_foreground(cameras[-1])]),
                 "extremity_detection": len(arrivals["/extremities"]), "body_tracker": len(poses)})
    if ns.depth_bag is not None:
        answered["gesture_detection"] = len(arrivals["/gestures"])
    per_set = core_ms_per_set(cpu_s, answered, len(inputs))
    out = {
        "bag": str(bag), "cameras": len(cameras), "rate": ns.rate,
        "machine": {"cpus": os.cpu_count(), "processor": platform.processor() or platform.machine()},
        "node_params": list(ns.param),
        **replay,
        "frame_sets_in": len(inputs), "frame_sets_with_person": len(person_in),
        "poses_out": len(poses),
        "poses_per_s": len([s for s in poses if s in truth]) / max(len(person_in) * period, 1e-9),
        "poses_per_s_tracking": tracking_rate(poses, inputs, truth, period),
        "frame_sets_skipped": monitor.skipped,
        "out_of_order": {t: n for t, n in monitor.out_of_order.items()
                         if t not in {topics.camera_image(c) for c in cameras}},
        **latency_summary(latency_ms(inputs, poses)),
        "mean_error_mm": float(np.mean(list(errors.values()))) if errors else float("nan"),
        "tracker_seconds_per_frame": (float(np.median(monitor.tracker_seconds)) if monitor.tracker_seconds
                                      else float("nan")),
        "extremities": {"out": len(arrivals["/extremities"]),
                        **latency_summary(latency_ms(inputs, arrivals["/extremities"]))},
        "composed": bool(ns.composed),
        "foreground": {c: len(arrivals.get(topics.camera_foreground(c), {})) for c in cameras},
        "foreground_latency": latency_summary(latency_ms(inputs, arrivals.get(topics.camera_foreground(cameras[-1]),
                                                                               {}))),
        "cpu_cores": {n: c / wall for n, c in cpu_s.items()},
        "core_ms_per_set": {n: v["core_ms_per_set"] for n, v in per_set.items()},
        "core_ms_per_input_set": {n: v["core_ms_per_input_set"] for n, v in per_set.items()},
        "first_pose_after_person_s": (min(poses[s] for s in poses) - min(inputs[s] for s in person_in)
                                      if poses and person_in else float("nan")),
    }
    if ns.depth_bag is not None:
        depth_in, answered = arrivals[topics.DEPTH_IMAGE], arrivals["/gestures"]
        depth_period = frame_period_s(list(depth_in)) if len(depth_in) > 1 else 1 / DEPTH_FPS
        out["gestures"] = {"bag": str(ns.depth_bag), "depth_frames_in": len(depth_in),
                           "frames_answered": len(answered),
                           "frames_per_s": len(answered) / max(len(depth_in) * depth_period, 1e-9),
                           **latency_summary(latency_ms(depth_in, answered))}
    if ns.offline:
        offline = offline_report(bag, ns)
        per_frame = offline["methods"]["kf-hpf"]["per_frame_mm"]
        by_stamp = {s: e for s, e in zip(sorted(truth), per_frame) if e is not None}
        same = [by_stamp[s] for s in errors if s in by_stamp]
        out["offline"] = {"mean_error_mm": float(np.mean(list(by_stamp.values()))),
                          "mean_error_mm_on_published_stamps": float(np.mean(same)) if same else float("nan"),
                          "seconds_per_frame": offline["methods"]["kf-hpf"]["seconds_per_frame"]}
    return out


def print_report(r: dict) -> None:
    print(f"\n{Path(r['bag']).name}: {r['cameras']} cameras, replay at rate {r['rate']:g}: "
          f"{r['replay_bag_seconds']:.1f} s of bag published in {r['replay_seconds']:.1f} s, at most "
          f"{r['replay_behind_max_s']:.2f} s behind (p95 {r['replay_behind_p95_s']:.3f} s), "
          f"{r['replay_cpu_seconds']:.1f} CPU s; "
          f"{r['machine']['cpus']} CPUs")
    print(f"  frame sets in {r['frame_sets_in']} ({r['frame_sets_with_person']} with a person), poses out "
          f"{r['poses_out']}, {r['poses_per_s']:.2f} poses/s ({r['poses_per_s_tracking']:.2f} from the first "
          f"pose on), skipped {r['frame_sets_skipped']}, first pose "
          f"{r['first_pose_after_person_s']:.1f} s after the person came in")
    print(f"  pose latency p50 {r['latency_p50_ms']:.0f} ms, p95 {r['latency_p95_ms']:.0f} ms, max "
          f"{r['latency_max_ms']:.0f} ms; tracker {r['tracker_seconds_per_frame']:.2f} s per frame set "
          f"(the thesis: {THESIS_SECONDS_PER_FRAME})")
    print(f"  mean joint error of the published poses {r['mean_error_mm']:.1f} mm; offline the same pipeline "
          f"tracks {r['poses_per_s_bound']:.2f} frame sets/s: live is {r['poses_per_s_of_bound']:.2f} of it")
    if "offline" in r:
        o = r["offline"]
        print(f"  offline, every frame set: {o['mean_error_mm']:.1f} mm ({o['mean_error_mm_on_published_stamps']:.1f} "
              f"on the published stamps), {o['seconds_per_frame']:.2f} s per frame set")
    e = r["extremities"]
    print(f"  extremities {e['out']}/{r['frame_sets_in']}, latency p50 {e['latency_p50_ms']:.0f} ms, "
          f"p95 {e['latency_p95_ms']:.0f} ms; foreground masks per camera "
          + " ".join(f"{c} {n}" for c, n in r["foreground"].items()))
    if "gestures" in r:
        g = r["gestures"]
        print(f"  gestures: {g['frames_answered']}/{g['depth_frames_in']} depth frames answered, "
              f"{g['frames_per_s']:.1f} frames/s, latency p50 {g['latency_p50_ms']:.0f} ms, p95 "
              f"{g['latency_p95_ms']:.0f} ms")
    print("  CPU (cores): " + ", ".join(f"{n} {c:.2f}" for n, c in r["cpu_cores"].items()))
    print("  CPU ms per frame set answered (per set in): " + ", ".join(
        f"{n} {c:.0f} ({r['core_ms_per_input_set'][n]:.0f})" for n, c in r["core_ms_per_set"].items()))
    late = {t: n for t, n in r["out_of_order"].items() if n}
    print("  outputs out of stamp order: " + (", ".join(f"{t} {n}" for t, n in late.items()) or "none"))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("bag", nargs="?", default=None, help="multi-view bag (default: rendered once into out/bench/)")
    p.add_argument("--depth-bag", default=None, help="depth bag for gesture_detection alongside (default: rendered)")
    p.add_argument("--no-gestures", action="store_true", help="no gesture_detection alongside")
    p.add_argument("--composed", action="store_true",
                   help="the room_pipeline node (segmentation, keypoints and tracking in one process) in place "
                        "of foreground_segmentation, extremity_detection and body_tracker")
    p.add_argument("--rate", type=float, default=1.0, help="replay rate (default 1: real time)")
    p.add_argument("--param", action="append", default=[], metavar="NODE:KEY=VALUE",
                   help="a node's parameter (repeatable), e.g. body_tracker:filter.particles=100")
    p.add_argument("--offline", action="store_true",
                   help="also run the tracker offline on every frame set and report its error")
    p.add_argument("--offline-report", metavar="JSON", default=None,
                   help="with --offline: the offline report, reused when it was made with the same bag and "
                        "tracker settings, else written there")
    p.add_argument("--json", metavar="OUT", help="write the figures as JSON")
    p.add_argument("--logs", default=str(DEFAULT_DIR / "logs"), help="node logs (default out/bench/logs)")
    p.add_argument("--domain-id", type=int, default=None, help="ROS_DOMAIN_ID (default: the environment's)")
    ns = p.parse_args(argv)
    if not ns.rate > 0:
        print("bench_pipeline: --rate must be > 0", file=sys.stderr)
        return 2
    for item in ns.param:
        node, _, kv = item.partition(":")
        if node not in NODES or "=" not in kv:
            print(f"bench_pipeline: --param {item!r} is not NODE:KEY=VALUE with NODE one of {', '.join(NODES)}",
                  file=sys.stderr)
            return 2
    try:
        r = run(ns)
    except (BagReadError, RuntimeError, OSError) as err:
        print(f"bench_pipeline: {err}", file=sys.stderr)
        return 2
    print_report(r)
    if ns.json:
        Path(ns.json).parent.mkdir(parents=True, exist_ok=True)
        Path(ns.json).write_text(json.dumps(r, indent=1))
        print(f"wrote {ns.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
