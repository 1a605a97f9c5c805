"""Starting and stopping hmocap_ros nodes as separate processes (demo, tests, benchmarks).

There is no ``ros2 launch`` in a PyPI-wheel install, so the demo and the DDS tests start
each node with this environment's Python (needed: its bootstrapper sets LD_LIBRARY_PATH)
and stop it with SIGINT, as a terminal would.
"""

from __future__ import annotations

import logging
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

log = logging.getLogger(__name__)


#: The environment variables naming a Fast DDS XML profiles file: Fast DDS 2.x (the rmw_fastrtps_cpp
#: of ROS 2 Jazzy) reads the first, Fast DDS 3 the second.
DDS_PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")


def dds_profile(name: str = "local") -> Path:
    """The package's Fast DDS profile ``config/fastdds_<name>.xml``: ``local`` (one host: a
    shared-memory segment that holds many full-size frames, plus UDP) or ``room`` (several hosts:
    UDP with large socket buffers). FileNotFoundError when the package has no such file."""
    from hmocap_ros.config_files import find_config_file

    path = find_config_file(f"fastdds_{name}.xml")
    if path is None:
        raise FileNotFoundError(f"no Fast DDS profile config/fastdds_{name}.xml in hmocap_ros")
    return path


def dds_profile_env(base: Mapping[str, str] | None = None, name: str = "local",
                    override: bool = True) -> dict[str, str]:
    """``base`` (default: this process's environment) with the profile :func:`dds_profile` named
    in both :data:`DDS_PROFILE_VARIABLES`; with ``override=False`` a profile already named in
    ``base`` is kept."""
    env = dict(os.environ if base is None else base)
    if override or not any(env.get(v) for v in DDS_PROFILE_VARIABLES):
        path = str(dds_profile(name))
        for variable in DDS_PROFILE_VARIABLES:
            env[variable] = path
    return env


def loopback_dds_env(base: Mapping[str, str] | None = None, domain_id: int | None = None) -> dict[str, str]:
    """An environment keeping DDS on this machine: LOCALHOST discovery, a domain id and the
    one-host Fast DDS profile (``config/fastdds_local.xml``, so full-size frames pass whole).

    ``ROS_AUTOMATIC_DISCOVERY_RANGE``, ``ROS_DOMAIN_ID`` and a profiles file already set in
    ``base`` are kept, the domain unless ``domain_id`` is given.
    """
    try:
        env = dds_profile_env(base, "local", override=False)
    except FileNotFoundError as err:  # an install without config/: Fast DDS's own defaults
        log.warning("%s: full-size frames may be lost", err)
        env = dict(os.environ if base is None else base)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(domain_id)
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


