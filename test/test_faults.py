"""Faults of a running room (marked ``faults``; ``make test-faults``): nodes and the recorder
killed mid-stream, a camera that stops and comes back, stamps that jump back, and a long soak.

- Each node killed with SIGKILL while the shipped bags are replayed in a loop (``hmocap replay
  --loop``, whose stamps go back at every pass) and started again: the other nodes keep
  running, and the killed node's outputs, and those downstream of it, resume.
- The recorder killed with SIGKILL while it records the pipeline's outputs: the bag reads and
  holds what was written a flush period before (``test_record_crash`` checks the recorder alone).
- A camera that stops for a while and comes back: body_tracker keeps publishing on the sets of
  the other views (the camera listed as dropped) and takes the camera again when it is back.
- Stamps that jump back in a bag: body_tracker starts its frame sets and tracks over with a
  warning and answers every frame set after the jump.
- The soak: the whole pipeline replayed in a loop for ``HMOCAP_SOAK_MINUTES`` (default 30), the
  resident memory (VmRSS) of each node sampled every ``HMOCAP_SOAK_SAMPLE_S`` seconds (default
  10) into a JSON series (``HMOCAP_SOAK_JSON``, default ``out/soak_rss.json``); it fails when a
  node's memory after the warm-up (``HMOCAP_SOAK_WARMUP_MINUTES``, default a third of the run,
  at most 5) grows by more than ``HMOCAP_SOAK_MAX_GROWTH_MB`` (default 5 MB).
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hmocap_ros.demo import DEMO_BAG, DEMO_RIG, GESTURE_BAG
from hmocap_ros.eval.pipeline_stats import process_rss_mb
from hmocap_ros.io import topics as bag_topics
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.bag_writer import BagWriter
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.processes import NodeProcess, _written, loopback_dds_env, replay_through_nodes

pytestmark = pytest.mark.faults

CAMERAS = ["cam_1", "cam_2", "cam_3", "cam_4"]
FAST = ["-p", "filter.particles:=120", "-p", "filter.layers:=0", "-p", "startup.particles:=60",
        "-p", "startup.frames:=2"]
EVERY_FRAME = ["-p", "latest_only:=false", "-p", "queue_depth:=100"]
BODY_0 = "/humans/bodies/b0"
#: the recorder flushes at least once a second; a loaded machine adds scheduling delay
LOSS_BOUND_S = 1.5
START_S = 120.0

#: the pipeline: name -> (module, arguments, text printed when ready, output topic)
PIPELINE = {
    "foreground_segmentation": ("hmocap_ros.nodes.foreground_segmentation",
                                ["-p", f"cameras:=[{','.join(CAMERAS)}]", "-p", "learn_frames:=8",
                                                   "-p", "latest_only:=false",
                                 "-p", "min_blob_area:=20", "-p", "max_hole_area:=60"],
                                "segmenting", "/cam_1/foreground"),
    "extremity_detection": ("hmocap_ros.nodes.extremity_detection", ["-p", "queue_depth:=25"],
                            "waiting for the rig", "/extremities"),
    "body_tracker": ("hmocap_ros.nodes.body_tracker", ["-p", "method:=kf-hpf", *FAST],
                     "waiting for the rig", "/humans/bodies/tracked"),
    "gesture_detection": ("hmocap_ros.nodes.gesture_detection", ["-p", "publish_probability:=false",
                                                                 "-p", "latest_only:=false"],
                          "detecting gestures", "/gestures"),
}
RECORDED = [PIPELINE[n][3] for n in PIPELINE] + [f"{BODY_0}/joint_states"]


def _start(name: str, env, log_dir: Path, suffix: str = "") -> NodeProcess:
    module, args, _, _ = PIPELINE[name]
    return NodeProcess.module(name + suffix, module, ["--ros-args", *args], env, log_dir)


def _wait_count(recorder: NodeProcess, topic: str, n: int, timeout: float = START_S) -> int:
    """Wait until the recorder has written ``n`` messages of ``topic``; returns the count."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        count = _written(recorder).get(topic, 0)
        if count >= n:
            return count
        time.sleep(0.1)
    return _written(recorder).get(topic, 0)


