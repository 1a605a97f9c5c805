"""A room of three hosts: one pipeline split over network namespaces, full-size frames across them.

The test builds its own room inside this machine: three network namespaces (the hosts
``camera``, ``segmenter`` and ``tracker``) on one private /24, joined by a bridge in the camera
host and a veth pair to each of the others (MTU 1500, as an Ethernet), so nothing leaves the
machine. Every process runs as a node of a real room would (docs/network.md): DDS discovery
``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` (multicast on the room's subnet), one domain, and
the multi-host Fast DDS profile ``config/fastdds_room.xml`` (UDP only, 4 MiB socket buffers):

- ``camera``: a camera publishing 640x480 rgb8 frames at 10 Hz (reliable, as most drivers), which
  counts the masks that come back from ``segmenter``;
- ``segmenter``: ``foreground_segmentation`` (frames in from ``camera``, masks out to both);
- ``tracker``: ``camera_rig_publisher`` answering every frame of ``camera`` with its CameraInfo,
  and ``hmocap record`` of the masks and the CameraInfo messages.

Checked: every frame crossed to both hosts and every answer came back (masks at the camera and
at the recorder, one CameraInfo per frame, with the frames' stamps).

Needs root and iproute2 (``ip netns``); skipped with the reason elsewhere. The namespaces have
names of their own per run and are deleted however the test ends. Part of the default suite
(about 20 s), marked ``multihost`` to run alone (``make test-multihost``) or leave out
(``-m "not multihost"``).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from hmocap_ros.config_files import find_config_file
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.processes import NodeProcess, dds_profile_env

pytestmark = pytest.mark.multihost

CAMERA = str(Path(__file__).resolve().parent / "fixtures" / "full_size_camera.py")
HOSTS = ("camera", "segmenter", "tracker")
FRAMES = 20


def _ip(*args: str) -> None:
    out = subprocess.run(["ip", *args], check=False, capture_output=True, text=True, timeout=30)
    if out.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {out.stderr.strip()}")


class Room:
    """Network namespaces ``hm<tag>_<host>`` on 10.77.<n>.0/24: the camera host .1 on a bridge,
    the others .2, .3 behind veth pairs. :meth:`delete` removes them (and their links)."""

    def __init__(self):
        self.tag = uuid.uuid4().hex[:6]
        self.subnet = f"10.77.{int(self.tag, 16) % 250 + 1}"
        self.namespaces: dict[str, str] = {}
        self.addresses: dict[str, str] = {}

    def create(self) -> None:
        for i, host in enumerate(HOSTS, start=1):
            ns = f"hm{self.tag}_{host}"
            _ip("netns", "add", ns)
            self.namespaces[host] = ns
            self.addresses[host] = f"{self.subnet}.{i}"
            _ip("-n", ns, "link", "set", "lo", "up")
        hub = self.namespaces["camera"]
        bridge = f"hb{self.tag}"
        _ip("-n", hub, "link", "add", bridge, "type", "bridge")
        _ip("-n", hub, "addr", "add", f"{self.addresses['camera']}/24", "dev", bridge)
        _ip("-n", hub, "link", "set", bridge, "up")
        _ip("-n", hub, "route", "add", "224.0.0.0/4", "dev", bridge)
        for host in HOSTS[1:]:
            near, far = f"h{self.tag}{host[0]}0", f"h{self.tag}{host[0]}1"
            ns = self.namespaces[host]
            _ip("-n", hub, "link", "add", near, "mtu", "1500", "type", "veth", "peer", "name", far, "netns", ns)
            _ip("-n", hub, "link", "set", near, "master", bridge)
            _ip("-n", hub, "link", "set", near, "up")
            _ip("-n", ns, "addr", "add", f"{self.addresses[host]}/24", "dev", far)
            _ip("-n", ns, "link", "set", far, "up")
            _ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", far)

    def delete(self) -> None:
        for ns in self.namespaces.values():
            subprocess.run(["ip", "netns", "del", ns], check=False, capture_output=True, timeout=30)
        self.namespaces.clear()

    def command(self, host: str, argv: list[str]) -> list[str]:
        return ["ip", "netns", "exec", self.namespaces[host], *argv]

    def received_bytes(self, host: str) -> int:
        """Bytes the host's network interface (not its loopback) has received."""
        out = subprocess.run(["ip", "-n", self.namespaces[host], "-s", "-j", "link", "show",
                              f"h{self.tag}{host[0]}1"], check=True, capture_output=True, text=True, timeout=30)
        return int(json.loads(out.stdout)[0]["stats64"]["rx"]["bytes"])