class NodeProcess:
    """A node (or ``hmocap`` subcommand) running in its own process, output captured to a log file."""

    def __init__(self, name: str, argv: Sequence[str], env: Mapping[str, str], log_dir: Path):
        self.name = name
        self.log_path = Path(log_dir) / f"{name}.log"
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        self._log = self.log_path.open("w")
        self.proc = subprocess.Popen(
            list(argv), env=dict(env), stdout=self._log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL
        )

    @classmethod
    def module(cls, name: str, module: str, args: Sequence[str], env, log_dir) -> NodeProcess:
        """Run ``python -m module args`` with this interpreter."""
        return cls(name, [sys.executable, "-m", module, *args], env, log_dir)

    def output(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def wait_for_output(self, text: str, timeout: float) -> bool:
        """Wait until ``text`` appears in the process output (False on timeout or exit)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if text in self.output():
                return True
            if self.proc.poll() is not None:
                return text in self.output()
            time.sleep(0.05)
        return False

    def wait(self, timeout: float) -> int | None:
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            return None

    def __enter__(self) -> NodeProcess:
        return self

    def __exit__(self, *_exc) -> None:
        self.stop()

    def stop(self, timeout: float = 10.0) -> int:
        """SIGINT, then SIGKILL after ``timeout``; returns the exit code (idempotent)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()
        return self.proc.returncode


#: Topics that nodes publish on a timer, not per input: their traffic says nothing about a backlog.
PERIODIC_TOPICS = ("/diagnostics", "/rosout", "/parameter_events")


@dataclass(frozen=True)
class ReplayResult(Mapping):
    """What :func:`replay_through_nodes` ran and what came back.

    A mapping of the processes (stopped) by name (``result["body_tracker"].output()``), with the
    messages recorded per topic and the counts that were expected of the nodes.
    """

    procs: dict[str, NodeProcess]
    recorded: dict[str, int] = field(default_factory=dict)
    expected: dict[str, int] = field(default_factory=dict)

    @property
    def unanswered(self) -> dict[str, int]:
        """Per topic of ``expected`` that fell short, how many messages never came."""
        return {t: n - self.recorded.get(t, 0) for t, n in self.expected.items() if self.recorded.get(t, 0) < n}

    def __getitem__(self, name: str) -> NodeProcess:
        return self.procs[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self.procs)

    def __len__(self) -> int:
        return len(self.procs)


_SUMMARY_LINE = re.compile(r"^  (/\S+): (\d+) messages$", re.MULTILINE)


def _recorded(recorder: NodeProcess) -> dict[str, int]:
    """Messages recorded per topic: the stopped recorder's summary, else its last progress line."""
    counts = {topic: int(n) for topic, n in _SUMMARY_LINE.findall(recorder.output())}
    return counts or _written(recorder)


def _written(recorder: NodeProcess) -> dict[str, int]:
    """Messages recorded per topic so far, from the recorder's last ``--progress`` line."""
    lines = [ln for ln in recorder.output().splitlines() if ln.startswith("written: ")]
    counts: dict[str, int] = {}
    if lines:
        for item in lines[-1].split(": ", 2)[2].split(", "):
            topic, _, n = item.rpartition(" ")
            counts[topic] = int(n)
    return counts


def replay_through_nodes(
    bag: Path,
    nodes: Sequence[tuple[str, str, Sequence[str], str]],
    record_topics: Sequence[str],
    out_bag: Path,
    env: Mapping[str, str],
    log_dir: Path,
    replay_topics: Sequence[str] | None = None,
    replay_rate: float = 1.0,
    ready_timeout: float = 60.0,
    settle: float = 1.0,
    replay_timeout: float = 600.0,
    drain_timeout: float = 120.0,
    drain_topics: Sequence[str] | None = None,
    expect: Mapping[str, int] | None = None,
    subscribers: int = 1,
) -> ReplayResult:
    """Replay ``bag`` into ``nodes`` (separate processes over DDS) while recording ``record_topics``.

    ``nodes`` are ``(name, module, args, ready_text)``: each is started with ``python -m module
    args`` and waited for until ``ready_text`` appears in its output. The recorder starts first;
    the replay starts once the recorder has matched a publisher of every recorded topic (both
    sides of discovery: a best-effort link drops what comes before), and waits itself for
    ``subscribers`` subscribers on each replayed topic (``--wait-subscribers``, plus its
    ``--settle``): as many as the nodes that subscribe to it, so none loses the first frames.
    After the replay ends, the nodes may still be working through a backlog (a slow or loaded
    machine, or one still compiling on its first frames): they are stopped only once every
    topic of ``expect`` has at least that many messages recorded, and then nothing new has been
    recorded on ``drain_topics`` (default: the recorded topics but :data:`PERIODIC_TOPICS`) for
    ``settle`` seconds (all within ``drain_timeout`` s), then the recorder last, so it flushes
    everything. Give ``expect`` whenever the number of outputs is known: a node slower than
    ``settle`` to its first output is otherwise stopped before it answered, and the result
    counts the frames the nodes never answered (:attr:`ReplayResult.unanswered`, also logged as
    a warning).
    Returns a :class:`ReplayResult`: the processes (stopped), so callers can read their logs,
    and the messages recorded per topic.
    Raises RuntimeError, with the log of the process at fault, when something does not start.
    """
    procs: dict[str, NodeProcess] = {}
    if drain_topics is None:
        drain_topics = [t for t in record_topics if t not in PERIODIC_TOPICS]
    recorder = NodeProcess.module("record", "hmocap_ros.cli",
                                  ["record", "--out", str(out_bag), "--progress", "0.2", *record_topics],
                                  env, log_dir)
    procs["record"] = recorder
    try:
        _start_nodes(procs, nodes, env, log_dir, ready_timeout)
        # Outputs are published only once the replay feeds the nodes: make sure the recorder's
        # subscriptions have matched their publishers first (the replayed topics it records
        # match the replay once it starts, within its --settle).
        for topic in [t for t in record_topics if t not in (replay_topics or ())]:
            if not recorder.wait_for_output(f"receiving {topic} from", ready_timeout):
                raise RuntimeError(f"the recorder never matched a publisher of {topic}:\n{recorder.output()}")
        replay_args = ["replay", str(bag), "--rate", str(replay_rate), "--wait-subscribers", str(subscribers),
                       "--wait-timeout", str(ready_timeout)]
        if replay_topics:
            replay_args += ["--topics", *replay_topics]
        replay = NodeProcess.module("replay", "hmocap_ros.cli", replay_args, env, log_dir)
        procs["replay"] = replay
        if replay.wait(replay_timeout) is None:
            raise RuntimeError(f"the replay did not finish in {replay_timeout:.0f} s")
        if replay.proc.returncode != 0:
            raise RuntimeError(f"the replay failed:\n{replay.output()}")
        _drain(recorder, dict(expect or {}), drain_topics, settle, drain_timeout)
    finally:
        for name, proc in procs.items():
            if name != "record":
                proc.stop()
        recorder.stop()
    result = ReplayResult(procs, _recorded(recorder), dict(expect or {}))
    for topic, missing in result.unanswered.items():
        log.warning("replay of %s: %s has %d of %d messages: %d frames never answered",
                    Path(bag).name, topic, result.recorded.get(topic, 0), result.expected[topic], missing)
    return result


def _start_nodes(procs: dict[str, NodeProcess], nodes: Sequence[tuple[str, str, Sequence[str], str]],
                 env: Mapping[str, str], log_dir: Path, ready_timeout: float) -> None:
    """Start every node (added to ``procs``), then wait for each one's ready text."""
    for name, module, args, _ready in nodes:
        procs[name] = NodeProcess.module(name, module, list(args), env, log_dir)
    for name, _module, _args, ready in nodes:
        if not procs[name].wait_for_output(ready, ready_timeout):
            raise RuntimeError(f"{name} did not start:\n{procs[name].output()}")


def _drain(recorder: NodeProcess, expect: Mapping[str, int], drain_topics: Sequence[str],
           settle: float, drain_timeout: float) -> None:
    """Wait until the recorder has ``expect``'s counts, then until ``drain_topics`` stay quiet
    for ``settle`` seconds; ``drain_timeout`` bounds both."""
    end = time.monotonic() + drain_timeout
    while time.monotonic() < end:
        counts = _written(recorder)
        if all(counts.get(t, 0) >= n for t, n in expect.items()):
            break
        time.sleep(0.1)
    last = sum(_written(recorder).get(t, 0) for t in drain_topics)
    quiet_since = time.monotonic()
    while time.monotonic() - quiet_since < settle and time.monotonic() < end:
        time.sleep(0.1)
        count = sum(_written(recorder).get(t, 0) for t in drain_topics)
        if count != last:
            last, quiet_since = count, time.monotonic()
