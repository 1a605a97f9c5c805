"""Real processes over DDS (loopback, own domain from conftest): replay -> node -> record, and the recorder's stop."""

import os
import sys
from pathlib import Path

import numpy as np
import pytest

from hmocap_ros.demo import DEMO_BAG, DEMO_RIG, run_demo
from hmocap_ros.geometry.rig import load_rig
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.bag_writer import LATCHED, BagWriter
from hmocap_ros.io.msg_factory import RosbagsFactory, make_header, stamp_to_ns
from hmocap_ros.processes import NodeProcess, loopback_dds_env, replay_through_nodes

PUBLISHER = r"""
import sys, time, rclpy
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
rclpy.init()
node = rclpy.create_node("test_publisher")
pub = node.create_publisher(JointState, "/test_joints", QoSProfile(depth=1000))
end = time.monotonic() + 30
while pub.get_subscription_count() < 1 and time.monotonic() < end:
    time.sleep(0.05)
n = int(sys.argv[1])
for i in range(n):
    msg = JointState(name=["a", "b"], position=[float(i), -float(i)])
    msg.header.stamp.sec = i
    pub.publish(msg)
    time.sleep(0.002)
print("published", n, flush=True)
time.sleep(1.0)
node.destroy_node(); rclpy.shutdown()
"""


def test_environment_is_loopback():
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert os.environ["ROS_DOMAIN_ID"]


def test_replay_node_record_pipeline(tmp_path):
    # replay -> camera_rig_publisher -> record, three processes over DDS: one CameraInfo per
    # image, with the image's stamp and the rig's intrinsics, and the rig latched.
    rig = load_rig(DEMO_RIG)
    images = [f"/{c}/image_raw" for c in rig.names]
    out = tmp_path / "out.mcap"
    with BagReader(DEMO_BAG) as reader:
        per_camera = {c: reader.topics()[f"/{c}/image_raw"].count for c in rig.names}
    node = ("camera_rig_publisher", "hmocap_ros.nodes.camera_rig_publisher",
            ["--ros-args", "-p", f"rig_file:={DEMO_RIG}"], "serving rig")
    replay_through_nodes(DEMO_BAG, [node], ["/camera_rig", *(f"/{c}/camera_info" for c in rig.names)], out,
                         loopback_dds_env(), tmp_path / "logs", replay_topics=images, replay_rate=0.5,
                         expect={f"/{c}/camera_info": n for c, n in per_camera.items()})
    with BagReader(DEMO_BAG) as reader:
        sent = {(m.topic.split("/")[1], stamp_to_ns(m.msg.header.stamp)) for m in reader.messages(images)}
    with BagReader(out) as reader:
        infos = {(m.topic.split("/")[1], stamp_to_ns(m.msg.header.stamp)): m.msg
                 for m in reader.messages() if m.topic.endswith("camera_info")}
        rig_msg = reader.first("/camera_rig")
        assert reader.topics()["/camera_rig"].latched
    assert set(infos) == sent
    for cam in rig.cameras:
        msg = next(m for (name, _), m in infos.items() if name == cam.name)
        assert (msg.width, msg.height) == (cam.width, cam.height)
        np.testing.assert_allclose(np.asarray(msg.k).reshape(3, 3), cam.K)
    assert list(rig_msg.camera_names) == list(rig.names)


@pytest.mark.slow
def test_demo_runs_every_node_and_reports(tmp_path, capsys):
    """The demo's figures: every mask and pose answered (75 frame sets, 65 with the person),
    foreground F1, joint error and gesture hits near what the pipeline scores on the shipped
    bags (0.88, 38-42 mm, 25 of 38 with 1 false detection), far from a broken stage (an empty
    mask scores F1 0, a standing A-pose about 150 mm, a detector that finds nothing 0 of 38)."""
    import re

    assert run_demo(tmp_path) == 0
    out = capsys.readouterr().out
    assert "foreground: 75/75 masks per camera" in out and "demo: OK" in out
    f1 = float(re.search(r"F1 vs ground truth ([0-9.]+)", out).group(1))
    poses = re.search(r"body_tracker: (\d+)/(\d+) frames with a pose, mean joint error (\d+) mm", out)
    found = re.search(r"found (\d+) of (\d+) held gestures, (\d+) false detections", out)
    assert f1 > 0.85, out
    assert poses is not None and poses.group(1) == poses.group(2) == "65", out
    assert int(poses.group(3)) < 60, out
    assert found is not None and int(found.group(1)) >= 20 and int(found.group(3)) <= 3, out


