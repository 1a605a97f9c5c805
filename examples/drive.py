"""Drive the example apps from a bag: the bag replayed through the nodes and the app, each its own
process over DDS on loopback (as ``make demo`` runs the pipeline), watched by a monitor.

- :func:`drive_light_switch`: a depth bag (``scenes.gesture_scene``) through ``gesture_detection``
  and ``light_switch``;
- :func:`drive_presence`: a bag of body_tracker's outputs (``scenes.walk_scene``) straight into
  ``presence``.

The monitor (:mod:`hmocap_examples.monitor`) subscribes to every replayed topic and to the
outputs, and notes when DDS says each message was published. The replay starts once each
replayed topic has two subscribers (the node that reads it and the monitor). An app's reaction
time (:func:`reaction_ms`, :func:`light_reactions`) is the publication time of its output
minus that of the room's output it reacted to: the DDS hop to the app and its work, on this
machine's one clock.

    .venv/bin/python benchmarks/bench_apps.py     # prints the figures over a few runs
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.io.typestore import hmocap_typestore
from hmocap_ros.processes import NodeProcess

__all__ = ["AppRun", "Noted", "drive_light_switch", "drive_presence", "light_reactions", "reaction_ms"]

DEPTH_TOPICS = {"/tf_static": "tf2_msgs/msg/TFMessage", "/depth/image_raw": "sensor_msgs/msg/Image",
                "/depth/camera_info": "sensor_msgs/msg/CameraInfo"}
BODY_TOPICS = {"/tf_static": "tf2_msgs/msg/TFMessage", "/skeleton": "hmocap_interfaces/msg/Skeleton",
               "/humans/bodies/tracked": "hri_msgs/msg/IdsList"}
LATCHED = ["/tf_static", "/light", "/presence"]


@dataclass(frozen=True)
class Noted:
    """One message as the monitor saw it: published at ``source_ns``, arrived at ``received_ns``."""

    source_ns: int
    received_ns: int
    # a deserialised message of the topic's type (rosbags' message classes carry no static types)
    msg: Any


@dataclass(frozen=True)
class AppRun:
    """What a drive saw: ``messages[topic]`` in arrival order, and the processes' logs by name."""

    messages: Mapping[str, list]
    logs: Mapping[str, str]


def _read_monitor(path: Path, types: Mapping[str, str]) -> dict[str, list]:
    store = hmocap_typestore()
    out: dict[str, list] = {t: [] for t in types}
    for line in path.read_text().splitlines():
        item = json.loads(line)
        msg = store.deserialize_cdr(bytes.fromhex(item["cdr"]), types[item["topic"]])
        out[item["topic"]].append(Noted(item["source_ns"], item["received_ns"], msg))
    return out


def _count(path: Path) -> dict[str, int]:
    counts: dict[str, int] = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.endswith("}"):
                topic = json.loads(line)["topic"]
                counts[topic] = counts.get(topic, 0) + 1
    return counts


def _run(bag: Path, nodes, replayed: Mapping[str, str], outputs: Mapping[str, str], out: Path, env,
         expect: Mapping[str, int], timeout: float = 120.0, settle: float = 1.0) -> AppRun:
    """Start ``nodes`` (name, module, args, ready text) and the monitor, replay ``replayed``
    topics of ``bag``, wait for ``expect`` messages per output topic (and ``settle`` s of quiet),
    stop everything."""
    out.mkdir(parents=True, exist_ok=True)
    noted = out / "monitor.jsonl"
    types = {**replayed, **outputs}
    procs: dict[str, NodeProcess] = {}
    try:
        procs["monitor"] = NodeProcess.module(
            "monitor", "hmocap_examples.monitor",
            [str(noted), *(f"{t}:{k}" for t, k in types.items()), "--latched", *(t for t in types if t in LATCHED),
             "--ready", *outputs], env, out / "logs")
        for name, module, args, _ready in nodes:
            procs[name] = NodeProcess.module(name, module, list(args), env, out / "logs")
        for name, _module, _args, ready in [*nodes, ("monitor", "", (), "monitor: matched")]:
            if not procs[name].wait_for_output(ready, timeout):
                raise RuntimeError(f"{name} did not start:\n{procs[name].output()}")
        procs["replay"] = replay = NodeProcess.module(
            "replay", "hmocap_ros.cli", ["replay", str(bag), "--topics", *replayed, "--wait-subscribers", "2",
                                         "--wait-timeout", str(timeout)], env, out / "logs")
        if replay.wait(timeout) is None or replay.proc.returncode != 0:
            raise RuntimeError(f"the replay failed:\n{replay.output()}")
        end = time.monotonic() + timeout
        while time.monotonic() < end and any(_count(noted).get(t, 0) < n for t, n in expect.items()):
            time.sleep(0.1)
        time.sleep(settle)
    finally:
        for name in [n for n in procs if n != "monitor"] + ["monitor"] * ("monitor" in procs):
            procs[name].stop()
    return AppRun(_read_monitor(noted, types), {name: proc.output() for name, proc in procs.items()})


