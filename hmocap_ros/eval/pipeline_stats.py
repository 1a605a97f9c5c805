"""Figures of a live pipeline run: what went in, what came out, how late, how accurate.

Plain functions over what a monitor saw on the topics (receive times and header stamps), used
by ``benchmarks/bench_pipeline.py`` (``hmocap bench pipeline``). No rclpy here.

Definitions:

- **latency** of an output: the time it was received minus the time the input with the same
  header stamp was received (the last camera of a frame set, or the depth frame), both on
  the monitor's clock; so it spans the nodes' queues, their processing and two DDS hops.
- **output rate**: outputs per second of input stream time while there is something to
  output (the frame sets with a person, for the body tracker).
- **CPU**: a process's user + system CPU seconds over the run, divided by the run's wall
  seconds (1.0 is one core kept busy); per frame set: its CPU milliseconds over the frame
  sets it answered (:func:`core_ms_per_set`).
- **replay timing**: what ``hmocap replay`` says of its own pace (:func:`replay_timing`).
"""

from __future__ import annotations

import os
import struct
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from hmocap_ros.eval.metrics import match_joints, mpjpe


def header_stamp_ns(cdr: bytes) -> int:
    """The ``header.stamp`` (ns) of a serialized message whose first field is a std_msgs/Header
    (4 bytes of CDR encapsulation, then ``int32 sec``, ``uint32 nanosec``)."""
    little = cdr[1] == 1
    sec, nanosec = struct.unpack_from("<iI" if little else ">iI", cdr, 4)
    return sec * 1_000_000_000 + nanosec


def latency_ms(inputs: Mapping[int, float], outputs: Mapping[int, float]) -> np.ndarray:
    """Per output whose stamp was an input's, receive time minus the input's (ms)."""
    return np.array([(t - inputs[s]) * 1e3 for s, t in outputs.items() if s in inputs], dtype=float)


def latency_summary(values: np.ndarray) -> dict:
    """p50, p95 and max (ms) of ``values``; NaN when there are none."""
    if values.size == 0:
        return {"latency_p50_ms": float("nan"), "latency_p95_ms": float("nan"), "latency_max_ms": float("nan")}
    return {"latency_p50_ms": float(np.percentile(values, 50)),
            "latency_p95_ms": float(np.percentile(values, 95)),
            "latency_max_ms": float(values.max())}


def stream_seconds(stamps: Sequence[int], period_s: float) -> float:
    """Stream time (s) covered by frames at ``stamps``: their count times the frame period."""
    return len(stamps) * period_s


def frame_period_s(stamps: Sequence[int]) -> float:
    """The median spacing (s) of sorted ``stamps``."""
    s = np.sort(np.asarray(stamps, dtype=np.int64))
    return float(np.median(np.diff(s))) * 1e-9 if len(s) > 1 else float("nan")


def pose_errors(estimates: Mapping[int, tuple[Sequence[str], np.ndarray]],
                truth: Mapping[int, tuple[Sequence[str], np.ndarray]]) -> dict[int, float]:
    """MPJPE (mm) per stamp of ``estimates`` that has ``truth``; both map a stamp to
    (joint names, (J, 3) positions in metres) and are matched by joint name."""
    out = {}
    for stamp, (names, est) in estimates.items():
        if stamp in truth:
            gt_names, gt = truth[stamp]
            i, j = match_joints(names, gt_names)
            out[stamp] = float(mpjpe(np.asarray(est)[i], np.asarray(gt)[j]))
    return out


def process_cpu_seconds(pid: int) -> float | None:
    """User + system CPU seconds of process ``pid`` and its waited-for children (None when
    it is gone); from /proc/PID/stat."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    ticks = os.sysconf("SC_CLK_TCK")
    return sum(int(fields[k]) for k in (11, 12, 13, 14)) / ticks  # utime stime cutime cstime


def process_rss_mb(pid: int) -> float | None:
    """Resident set size (MB) of process ``pid`` (None when it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def core_ms_per_set(cpu_s: Mapping[str, float], answered: Mapping[str, int], sets_in: int) -> dict:
    """Per node of ``cpu_s`` (CPU seconds), CPU ms per frame set it answered (``answered``:
    outputs per node; NaN for none) and per frame set that came in (``sets_in``)."""
    return {n: {"core_ms_per_set": 1e3 * c / answered[n] if answered.get(n) else float("nan"),
                "core_ms_per_input_set": 1e3 * c / sets_in if sets_in else float("nan")}
            for n, c in cpu_s.items()}


def replay_timing(output: str) -> dict:
    """The figures of ``hmocap replay``'s timing line (``replay timing: bag_s=... wall_s=...
    behind_max_s=... behind_p95_s=... cpu_s=...``), NaN when it printed none."""
    keys = {"bag_s": "replay_bag_seconds", "wall_s": "replay_seconds",
            "behind_max_s": "replay_behind_max_s", "behind_p95_s": "replay_behind_p95_s",
            "cpu_s": "replay_cpu_seconds"}
    out = {v: float("nan") for v in keys.values()}
    for line in output.splitlines():
        if line.startswith("replay timing:"):
            for item in line.split(":", 1)[1].split():
                key, _, value = item.partition("=")
                if key in keys:
                    out[keys[key]] = float(value)
    return out