@pytest.mark.parametrize("stop_signal", ["SIGINT", "SIGTERM"])
def test_recorder_loses_nothing_on_stop(tmp_path, stop_signal):
    import signal

    env = loopback_dds_env()
    out = tmp_path / "rec.mcap"
    n = 300
    with NodeProcess.module("rec", "hmocap_ros.cli", ["record", "-o", str(out), "--progress", "0.1",
                                                      "/test_joints"], env, tmp_path) as rec:
        assert rec.wait_for_output("recording to", 30), rec.output()
        with NodeProcess("pub", [sys.executable, "-c", PUBLISHER, str(n)], env, tmp_path) as pub:
            assert pub.wait_for_output("published", 60), pub.output()
            # The stop comes once the recorder has taken every message, however loaded the machine:
            # what is tested is that the stop loses none of the messages written.
            assert rec.wait_for_output(f"written: {n} messages", 60), rec.output()
            rec.proc.send_signal(getattr(signal, stop_signal))
            assert rec.wait(20) == 0, rec.output()
        assert f"closed {out}" in rec.output()
    with BagReader(out) as reader:
        msgs = [m.msg for m in reader.messages(["/test_joints"])]
    assert len(msgs) == n
    assert [m.header.stamp.sec for m in msgs] == list(range(n))
    assert list(msgs[7].position) == [7.0, -7.0]


def test_replay_rate_and_latched_topic(tmp_path):
    # 20 messages 100 ms apart in the bag, replayed at rate 2: the recorder receives them ~50 ms
    # apart. Measured on the recorder's receive times (the log times of the recorded bag), so the
    # start-up of the processes and the replay's --linger do not count.
    rate, n, spacing_ns = 2.0, 20, 100_000_000
    factory = RosbagsFactory()
    src = tmp_path / "src.mcap"
    with BagWriter(src) as bag:
        bag.add_topic("/latched_text", "std_msgs/msg/String", LATCHED)
        bag.write("/latched_text", factory.make("std_msgs/msg/String", data="calibration"), 0)
        for i in range(n):
            msg = factory.make("sensor_msgs/msg/JointState", header=make_header(factory, i, "room"),
                               name=["j"], position=np.array([i], float), velocity=np.zeros(0),
                               effort=np.zeros(0))
            bag.write("/joints", msg, spacing_ns * i)
    env = loopback_dds_env()
    out = tmp_path / "out.mcap"
    # the pace is measured on the recorder's clock: logged at receive time
    with NodeProcess.module("rec", "hmocap_ros.cli", ["record", "--out", str(out), "--log-time", "receive",
                                                      "--progress", "0.1", "/joints", "/latched_text"],
                            env, tmp_path) as rec:
        assert rec.wait_for_output("recording to", 30)
        with NodeProcess.module("play", "hmocap_ros.cli",
                                ["replay", str(src), "--rate", str(rate), "--wait-subscribers", "1"],
                                env, tmp_path) as play:
            assert play.wait(60) == 0, play.output()
        assert rec.wait_for_output(f"/joints {n}", 30), rec.output()
    with BagReader(out) as reader:
        topics = reader.topics()
        received = [(m.msg.position[0], m.log_time_ns) for m in reader.messages(["/joints"])]
        assert reader.first("/latched_text").data == "calibration"
    assert topics["/latched_text"].latched
    assert [value for value, _ in received] == list(range(n))
    gaps = np.diff([t for _, t in received]) / (spacing_ns / rate)  # 1 = the bag's spacing at this rate
    # The whole stream within +-40 % of its length at rate 2 (rate 1 would take 2x, no pacing ~0);
    # single gaps vary with scheduling, their median keeps the pace.
    assert 0.6 < gaps.sum() / (n - 1) < 1.4, gaps
    assert 0.5 < np.median(gaps) < 1.5, gaps


