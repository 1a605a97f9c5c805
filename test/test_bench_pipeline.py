"""The live pipeline benchmark: its figures from what a monitor saw, and the command line."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hmocap_ros.commands.bench import split_arguments
from hmocap_ros.eval.pipeline_stats import (
    core_ms_per_set,
    frame_period_s,
    header_stamp_ns,
    latency_ms,
    latency_summary,
    pose_errors,
    process_cpu_seconds,
    process_rss_mb,
    replay_timing,
)

ROOT = Path(__file__).resolve().parents[1]


def test_the_header_stamp_is_read_from_the_serialized_message():
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Image

    msg = Image()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1_795_000_123, 456_789_012
    msg.header.frame_id = "cam_1"
    assert header_stamp_ns(serialize_message(msg)) == 1_795_000_123 * 10**9 + 456_789_012


def test_latency_pairs_outputs_with_the_input_of_their_stamp():
    inputs = {100: 1.0, 200: 1.04, 300: 1.08}
    outputs = {100: 1.05, 300: 1.20, 999: 5.0}  # 999: no such input, not counted
    lat = latency_ms(inputs, outputs)
    np.testing.assert_allclose(np.sort(lat), [50.0, 120.0])
    s = latency_summary(lat)
    assert s["latency_max_ms"] == pytest.approx(120.0)
    assert s["latency_p50_ms"] == pytest.approx(85.0)
    assert np.isnan(latency_summary(np.array([]))["latency_p95_ms"])


def test_pose_errors_match_joints_by_name_and_frame_period_is_the_median_spacing():
    truth = {10: (["a", "b"], np.array([[0, 0, 0], [1, 0, 0]], float))}
    est = {10: (["b", "a", "extra"], np.array([[1, 0, 0.01], [0, 0, 0.03], [9, 9, 9]], float)),
           20: (["a"], np.zeros((1, 3)))}
    assert pose_errors(est, truth) == {10: pytest.approx(20.0)}
    assert frame_period_s([0, 40_000_000, 80_000_000, 200_000_000]) == pytest.approx(0.04)


def test_cpu_and_memory_of_a_process_and_of_one_that_is_gone():
    assert process_cpu_seconds(os.getpid()) > 0.0
    assert process_rss_mb(os.getpid()) > 10.0
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    assert process_cpu_seconds(proc.pid) is None and process_rss_mb(proc.pid) is None


def test_cpu_per_frame_set_and_the_replay_timing_line():
    per = core_ms_per_set({"seg": 2.0, "kp": 1.5, "idle": 0.3}, {"seg": 100, "kp": 50, "idle": 0}, 200)
    assert per["seg"] == {"core_ms_per_set": pytest.approx(20.0), "core_ms_per_input_set": pytest.approx(10.0)}
    assert per["kp"]["core_ms_per_set"] == pytest.approx(30.0)
    assert np.isnan(per["idle"]["core_ms_per_set"])  # answered nothing
    out = "replaying x.mcap: 5 topics at rate 1\nreplay timing: bag_s=20.000 wall_s=20.250 " \
          "behind_max_s=0.310 behind_p95_s=0.020 cpu_s=2.5\n  /cam_1/image_raw: 500 messages published\n"
    assert replay_timing(out) == {"replay_bag_seconds": 20.0, "replay_seconds": 20.25,
                                  "replay_behind_max_s": 0.31, "replay_behind_p95_s": 0.02,
                                  "replay_cpu_seconds": 2.5}
    assert all(np.isnan(v) for v in replay_timing("no such line").values())


def test_bench_arguments_after_the_benchmark_names_go_to_the_scripts():
    assert split_arguments(["bench", "pipeline", "x.mcap", "--json", "o.json"]) == (
        ["bench", "pipeline"], ["x.mcap", "--json", "o.json"])
    assert split_arguments(["bench", "pipeline", "tracker"]) == (["bench", "pipeline", "tracker"], [])
    assert split_arguments(["bench", "tracker", "--", "--frames", "3"]) == (["bench", "tracker"], ["--frames", "3"])
    assert split_arguments(["bench"]) == (["bench"], [])


@pytest.mark.slow
def test_the_pipeline_benchmark_runs_the_nodes_on_the_shipped_bags(tmp_path, free_domain_id):
    """The whole benchmark on the shipped 160x120 bags, replayed at a tenth of real time."""
    from hmocap_ros.demo import DEMO_BAG, GESTURE_BAG

    out = tmp_path / "pipe.json"
    run = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_pipeline.py"), str(DEMO_BAG),
                          "--depth-bag", str(GESTURE_BAG), "--rate", "0.1", "--json", str(out),
                          "--logs", str(tmp_path / "logs"), "--domain-id", str(free_domain_id),
                          *(a for kv in ("foreground_segmentation:learn_frames=8",
                                         "foreground_segmentation:min_blob_area=20",
                                         "foreground_segmentation:max_hole_area=60")
                             for a in ("--param", kv))],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    r = json.loads(out.read_text())
    assert r["frame_sets_in"] == 28 and r["frame_sets_with_person"] == 20
    assert r["poses_out"] >= 1 and r["mean_error_mm"] < 150.0
    assert r["latency_p50_ms"] > 0.0 and r["latency_p95_ms"] >= r["latency_p50_ms"]
    # bounded: newest-first nodes answer within a few processing times, not after a queue
    assert r["extremities"]["latency_max_ms"] < 5_000 and r["latency_max_ms"] < 30_000, r
    assert r["gestures"]["latency_max_ms"] < 5_000, r["gestures"]
    assert not any(r["out_of_order"].values()), r["out_of_order"]
    assert r["gestures"]["depth_frames_in"] == 72 and r["gestures"]["frames_answered"] >= 60
    assert set(r["cpu_cores"]) == {"foreground_segmentation", "extremity_detection", "body_tracker",
                                   "gesture_detection"}
    assert set(r["core_ms_per_set"]) == set(r["cpu_cores"])
    assert all(v > 0 for v in r["core_ms_per_set"].values()), r["core_ms_per_set"]
    # the replay's own timing: the shipped bag's span at a tenth of real time
    assert r["replay_bag_seconds"] > 10 and r["replay_seconds"] > 10 and r["replay_behind_max_s"] >= 0
