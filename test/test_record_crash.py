"""A recorder killed mid-stream (SIGKILL) leaves a bag that reads, and `hmocap repair` makes whole."""

import re
import signal
import sys
import time

from hmocap_ros.cli import main as hmocap
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.summaryless_mcap import has_summary
from hmocap_ros.processes import NodeProcess, loopback_dds_env

# The recorder flushes at least once a second; a loaded machine adds scheduling delay.
LOSS_BOUND_S = 1.5

PUBLISHER = r"""
import sys, time, rclpy
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
rclpy.init()
node = rclpy.create_node("crash_publisher")
pub = node.create_publisher(JointState, "/crash_joints", QoSProfile(depth=1000))
end = time.monotonic() + 30
while pub.get_subscription_count() < 1 and time.monotonic() < end:
    time.sleep(0.05)
time.sleep(0.5)
for i in range(int(sys.argv[1])):
    msg = JointState(name=["a"], position=[float(i)])
    msg.header.stamp.sec = i
    pub.publish(msg)
    print(f"sent {i} {time.monotonic():.6f}", flush=True)
    time.sleep(float(sys.argv[2]))
time.sleep(30)
"""


def _sent_times(output: str) -> dict[int, float]:
    return {int(i): float(t) for i, t in re.findall(r"^sent (\d+) ([\d.]+)$", output, re.M)}


def _stamps(path) -> list[int]:
    with BagReader(path) as reader:
        return [m.msg.header.stamp.sec for m in reader.messages(["/crash_joints"])]


def test_killed_recorder_leaves_a_readable_bag_that_repair_makes_whole(tmp_path, capsys):
    env = loopback_dds_env()
    out = tmp_path / "crash.mcap"
    n, kill_after = 250, 150
    with NodeProcess.module("rec", "hmocap_ros.cli", ["record", "-o", str(out), "/crash_joints"], env,
                            tmp_path) as rec:
        assert rec.wait_for_output("recording to", 30), rec.output()
        with NodeProcess("pub", [sys.executable, "-c", PUBLISHER, str(n), "0.01"], env, tmp_path) as pub:
            assert pub.wait_for_output(f"sent {kill_after} ", 60), pub.output()
            rec.proc.send_signal(signal.SIGKILL)
            t_kill = time.monotonic()
            rec.wait(10)
            sent = _sent_times(pub.output())
    assert rec.proc.returncode == -signal.SIGKILL

    stamps = _stamps(out)  # BagReader reads the bag as it was left
    must_have = [i for i, t in sent.items() if t < t_kill - LOSS_BOUND_S]
    assert set(must_have) <= set(stamps), (len(must_have), len(stamps))
    assert stamps == list(range(len(stamps)))  # in order, nothing missing before the last flush

    assert hmocap(["info", str(out)]) == 0
    assert hmocap(["repair", str(out)]) == 0
    assert "repaired" in capsys.readouterr().out
    assert has_summary(out) and _stamps(out) == stamps
    assert hmocap(["repair", str(out)]) == 0
    assert "whole already" in capsys.readouterr().out

    # A second recording to the same name refuses and leaves the first one alone.
    with NodeProcess.module("rec2", "hmocap_ros.cli", ["record", "-o", str(out), "/crash_joints"], env,
                            tmp_path) as rec2:
        assert rec2.wait(30) not in (0, None), rec2.output()
        assert "exists already" in rec2.output() and "hmocap repair" in rec2.output()
    assert _stamps(out) == stamps


def test_summaryless_bag_cut_mid_record_reads_up_to_the_cut(tmp_path):
    from hmocap_ros.io.bag_writer import BagWriter
    from hmocap_ros.io.msg_factory import RosbagsFactory

    factory = RosbagsFactory()
    live = tmp_path / "live.mcap"
    bag = BagWriter(live, chunk_size=200).open()  # small chunks: one flush every few messages
    for i in range(40):
        bag.write("/text", factory.make("std_msgs/msg/String", data=f"m{i}"), i)
    data = live.read_bytes()  # as a killed recorder leaves it
    bag.close()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:-80])  # the trailer and the end of the last chunk's records gone
    with BagReader(cut) as reader:
        assert reader.summaryless is not None and "hmocap repair" in reader.repair_hint()
        got = [m.msg.data for m in reader.messages()]
    assert 0 < len(got) < 40 and got == [f"m{i}" for i in range(len(got))]
    assert hmocap(["repair", str(cut)]) == 0
    with BagReader(cut) as reader:
        assert reader.summaryless is None
        assert [m.msg.data for m in reader.messages()] == got