def test_replay_publishes_the_stored_bytes_unchanged_and_reports_its_timing(tmp_path):
    """Full-size rgb8 frames (640x480, random pixels) and a latched topic replayed into the
    recorder: every message arrives, byte for byte the bag's serialized message (the replay
    decodes nothing), and the replay prints its timing line with the bag's span."""
    from hmocap_ros.eval.pipeline_stats import replay_timing

    factory = RosbagsFactory()
    rng = np.random.default_rng(7)
    src = tmp_path / "src.mcap"
    n, period_ns = 12, 40_000_000
    with BagWriter(src) as bag:
        bag.add_topic("/latched_text", "std_msgs/msg/String", LATCHED)
        bag.write("/latched_text", factory.make("std_msgs/msg/String", data="calibration"), 0)
        for i in range(n):
            msg = factory.make("sensor_msgs/msg/Image", header=make_header(factory, i * period_ns, "cam_1"),
                               height=480, width=640, encoding="rgb8", is_bigendian=0, step=1920,
                               data=rng.integers(0, 256, 480 * 1920, dtype=np.uint8))
            bag.write("/cam_1/image_raw", msg, i * period_ns)
    env = loopback_dds_env()
    out = tmp_path / "out.mcap"
    with NodeProcess.module("rec", "hmocap_ros.cli", ["record", "-o", str(out), "--progress", "0.1",
                                                      "/cam_1/image_raw", "/latched_text"], env, tmp_path) as rec:
        assert rec.wait_for_output("recording to", 30)
        with NodeProcess.module("play", "hmocap_ros.cli", ["replay", str(src), "--wait-subscribers", "1"],
                                env, tmp_path) as play:
            assert play.wait(60) == 0, play.output()
            timing = replay_timing(play.output())
        assert rec.wait_for_output(f"/cam_1/image_raw {n}", 30), rec.output()
    with BagReader(src) as reader:
        sent = {m.topic: [] for m in reader.messages(raw=True)}
        for m in reader.messages(raw=True):
            sent[m.topic].append(bytes(m.msg))
    with BagReader(out) as reader:
        got = {t: [bytes(m.msg) for m in reader.messages([t], raw=True)] for t in sent}
    assert got["/cam_1/image_raw"] == sent["/cam_1/image_raw"]  # all n, in order, unchanged
    assert got["/latched_text"] == sent["/latched_text"]
    assert timing["replay_bag_seconds"] == pytest.approx((n - 1) * period_ns * 1e-9, abs=1e-3)
    # first to last publication: the span, give or take how late a message went out
    assert abs(timing["replay_seconds"] - timing["replay_bag_seconds"]) <= timing["replay_behind_max_s"] + 1e-3
    assert timing["replay_behind_max_s"] >= timing["replay_behind_p95_s"] >= -1e-3


def _console_scripts() -> list[str]:
    import re

    setup_py = (Path(__file__).resolve().parents[1] / "setup.py").read_text()
    return re.findall(r'^\s*"(\w+) = hmocap_ros[\w.]*:main",', setup_py, re.M)


@pytest.mark.parametrize("script", _console_scripts())
def test_console_scripts_answer_help(script):
    import subprocess

    exe = Path(sys.executable).parent / script
    assert exe.exists(), f"{exe} is not installed: make setup installs the package's executables"
    res = subprocess.run([str(exe), "--help"], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert "usage" in res.stdout.lower()


def test_invalid_parameter_is_one_clear_line_and_exit_code_2(tmp_path, free_domain_id):
    import subprocess

    exe = Path(sys.executable).parent / "body_tracker"
    assert exe.exists(), f"{exe} is not installed: make setup installs the package's executables"
    res = subprocess.run([str(exe), "--ros-args", "-p", "method:=annealing", "-p",
                          f"rig_file:={DEMO_RIG}"], capture_output=True, text=True, timeout=60,
                         env=loopback_dds_env(domain_id=free_domain_id))
    assert res.returncode == 2
    assert "method must be one of" in res.stderr + res.stdout
    assert "Traceback" not in res.stderr


def test_a_node_names_a_parameter_it_does_not_have(free_domain_id):
    """An outdated flat name of a grouped setting is reported with the names it may mean."""
    import signal
    import subprocess
    import time

    exe = Path(sys.executable).parent / "body_tracker"
    assert exe.exists(), f"{exe} is not installed: make setup installs the package's executables"
    proc = subprocess.Popen([str(exe), "--ros-args", "-p", "working_width:=160", "-p",
                             f"rig_file:={DEMO_RIG}"], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True,
                            env=loopback_dds_env(domain_id=free_domain_id))
    lines = []
    deadline = time.monotonic() + 60
    try:
        for line in proc.stdout:
            lines.append(line)
            if "unknown parameter" in line or time.monotonic() > deadline:
                break
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)
    text = "".join(lines)
    assert "unknown parameter 'working_width' ignored" in text, text
    assert "weighting.working_width" in text and "startup.working_width" in text