def _ros_args(params: Sequence[str]) -> list[str]:
    return ["--ros-args", *(a for p in params for a in ("-p", p))] if params else []


def drive_light_switch(bag: Path, out: Path, env: Mapping[str, str], params: Sequence[str] = (),
                       toggles: int = 1) -> AppRun:
    """Replay the depth bag ``bag`` through gesture_detection and light_switch (its ``-p``
    ``params``); wait for ``toggles`` toggles of the light besides its initial state."""
    nodes = [("gesture_detection", "hmocap_ros.nodes.gesture_detection", [], "detecting gestures"),
             ("light_switch", "hmocap_examples.light_switch", _ros_args(params), "toggles it")]
    outputs = {"/gestures": "hmocap_interfaces/msg/GestureArray", "/light": "std_msgs/msg/Bool"}
    return _run(bag, nodes, DEPTH_TOPICS, outputs, out, env, {"/light": 1 + toggles})


def drive_presence(bag: Path, out: Path, env: Mapping[str, str], params: Sequence[str] = (),
                   changes: int = 1) -> AppRun:
    """Replay the tracker-output bag ``bag`` into presence (its ``-p`` ``params``); wait for
    ``changes`` presence messages besides the initial one."""
    nodes = [("presence", "hmocap_examples.presence", _ros_args(params), " zones from ")]
    outputs = {"/presence": "diagnostic_msgs/msg/DiagnosticArray"}
    return _run(bag, nodes, BODY_TOPICS, outputs, out, env, {"/presence": 1 + changes})


def reaction_ms(inputs: Sequence[Noted], outputs: Sequence[Noted]) -> list[tuple[int, float]]:
    """``(stamp, ms)`` per output of ``outputs`` (stamped messages): its publication time minus
    the first publication of an input of ``inputs`` with the same ``header.stamp``; outputs whose
    stamp no input has are left out."""
    first: dict[int, int] = {}
    for n in sorted(inputs, key=lambda n: n.source_ns):
        first.setdefault(stamp_to_ns(n.msg.header), n.source_ns)
    return [(stamp, (n.source_ns - first[stamp]) / 1e6) for n in outputs
            if (stamp := stamp_to_ns(n.msg.header)) in first]


def light_reactions(run: AppRun, gestures: Sequence[str] = ("pause",)) -> list[tuple[int, float]]:
    """``(stamp, ms)`` per toggle of the light (each ``/light`` message after the initial
    state): the stamp of the last ``/gestures`` message with one of ``gestures`` published
    before the toggle, the message it toggled on, and the time between the two publications.
    When the app answers within a frame period this is the message it toggled on; a slower app
    shows as a later stamp than the hold's first detection."""
    triggers = [(n.source_ns, stamp_to_ns(n.msg.header)) for n in run.messages["/gestures"]
                if any(g.name in gestures for g in n.msg.gestures)]
    out = []
    for toggle in run.messages["/light"][1:]:
        before = [t for t in triggers if t[0] <= toggle.source_ns]
        if before:
            out.append((before[-1][1], (toggle.source_ns - before[-1][0]) / 1e6))
    return out