class Room:
    """The pipeline of :data:`PIPELINE`, the shipped bags replayed in a loop, and a recorder."""

    def __init__(self, tmp_path: Path, nodes=tuple(PIPELINE), record=tuple(RECORDED), rate: float = 0.5):
        self.env = loopback_dds_env()
        self.logs = tmp_path / "logs"
        self.out = tmp_path / "room.mcap"
        self.procs: dict[str, NodeProcess] = {}
        self.recorder = NodeProcess.module("record", "hmocap_ros.cli",
                                           ["record", "-o", str(self.out), "--progress", "0.2", *record],
                                           self.env, self.logs)
        for name in nodes:
            self.procs[name] = _start(name, self.env, self.logs)
        for name in nodes:
            assert self.procs[name].wait_for_output(PIPELINE[name][2], START_S), self.procs[name].output()
        for topic in record:
            assert self.recorder.wait_for_output(f"receiving {topic} from", START_S), self.recorder.output()
        self.replays = []
        if "foreground_segmentation" in nodes:
            self.replays.append(self._replay("replay_mocap", DEMO_BAG, rate,
                                             ["/camera_rig", *(f"/{c}/image_raw" for c in CAMERAS)]))
        if "gesture_detection" in nodes:
            self.replays.append(self._replay("replay_gestures", GESTURE_BAG, rate,
                                             [bag_topics.DEPTH_IMAGE, bag_topics.DEPTH_INFO]))

    def _replay(self, name: str, bag: Path, rate: float, replayed: list) -> NodeProcess:
        return NodeProcess.module(name, "hmocap_ros.cli",
                                  ["replay", str(bag), "--loop", "--rate", str(rate), "--topics", *replayed,
                                   "--wait-subscribers", "1", "--wait-timeout", str(START_S)],
                                  self.env, self.logs)

    def count(self, topic: str) -> int:
        return _written(self.recorder).get(topic, 0)

    def all_running(self) -> dict[str, int | None]:
        return {name: p.proc.poll() for name, p in self.procs.items()}

    def stop(self) -> None:
        for proc in [*self.replays, *self.procs.values()]:
            proc.stop()
        self.recorder.stop()


@pytest.fixture
def room(tmp_path):
    room = Room(tmp_path)
    yield room
    room.stop()


def _grows(room: Room, topics: list, by: int, timeout: float = START_S) -> dict:
    """Wait until each of ``topics`` has ``by`` more messages than now; the counts reached."""
    start = {t: room.count(t) for t in topics}
    for topic in topics:
        _wait_count(room.recorder, topic, start[topic] + by, timeout)
    return {t: room.count(t) - start[t] for t in topics}


def test_each_node_killed_and_restarted_resumes_while_the_others_run(room):
    # every output flows before the faults
    grown = _grows(room, RECORDED, 3)
    assert all(n >= 3 for n in grown.values()), (grown, room.recorder.output())
    downstream = {"foreground_segmentation": ["/extremities", "/humans/bodies/tracked"],
                  "extremity_detection": ["/humans/bodies/tracked"],
                  "body_tracker": [], "gesture_detection": []}
    for k, name in enumerate(PIPELINE):
        room.procs[name].proc.send_signal(signal.SIGKILL)
        assert room.procs[name].wait(30) == -signal.SIGKILL
        others = {n: code for n, code in room.all_running().items() if n != name}
        assert all(code is None for code in others.values()), (name, others)
        # the rest keeps running: the gestures flow while a mocap node is down, and back
        if name != "gesture_detection":
            assert _grows(room, ["/gestures"], 2)["/gestures"] >= 2, name
        room.procs[name] = _start(name, room.env, room.logs, f"_{k}")
        assert room.procs[name].wait_for_output(PIPELINE[name][2], START_S), room.procs[name].output()
        output = PIPELINE[name][3]
        grown = _grows(room, [output, *downstream[name]], 3)
        assert all(n >= 3 for n in grown.values()), (name, grown, room.procs[name].output())
    for name, proc in room.procs.items():
        assert "Traceback" not in proc.output(), (name, proc.output())
    # the loop's stamps go back at every pass: the trackers start over and keep answering
    assert "the stamps went back" in room.procs["body_tracker"].output()


