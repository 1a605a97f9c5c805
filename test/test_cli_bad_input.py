"""Every ``hmocap`` command that reads bags answers bad input with a short error on stderr and a
non-zero exit status, never a traceback.

A zoo of bad files (missing, empty, a folder, random bytes, a text file, a valid bag truncated at
several offsets and one with bytes overwritten in the middle of its data) goes through ``hmocap
info``, ``eval mocap``, ``eval gestures``, ``eval consistency``, ``train gestures``, ``detect
gestures`` and ``track`` in
this process (``cli.main``;
none of them starts DDS) and through ``hmocap replay`` as subprocesses, in parallel, with the
loopback DDS settings and domain id of ``conftest.py`` inherited from the environment. Impossible
replay options (``--rate 0``, ``--rate -1``, ``--topics /nonexistent``) go the same way.

A truncated bag is a recording that did not close: a command may refuse it, or read its complete
records with a warning that names ``hmocap repair``; ``info`` always exits non-zero on it.
"""

from __future__ import annotations

import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from hmocap_ros import cli
from hmocap_ros.io.bag_writer import LATCHED, BagWriter
from hmocap_ros.io.conversions import numpy_to_image
from hmocap_ros.io.msg_factory import RosbagsFactory
from hmocap_ros.io.typestore import hmocap_typestore

#: An error longer than this many lines on stderr is a dump, not a message.
MAX_ERROR_LINES = 3
REPLAY_TIMEOUT_S = 60
UNREADABLE = "not a readable bag"
REPAIR_HINT = "hmocap repair"

#: name -> text the error must contain (besides the file's name).
BAD_FILES = {
    "missing.mcap": "does not exist",
    "empty.mcap": UNREADABLE,
    "folder": UNREADABLE,
    "random.mcap": UNREADABLE,
    "notes.txt": UNREADABLE,
    "truncated_8.mcap": UNREADABLE,
    "truncated_100.mcap": UNREADABLE,
    "truncated_half.mcap": UNREADABLE,
    "truncated_end.mcap": UNREADABLE,
    "overwritten_middle.mcap": "",
}

# (command, extra arguments (OUT: a path in the case's folder)); each takes the bag first.
IN_PROCESS_COMMANDS = {
    "info": (["info"], []),
    "eval_mocap": (["eval", "mocap"], []),
    "eval_gestures": (["eval", "gestures"], ["--json", "OUT/eval.json"]),
    "eval_consistency": (["eval", "consistency"], ["--json", "OUT/consistency.json", "--quiet"]),
    "train_gestures": (["train", "gestures"], ["--out", "OUT/forest.npz", "--quiet"]),
    "detect_gestures": (["detect", "gestures"], ["--out", "OUT/gestures.mcap", "--quiet"]),
    "track": (["track"], ["--out", "OUT/tracked.mcap", "--quiet"]),
    "render_overlay": (["render", "overlay"], ["--out", "OUT/overlay.mp4"]),
}


def _write_small_bag(path: Path) -> None:
    """Ten 16x16 RGB frames of random 3-bit pixels and a latched text topic: about 8 kB, the
    middle of it inside the zstd-compressed chunk, which overwritten bytes make undecodable."""
    rng = np.random.default_rng(0)
    factory = RosbagsFactory(hmocap_typestore())
    with BagWriter(path) as bag:
        bag.add_topic("/note", "std_msgs/msg/String", LATCHED)
        bag.write("/note", factory.make("std_msgs/msg/String", data="small bag"), 1_000)
        for i in range(10):
            stamp = 1_000_000_000 + i * 40_000_000
            img = rng.integers(0, 8, (16, 16, 3), dtype=np.uint8)
            bag.write("/cam_1/image_raw", numpy_to_image(img, "rgb8", stamp, "cam_1", factory), stamp)


