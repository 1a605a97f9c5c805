"""How the command-line tools meet the terminal: a closed pipe, Ctrl-C, --help.

- ``hmocap info BAG | head -1`` and ``body_tracker --help | head -1`` end without a traceback
  (exit status 141, as a program that SIGPIPE ended, when the pipe closed under them);
- Ctrl-C ends a command with exit status 130 and one line, and ``hmocap demo`` stopped half-way
  leaves the previous run's results whole;
- every option's default is in ``--help``; a node's ``--help`` is plain text, without the
  docstrings' reStructuredText markup.
"""
from __future__ import annotations

import argparse
import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

from hmocap_ros import cli
from hmocap_ros.demo import DEMO_BAG
from hmocap_ros.terminal import EXIT_CLOSED_PIPE, EXIT_INTERRUPTED, plain_text

ROOT = Path(__file__).resolve().parents[1]
NODES = ["body_tracker", "camera_rig_publisher", "extremity_detection", "foreground_segmentation",
         "gesture_detection", "gesture_trainer", "room_pipeline"]


def _first_line_then_close(argv: list[str]) -> tuple[str, int, str]:
    """Run ``argv`` into a pipe that is closed after its first line (as ``| head -1``)."""
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    assert proc.stdout is not None and proc.stderr is not None
    first = proc.stdout.readline().decode()
    proc.stdout.close()
    err = proc.stderr.read().decode()
    return first, proc.wait(60), err


@pytest.mark.parametrize("argv", [
    [sys.executable, "-m", "hmocap_ros.cli", "info", str(DEMO_BAG)],
    [sys.executable, "-m", "hmocap_ros.nodes.body_tracker", "--help"],
    [sys.executable, "-m", "hmocap_ros.cli", "sim", "mocap", "--help"],
])
def test_a_closed_pipe_ends_the_output_without_a_traceback(argv):
    first, status, err = _first_line_then_close(argv)
    assert first.strip() and "Traceback" not in err and "BrokenPipeError" not in err, err
    assert status in (0, EXIT_CLOSED_PIPE)


def test_a_pipe_closed_under_a_command_exits_141(monkeypatch):
    module = importlib.import_module("hmocap_ros.commands.info")

    def raise_closed(*_a, **_k):
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(module, "main_from_args", raise_closed)
    assert cli.main(["info", str(DEMO_BAG)]) == EXIT_CLOSED_PIPE


def test_ctrl_c_ends_a_command_with_130_and_one_line(monkeypatch, capsys):
    from hmocap_ros import demo

    def interrupted(*_a, **_k):
        raise KeyboardInterrupt

    monkeypatch.setattr(demo, "run_demo", interrupted)
    assert cli.main(["demo", "--out", "unused"]) == EXIT_INTERRUPTED
    err = capsys.readouterr().err
    assert err.strip() == "hmocap: interrupted"


def test_an_interrupted_demo_leaves_the_previous_results_whole(monkeypatch, tmp_path, capsys):
    from hmocap_ros import demo

    out = tmp_path / "demo"
    out.mkdir()
    (out / "body_overlay.mp4").write_bytes(b"the previous run's video")
    started = []

    def body_demo(work, env, rate=0.25):
        started.append(work)
        assert work != out and (out / "body_overlay.mp4").exists()
        (work / "body.mcap").write_bytes(b"half")
        raise KeyboardInterrupt

    monkeypatch.setattr(demo, "run_body_demo", body_demo)
    assert cli.main(["demo", "--out", str(out)]) == EXIT_INTERRUPTED
    assert started and (out / "body_overlay.mp4").read_bytes() == b"the previous run's video"
    assert not (out / "body.mcap").exists()


def test_a_finished_demo_takes_the_place_of_the_previous_one(tmp_path):
    from hmocap_ros.demo import _replace

    out, work = tmp_path / "demo", tmp_path / ".demo.partial"
    out.mkdir()
    (out / "old.txt").write_text("old")
    work.mkdir()
    (work / "new.txt").write_text("new")
    _replace(out, work)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]
    assert [p.name for p in out.iterdir()] == ["new.txt"]


def _command_parsers():
    paths = [[n] for n in cli.COMMANDS] + [[g, k] for g, (_, _, kinds) in cli.COMMAND_GROUPS.items() for k in kinds]
    for path in paths:
        parser = cli.build_parser(path)
        for part in path:
            parser = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[part]
        yield " ".join(path), parser


def test_every_option_with_a_default_shows_it_in_help():
    missing = []
    for name, parser in _command_parsers():
        formatter = parser._get_formatter()
        for action in parser._actions:
            if (action.option_strings and action.nargs != 0 and action.default not in (None, "", [])
                    and action.default is not argparse.SUPPRESS
                    and "default" not in (formatter._get_help_string(action) or "")):
                missing.append(f"{name} {action.option_strings[0]}")
    assert not missing, missing
    help_text = cli.build_parser(["replay"])._subparsers._group_actions[0].choices["replay"].format_help()
    assert "(default 10.0)" in help_text  # --wait-timeout


def test_record_writes_to_out_as_every_command_and_keeps_o():
    parser = dict(_command_parsers())["record"]
    assert parser.parse_args(["--out", "a.mcap", "/x"]).out == "a.mcap"
    assert parser.parse_args(["-o", "a.mcap", "/x"]).out == "a.mcap"
    outputs = {name for name, p in _command_parsers() for a in p._actions
               if any(o in ("--output", "-o") for o in a.option_strings) and "--out" not in a.option_strings}
    assert not outputs


@pytest.mark.parametrize("node", NODES)
def test_node_help_is_plain_text(node, capsys):
    module = importlib.import_module(f"hmocap_ros.nodes.{node}")
    assert module.main([node, "--help"]) == 0
    text = capsys.readouterr().out
    assert text.startswith(f"usage: {node}") and "parameters" in text
    assert "``" not in text and not re.search(r":(mod|class|func|meth|data|attr):`", text), text


def test_plain_text_reads_the_markup():
    assert plain_text("``a`` and :class:`~x.y.Body`, :meth:`title <a.b>`, :mod:`hmocap_ros.io`::") == \
        "a and Body, title, hmocap_ros.io:"


def test_eval_mocap_prints_its_result_on_stdout_and_its_progress_on_stderr():
    run = subprocess.run([sys.executable, "-m", "hmocap_ros.cli", "eval", "mocap", str(DEMO_BAG), "--frames", "2",
                          "--silhouettes", "gt"], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines() == [line for line in run.stdout.splitlines() if "mean joint error" in line]
    assert len(run.stdout.splitlines()) == 1 and "over 2/2 frames" in run.stdout
    assert "frame set 1/" in run.stderr and "mean joint error" not in run.stderr