@pytest.fixture
def room():
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        pytest.skip("network namespaces need root (ip netns add): run as root, or on each host of a real room")
    if shutil.which("ip") is None:
        pytest.skip("no `ip` command (iproute2) to make network namespaces")
    room = Room()
    try:
        try:
            room.create()
        except (RuntimeError, OSError, subprocess.TimeoutExpired) as err:
            pytest.skip(f"cannot make network namespaces here: {err}")
        yield room
    finally:
        room.delete()
    leftover = subprocess.run(["ip", "netns", "list"], check=False, capture_output=True, text=True).stdout
    assert f"hm{room.tag}_" not in leftover


def room_env() -> dict[str, str]:
    """The environment of a node in the room: SUBNET discovery, the room profile, the run's domain."""
    env = dds_profile_env(name="room")
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
    env["PYTHONUNBUFFERED"] = "1"
    return env


def test_full_size_frames_cross_hosts_and_every_answer_comes_back(room, tmp_path):
    env = room_env()
    rig = find_config_file("rig_example.yaml")
    python = sys.executable
    out = tmp_path / "tracker.mcap"
    procs: list[NodeProcess] = []

    def start(name: str, host: str, argv: list[str]) -> NodeProcess:
        proc = NodeProcess(name, room.command(host, argv), env, tmp_path)
        procs.append(proc)
        return proc

    before = {host: room.received_bytes(host) for host in HOSTS[1:]}
    try:
        segmenter = start("foreground_segmentation", "segmenter",
                          [python, "-m", "hmocap_ros.nodes.foreground_segmentation", "--ros-args",
                           "-p", "cameras:=[cam_1]", "-p", "learn_frames:=5", "-p", "latest_only:=false"])
        rig_node = start("camera_rig_publisher", "tracker",
                         [python, "-m", "hmocap_ros.nodes.camera_rig_publisher", "--ros-args",
                          "-p", f"rig_file:={rig}", "-p", "cameras:=[cam_1]"])
        recorder = start("record", "tracker",
                         [python, "-m", "hmocap_ros.cli", "record", "-o", str(out), "--progress", "0.5",
                          "/cam_1/foreground", "/cam_1/camera_info"])
        for proc, ready in ((segmenter, "segmenting"), (rig_node, "serving rig")):
            assert proc.wait_for_output(ready, 120), proc.output()
        for topic in ("/cam_1/foreground", "/cam_1/camera_info"):
            assert recorder.wait_for_output(f"receiving {topic} from", 60), recorder.output()
        camera = start("camera", "camera",
                       [python, CAMERA, "/cam_1/image_raw", "rgb8", "10", str(FRAMES), "reliable",
                        "/cam_1/foreground", "sensor_msgs/msg/Image", "best_effort",
                        "2"])  # the segmenter and the rig publisher, on two other hosts
        assert camera.wait(120) == 0, camera.output()
        # the recorder's last messages may still be on their way
        recorder.wait_for_output(f"/cam_1/camera_info {FRAMES}", 10)
        received = {host: room.received_bytes(host) - before[host] for host in HOSTS[1:]}
    finally:
        for proc in reversed(procs):
            proc.stop()
    logs = {p.name: p.output() for p in procs}
    for name, log in logs.items():
        assert "Traceback" not in log and "XMLPARSER" not in log, f"{name}:\n{log}"
    # The camera got a mask for every frame, from another host
    assert f"answered {FRAMES} of {FRAMES}" in logs["camera"], logs
    assert re.search(rf"frames segmented: cam_1 {FRAMES}\b", logs["foreground_segmentation"]), logs
    # and a third host heard every frame (CameraInfo per image) and every mask
    sent = {(1000 + i) * 10**9 for i in range(FRAMES)}
    with BagReader(out) as reader:
        stamps = {topic: {stamp_to_ns(m.msg.header.stamp) for m in reader.messages([topic])}
                  for topic in ("/cam_1/foreground", "/cam_1/camera_info")}
    assert stamps["/cam_1/camera_info"] == sent, logs["record"]
    assert stamps["/cam_1/foreground"] == sent, logs["record"]
    # over the veth links: each frame (900 KiB) to both hosts, each mask (300 KiB) to the tracker
    assert received["segmenter"] >= FRAMES * 640 * 480 * 3, received
    assert received["tracker"] >= FRAMES * 640 * 480 * 4, received