@pytest.fixture(scope="module")
def zoo(tmp_path_factory) -> dict[str, Path]:
    """The valid bag (``good.mcap``) and the bad files of :data:`BAD_FILES`."""
    folder = tmp_path_factory.mktemp("zoo")
    good = folder / "good.mcap"
    _write_small_bag(good)
    data = good.read_bytes()
    files = {name: folder / name for name in BAD_FILES}
    files["empty.mcap"].write_bytes(b"")
    files["folder"].mkdir()
    files["random.mcap"].write_bytes(np.random.default_rng(1).bytes(4096))
    files["notes.txt"].write_text("camera notes\n")
    for name, size in (("8", 8), ("100", 100), ("half", len(data) // 2), ("end", len(data) - 10)):
        files[f"truncated_{name}.mcap"].write_bytes(data[:size])
    middle = len(data) // 2
    files["overwritten_middle.mcap"].write_bytes(data[:middle] + b"\xff" * 64 + data[middle + 64:])
    return {"good.mcap": good, **files}


def _problems(status: int, out: str, err: str, expected: list[str], recoverable: bool = False) -> list[str]:
    """What is wrong with a command's answer to bad input (empty when it is a short error, or,
    for a ``recoverable`` bag, a short warning naming ``hmocap repair``)."""
    problems = []
    if "Traceback" in out + err:
        problems.append("a traceback")
    if recoverable:
        expected = [text for text in expected if text != UNREADABLE]
    if status == 0 and not (recoverable and REPAIR_HINT in err):
        problems.append("exit status 0")
    lines = err.strip().splitlines()
    if not lines:
        problems.append("nothing on stderr")
    elif len(lines) > MAX_ERROR_LINES:
        problems.append(f"an error of {len(lines)} lines")
    problems += [f"no {text!r} in the error" for text in expected if text and text not in err]
    return problems


def _run_in_process(argv: list[str], capsys, caplog) -> tuple[int, str, str]:
    """``cli.main(argv)``: exit status, stdout, and stderr with the log lines (which the command
    line prints there) appended."""
    capsys.readouterr()
    caplog.clear()
    try:
        status = cli.main(argv)
    except SystemExit as exc:
        status = exc.code if isinstance(exc.code, int) else 1
    except Exception as exc:  # the failure under test: reported, not raised
        status, tail = 1, f"Traceback: {type(exc).__name__}: {exc}\n"
    else:
        tail = ""
    captured = capsys.readouterr()
    logged = "".join(f"{record.getMessage()}\n" for record in caplog.records)
    return status, captured.out, logged + captured.err + tail


@pytest.mark.parametrize("command", sorted(IN_PROCESS_COMMANDS))
@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_bag_commands_on_bad_files(zoo, tmp_path, capsys, caplog, command, name):
    words, extra = IN_PROCESS_COMMANDS[command]
    argv = [*words, str(zoo[name]), *(a.replace("OUT", str(tmp_path)) for a in extra)]
    status, out, err = _run_in_process(argv, capsys, caplog)
    expected = [name, BAD_FILES[name]] if command == "info" or BAD_FILES[name] else [name]
    if command == "info" and name == "overwritten_middle.mcap":
        expected = [name, UNREADABLE, "record at byte"]
    recoverable = name.startswith("truncated_") and command != "info"
    assert not _problems(status, out, err, expected, recoverable), (argv, status, out, err)


def test_info_on_a_valid_bag(zoo, capsys, caplog):
    status, out, err = _run_in_process(["info", str(zoo["good.mcap"])], capsys, caplog)
    assert status == 0 and not err
    assert "11 messages" in out and "/cam_1/image_raw" in out and "latched" in out


def test_info_reads_every_record(zoo, tmp_path, capsys, caplog):
    """Damage outside the messages (the bag's metadata record) is found too and named."""
    data = zoo["good.mcap"].read_bytes()
    at = data.index(b"serialized_metadata") + 100
    bag = tmp_path / "metadata_overwritten.mcap"
    bag.write_bytes(data[:at] + b"\xff" * 16 + data[at + 16:])
    status, out, err = _run_in_process(["info", str(bag)], capsys, caplog)
    assert not _problems(status, out, err, [bag.name, UNREADABLE, "metadata record"]), (status, out, err)


REPLAY_OPTIONS = {
    "rate_0": (["--rate", "0"], "--rate"),
    "rate_negative": (["--rate", "-1"], "--rate"),
    "rate_nan": (["--rate", "nan"], "--rate"),
    "topic_not_in_bag": (["--topics", "/nonexistent"], "/nonexistent"),
}


def _replay(argv: list[str]) -> tuple[int, str, str]:
    """``hmocap replay ARGV`` as a subprocess (``python -m hmocap_ros.cli``, so that PYTHONPATH
    picks the package); DDS settings come from the environment ``conftest.py`` set."""
    try:
        proc = subprocess.run([sys.executable, "-m", "hmocap_ros.cli", "replay", *argv, "--linger", "0"],
                              capture_output=True, text=True, timeout=REPLAY_TIMEOUT_S, env=os.environ.copy())
    except subprocess.TimeoutExpired as exc:
        return 124, str(exc.stdout or ""), f"timed out after {REPLAY_TIMEOUT_S} s"
    return proc.returncode, proc.stdout, proc.stderr


@pytest.fixture(scope="module")
def replays(zoo) -> dict[str, tuple[list[str], tuple[int, str, str]]]:
    """Every replay case run once, four at a time: case -> (expected texts, (status, out, err))."""
    cases = {name: ([str(zoo[name])], [name, BAD_FILES[name]]) for name in BAD_FILES}
    for case, (options, text) in REPLAY_OPTIONS.items():
        cases[case] = ([str(zoo["good.mcap"]), *options], [text])
    with ThreadPoolExecutor(max_workers=4) as pool:
        results = dict(zip(cases, pool.map(_replay, [argv for argv, _ in cases.values()]), strict=True))
    return {case: (cases[case][1], results[case]) for case in cases}


@pytest.mark.parametrize("case", sorted([*BAD_FILES, *REPLAY_OPTIONS]))
def test_replay_on_bad_input(replays, case):
    expected, (status, out, err) = replays[case]
    assert not _problems(status, out, err, expected, case.startswith("truncated_")), (case, status, out, err)


def test_record_without_topics_is_a_one_line_error(tmp_path, capsys, caplog):
    status, out, err = _run_in_process(["record", "-o", str(tmp_path / "x.mcap")], capsys, caplog)
    assert status == 2 and not _problems(status, out, err, ["name the topics to record"]), (status, out, err)
    assert not (tmp_path / "x.mcap").exists()