def test_killed_recorder_keeps_what_it_wrote_from_the_pipeline(tmp_path):
    room = Room(tmp_path, nodes=("gesture_detection",), record=("/gestures",), rate=1.0)
    try:
        _wait_count(room.recorder, "/gestures", 20)
        before = room.count("/gestures")
        time.sleep(LOSS_BOUND_S)
        room.recorder.proc.send_signal(signal.SIGKILL)
        assert room.recorder.wait(30) == -signal.SIGKILL
        assert room.procs["gesture_detection"].proc.poll() is None  # the node does not care
    finally:
        room.stop()
    with BagReader(room.out) as reader:
        gestures = [stamp_to_ns(m.msg.header.stamp) for m in reader.messages(["/gestures"])]
    assert len(gestures) >= before >= 20, (len(gestures), before)
    from hmocap_ros.cli import main as hmocap

    assert hmocap(["repair", str(room.out)]) == 0 and hmocap(["info", str(room.out)]) == 0


def _silhouette_bag(path: Path, drop: dict | None = None, jump_after: int | None = None,
                    jump_ns: int = 0) -> list[int]:
    """The demo bag's ground-truth silhouettes (as ``/<camera>/foreground``) in a new bag; the
    frames of ``drop`` (camera -> frame indices) left out; with ``jump_after``, the frames are
    written again after frame ``jump_after`` with their stamps moved by ``-jump_ns``. Returns the
    stamps in the order written."""
    with BagReader(DEMO_BAG) as reader:
        frames: dict[int, dict] = {}
        for m in reader.messages([f"/ground_truth/{c}/silhouette" for c in CAMERAS]):
            frames.setdefault(stamp_to_ns(m.msg.header.stamp), {})[m.topic.split("/")[2]] = m.msg
    stamps = sorted(frames)
    passes = [(stamps, 0)] if jump_after is None else [(stamps[:jump_after + 1], 0), (stamps, jump_ns)]
    written = []
    with BagWriter(path) as bag:
        log_ns = stamps[0] + 1_000_000_000 * 1000  # log times keep going forward
        for part, shift in passes:
            for k, stamp in enumerate(part):
                for cam in CAMERAS:
                    if drop and k in drop.get(cam, ()) and shift == 0:
                        continue
                    msg = frames[stamp][cam]
                    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp - shift, 1_000_000_000)
                    bag.write(f"/{cam}/foreground", msg, log_ns, "sensor_msgs/msg/Image")
                written.append(stamp - shift)
                log_ns += 40_000_000
    return written


def _tracker(args: list) -> tuple:
    return ("body_tracker", "hmocap_ros.nodes.body_tracker",
            ["--ros-args", "-p", f"rig_file:={DEMO_RIG}", "-p", "method:=hpf-apo", *EVERY_FRAME,
             "-p", "max_wait_ms:=150.0", *FAST, *args], "kernels ready")


def _diagnostics(out: Path) -> dict[int, dict]:
    with BagReader(out) as reader:
        return {stamp_to_ns(m.msg.header.stamp): {kv.key: kv.value for kv in m.msg.status[0].values}
                for m in reader.messages(["/diagnostics"])}