def test_every_hmocap_subcommand_answers_help(capsys):
    from hmocap_ros.cli import COMMAND_GROUPS, main

    commands = [["record"], ["replay"], ["demo"], ["info"], ["bench"]]
    for group, (_, _, kinds) in COMMAND_GROUPS.items():
        commands += [[group]] + [[group, kind] for kind in kinds]
    assert {"sim", "eval", "train"} <= {c[0] for c in commands}
    for argv in commands:
        with pytest.raises(SystemExit) as exit_info:
            main([*argv, "--help"])
        assert exit_info.value.code == 0, argv
        assert f"usage: hmocap {' '.join(argv)}" in capsys.readouterr().out, argv


def test_demo_bag_is_shipped():
    assert DEMO_BAG.is_file() and DEMO_RIG.is_file()


CLOCK_LISTENER = r"""
import json, sys, time, rclpy
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
n, last_ns = int(sys.argv[1]), int(sys.argv[2])
rclpy.init()
node = rclpy.create_node("clock_listener", parameter_overrides=[Parameter("use_sim_time", value=True)])
clocks, joints = [], []
node.create_subscription(Clock, "/clock", lambda m: clocks.append(m.clock.sec * 10**9 + m.clock.nanosec),
                         QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT))
node.create_subscription(JointState, "/joints",
                         lambda m: joints.append([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec,
                                                  node.get_clock().now().nanoseconds]), QoSProfile(depth=100))
print("listening", flush=True)
end = time.monotonic() + 60
while (len(joints) < n or not clocks or clocks[-1] != last_ns) and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.05)
print("RESULT " + json.dumps({"clocks": clocks, "joints": joints}), flush=True)
"""


def test_replay_publishes_clock_from_the_bag_stamps(tmp_path):
    """``hmocap replay --clock 50``: /clock runs on the bag's time line (from its first to its
    last stamp, never back, at about 50 Hz of replay time) and a node with use_sim_time reads
    each frame's stamp as its time when the frame arrives."""
    import json

    n, spacing_ns, first_ns = 12, 100_000_000, 5_000_000_000
    factory = RosbagsFactory()
    src = tmp_path / "src.mcap"
    with BagWriter(src) as bag:
        for i in range(n):
            stamp = first_ns + spacing_ns * i
            msg = factory.make("sensor_msgs/msg/JointState", header=make_header(factory, stamp, "room"),
                               name=["j"], position=np.array([i], float), velocity=np.zeros(0), effort=np.zeros(0))
            bag.write("/joints", msg, stamp)
    last_ns = first_ns + spacing_ns * (n - 1)
    env = loopback_dds_env()
    with NodeProcess("listener", [sys.executable, "-c", CLOCK_LISTENER, str(n), str(last_ns)], env, tmp_path) as lis:
        assert lis.wait_for_output("listening", 60), lis.output()
        with NodeProcess.module("play", "hmocap_ros.cli", ["replay", str(src), "--clock", "50",
                                                           "--wait-subscribers", "1"], env, tmp_path) as play:
            assert play.wait(60) == 0, play.output()
            assert "/clock at 50 Hz" in play.output(), play.output()
        assert lis.wait_for_output("RESULT", 70), lis.output()
    result = json.loads(lis.output().split("RESULT ", 1)[1].splitlines()[0])
    clocks, joints = np.array(result["clocks"]), np.array(result["joints"])
    assert len(joints) == n, lis.output()
    assert clocks.min() >= first_ns and clocks[-1] == last_ns
    assert np.all(np.diff(clocks) >= 0)
    # 1.1 s of replay at 50 Hz: about 55 ticks (best effort on loopback loses few)
    assert 25 <= len(clocks) <= 120, len(clocks)
    stamps, sim_now = joints[:, 0], joints[:, 1]
    assert np.all(np.abs(sim_now - stamps) < spacing_ns), (sim_now - stamps) / 1e6  # within a frame


def test_replay_clock_refuses_a_bad_frequency_and_a_bag_with_clock(tmp_path, capsys):
    from hmocap_ros import cli

    factory = RosbagsFactory()
    src = tmp_path / "clock.mcap"
    with BagWriter(src) as bag:
        bag.write("/clock", factory.make("rosgraph_msgs/msg/Clock"), 1)
    assert cli.main(["replay", str(src), "--clock", "0"]) == 2
    assert "--clock must be a positive frequency" in capsys.readouterr().err
    assert cli.main(["replay", str(src), "--clock"]) == 2
    err = capsys.readouterr().err
    assert "holds a /clock topic" in err and len(err.strip().splitlines()) == 1
