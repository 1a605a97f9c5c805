"""``hmocap info``, ``replay --loop`` and ``record --all`` / ``--duration`` on small bags made here.

The DDS tests run real processes on loopback in the run's own domain (``conftest.py``); they
wait on what the processes print, never on the wall clock.
"""

import re

import numpy as np

from hmocap_ros.cli import main
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.bag_writer import LATCHED, BagWriter
from hmocap_ros.io.msg_factory import RosbagsFactory, make_header
from hmocap_ros.processes import NodeProcess, loopback_dds_env


def _write_bag(path, n: int = 3, spacing_ns: int = 50_000_000) -> None:
    """``/joints`` (JointState, position [i]) ``n`` times, ``/text`` (String) once, ``/rig_text`` latched."""
    factory = RosbagsFactory()
    with BagWriter(path) as bag:
        bag.add_topic("/rig_text", "std_msgs/msg/String", LATCHED)
        bag.write("/rig_text", factory.make("std_msgs/msg/String", data="rig"), 0)
        for i in range(n):
            msg = factory.make("sensor_msgs/msg/JointState", header=make_header(factory, i, "room"),
                               name=["j"], position=np.array([i], float), velocity=np.zeros(0),
                               effort=np.zeros(0))
            bag.write("/joints", msg, spacing_ns * i)
        bag.write("/text", factory.make("std_msgs/msg/String", data="hello"), spacing_ns * n)


def _count(recorder: NodeProcess, topic: str) -> int:
    """Messages of ``topic`` written so far, from the recorder's last ``--progress`` line."""
    lines = [ln for ln in recorder.output().splitlines() if ln.startswith("written: ")]
    found = re.search(rf"(?:: |, ){re.escape(topic)} (\d+)", lines[-1]) if lines else None
    return int(found.group(1)) if found else 0


def _wait_for_count(recorder: NodeProcess, topic: str, n: int, timeout: float = 60.0) -> bool:
    import time

    end = time.monotonic() + timeout
    while time.monotonic() < end and recorder.proc.poll() is None:
        if _count(recorder, topic) >= n:
            return True
        time.sleep(0.05)
    return _count(recorder, topic) >= n


def test_info_lists_topics_types_and_counts(tmp_path, capsys):
    bag = tmp_path / "small.mcap"
    _write_bag(bag, n=4)
    assert main(["info", str(bag)]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0] == f"{bag}: 6 messages, 0.20 s"
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines()[1:]}
    assert rows == {"/joints": ["sensor_msgs/msg/JointState", "4"],
                    "/rig_text": ["std_msgs/msg/String", "1", "latched"],
                    "/text": ["std_msgs/msg/String", "1"]}


def test_replay_loop_publishes_the_bag_again(tmp_path):
    src = tmp_path / "src.mcap"
    _write_bag(src, n=3)
    out = tmp_path / "out.mcap"
    env = loopback_dds_env()
    # each pass repeats the bag's stamps: logged at receive time, the passes stay apart in the bag
    with NodeProcess.module("rec", "hmocap_ros.cli", ["record", "--out", str(out), "--log-time", "receive",
                                                      "--progress", "0.1", "/joints"], env, tmp_path) as rec:
        assert rec.wait_for_output("recording to", 30), rec.output()
        with NodeProcess.module("play", "hmocap_ros.cli",
                                ["replay", str(src), "--loop", "--rate", "2", "--topics", "/joints",
                                 "--wait-subscribers", "1", "--wait-timeout", "60"], env, tmp_path) as play:
            assert _wait_for_count(rec, "/joints", 7), (rec.output(), play.output())
            assert play.proc.poll() is None, play.output()  # still looping
        assert rec.stop() == 0, rec.output()
    assert "(looping)" in play.output()
    with BagReader(out) as reader:
        values = [int(m.msg.position[0]) for m in reader.messages(["/joints"])]
    assert len(values) >= 7
    assert values == [k % 3 for k in range(len(values))], values


def test_record_all_takes_every_topic_but_the_graph_ones(tmp_path):
    src = tmp_path / "src.mcap"
    _write_bag(src, n=3)
    out = tmp_path / "all.mcap"
    env = loopback_dds_env()
    with NodeProcess.module("rec", "hmocap_ros.cli", ["record", "-o", str(out), "--all", "--progress", "0.1"],
                            env, tmp_path) as rec:
        assert rec.wait_for_output("recording to", 30), rec.output()
        # /text is published last: once it is written, so is everything before it.
        with NodeProcess.module("play", "hmocap_ros.cli",
                                ["replay", str(src), "--wait-subscribers", "1", "--wait-timeout", "60"],
                                env, tmp_path) as play:
            assert _wait_for_count(rec, "/text", 1), (rec.output(), play.output())
            assert play.wait(60) == 0, play.output()
        assert rec.stop() == 0, rec.output()
    with BagReader(out) as reader:
        topics = reader.topics()
        assert [m.msg.position[0] for m in reader.messages(["/joints"])] == [0, 1, 2]
    assert {"/joints", "/text", "/rig_text"} <= set(topics)
    assert topics["/rig_text"].latched and topics["/joints"].msgtype == "sensor_msgs/msg/JointState"
    assert not {"/rosout", "/parameter_events"} & set(topics)


def test_record_duration_stops_by_itself(tmp_path):
    out = tmp_path / "short.mcap"
    with NodeProcess.module("rec", "hmocap_ros.cli", ["record", "-o", str(out), "--duration", "0.5", "/nothing"],
                            loopback_dds_env(), tmp_path) as rec:
        assert rec.wait(60) == 0, rec.output()  # no signal sent: the duration ends it
    log = rec.output()
    assert "/nothing: never published" in log and f"closed {out}" in log and " on SIG" not in log
    with BagReader(out) as reader:
        assert reader.topics() == {}