def test_a_camera_that_stops_and_comes_back(tmp_path):
    gap = range(12, 20)
    bag = tmp_path / "gap.mcap"
    stamps = _silhouette_bag(bag, drop={"cam_4": gap})
    out = tmp_path / "out.mcap"
    result = replay_through_nodes(bag, [_tracker([])], ["/diagnostics", f"{BODY_0}/joint_states"], out,
                                  loopback_dds_env(), tmp_path / "logs", replay_rate=0.5, settle=2.0,
                                  expect={"/diagnostics": len(stamps)})
    log = result["body_tracker"].output()
    assert "Traceback" not in log, log
    diags = _diagnostics(out)
    assert set(diags) == set(stamps), (len(diags), len(stamps))
    for k, stamp in enumerate(stamps):
        assert diags[stamp]["dropped"] == ("cam_4" if k in gap else ""), (k, diags[stamp])
    # tracked on three views in the gap, and on four again after it
    assert {diags[stamps[k]]["state"] for k in gap} == {"tracking"}
    assert diags[stamps[-1]]["state"] == "tracking" and diags[stamps[-1]]["views"] == " ".join(CAMERAS)


def test_stamps_jumping_back_start_the_tracker_over(tmp_path):
    bag = tmp_path / "jump.mcap"
    stamps = _silhouette_bag(bag, jump_after=14, jump_ns=10_000_000_000)
    out = tmp_path / "out.mcap"
    result = replay_through_nodes(bag, [_tracker([])], ["/diagnostics", f"{BODY_0}/joint_states"], out,
                                  loopback_dds_env(), tmp_path / "logs", replay_rate=0.5, settle=2.0,
                                  expect={"/diagnostics": len(stamps)})
    log = result["body_tracker"].output()
    assert "Traceback" not in log, log
    assert "the stamps went back by 10.56 s" in log, log  # 10 s and the 14 frame periods before
    diags = _diagnostics(out)
    after = stamps[15:]
    assert set(after) <= set(diags), sorted(set(after) - set(diags))
    with BagReader(out) as reader:
        posed = {stamp_to_ns(m.msg.header.stamp) for m in reader.messages([f"{BODY_0}/joint_states"])}
    assert len(posed & set(after)) >= 15  # the person is tracked again after the jump


def test_soak_memory_stays_flat(tmp_path):
    minutes = float(os.environ.get("HMOCAP_SOAK_MINUTES", "30"))
    period = float(os.environ.get("HMOCAP_SOAK_SAMPLE_S", "10"))
    warm_up = float(os.environ.get("HMOCAP_SOAK_WARMUP_MINUTES", min(5.0, minutes / 3)))
    max_growth_mb = float(os.environ.get("HMOCAP_SOAK_MAX_GROWTH_MB", "5"))
    path = Path(os.environ.get("HMOCAP_SOAK_JSON", "out/soak_rss.json"))
    room = Room(tmp_path, rate=1.0)
    series = {"minutes": minutes, "sample_s": period, "warm_up_minutes": warm_up, "t_s": [],
              "rss_mb": {name: [] for name in room.procs}, "recorded": []}
    try:
        t0 = time.monotonic()
        while time.monotonic() - t0 < minutes * 60:
            series["t_s"].append(round(time.monotonic() - t0, 1))
            for name, proc in room.procs.items():
                mb = process_rss_mb(proc.proc.pid)
                series["rss_mb"][name].append(None if mb is None else round(mb, 2))
            series["recorded"].append({t: room.count(t) for t in RECORDED})
            assert all(code is None for code in room.all_running().values()), room.all_running()
            time.sleep(period)
        logs = {name: proc.output() for name, proc in room.procs.items()}
    finally:
        room.stop()
    t = np.array(series["t_s"])
    after = t >= warm_up * 60
    series["growth_mb"] = {}
    for name, values in series["rss_mb"].items():
        v = np.array(values, float)[after]
        n = max(1, min(3, len(v) // 3))
        series["growth_mb"][name] = round(float(v[-n:].mean() - v[:n].mean()), 2) if len(v) else None
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(series, indent=1) + "\n")
    print(json.dumps({"growth_mb": series["growth_mb"], "json": str(path)}), file=sys.stderr)
    for name, log in logs.items():
        assert "Traceback" not in log, (name, log[-3000:])
    first, last = series["recorded"][0], series["recorded"][-1]
    assert all(last[topic] > first[topic] for topic in RECORDED), (first, last)  # outputs kept coming
    assert all(g is not None and g <= max_growth_mb for g in series["growth_mb"].values()), series["growth_mb"]
