"""The product starts without the simulator: ``import hmocap_ros``, every node module, the
``hmocap`` command and some nodes' ``--help`` run in a process where ``hmocap_sim`` cannot be
imported.

The process puts a finder first on :data:`sys.meta_path` that raises ImportError for
``hmocap_sim`` and its submodules (as if the package were not installed), then runs the code; it
starts in a temporary folder, so the checkout is not on its path either. A control runs the same
way and imports the simulator, which must fail: the hiding works. Building the ``hmocap``
parser loads no rclpy either (the front ends of commands/ import their node when they run).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NODES = sorted(p.stem for p in (ROOT / "hmocap_ros" / "nodes").glob("*.py") if p.stem != "__init__")

#: Runs first in the child: ``hmocap_sim`` is unimportable from then on.
HIDE_SIMULATOR = """
import importlib.abc, sys
class _NoSimulator(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "hmocap_sim" or name.startswith("hmocap_sim."):
            raise ImportError(f"{name} is hidden: the product must start without the simulator")
        return None
sys.meta_path.insert(0, _NoSimulator())
"""


def run_hidden(code: str, tmp_path: Path, timeout: float = 120) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter with ``hmocap_sim`` hidden, in ``tmp_path``."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run([sys.executable, "-c", HIDE_SIMULATOR + code], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=timeout)


def test_the_hiding_works(tmp_path):
    """The control: with the finder installed the simulator does not import."""
    done = run_hidden("import hmocap_sim.mocap_dataset\n", tmp_path)
    assert done.returncode != 0 and "hmocap_sim is hidden" in done.stderr, done.stderr
    done = run_hidden("import hmocap_ros.cli as c; raise SystemExit(c.main(['sim', 'mocap', '--help']))\n",
                      tmp_path)
    assert done.returncode != 0 and "hmocap_sim" in done.stderr, done.stderr


def test_the_product_and_every_node_import_without_the_simulator(tmp_path):
    assert len(NODES) >= 10
    code = ("import importlib, hmocap_ros, hmocap_ros.cli\n"
            f"for name in {NODES!r}:\n"
            "    importlib.import_module('hmocap_ros.nodes.' + name)\n"
            "assert not [m for m in sys.modules if m.split('.')[0] == 'hmocap_sim']\n"
            f"print('imported', {len(NODES)})\n")
    done = run_hidden(code, tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr
    assert f"imported {len(NODES)}" in done.stdout


@pytest.mark.parametrize("argv", [
    ["hmocap_ros.nodes.body_tracker", "--help"],
    ["hmocap_ros.nodes.gesture_detection", "--help"],
    ["hmocap_ros.nodes.camera_rig_publisher", "--help"],
])
def test_nodes_print_their_help_without_the_simulator(tmp_path, argv):
    """``python -m hmocap_ros.nodes.X --help`` (through :func:`runpy.run_module`, as ``-m`` does)."""
    code = (f"import runpy\nsys.argv = [{argv[0]!r}, *{argv[1:]!r}]\n"
            f"runpy.run_module({argv[0]!r}, run_name='__main__', alter_sys=True)\n")
    done = run_hidden(code, tmp_path)
    assert done.returncode == 0, done.stderr
    assert argv[0].rsplit(".", 1)[1] in done.stdout


def test_the_hmocap_command_without_the_simulator(tmp_path):
    """``hmocap --help`` and a product command's ``--help`` need no simulator."""
    for argv in (["--help"], ["eval", "mocap", "--help"], ["calibrate", "--help"]):
        done = run_hidden(f"import hmocap_ros.cli as c; raise SystemExit(c.main({argv!r}))\n", tmp_path)
        assert done.returncode == 0 and "usage: hmocap" in done.stdout, (argv, done.stderr)


def test_the_hmocap_parser_imports_no_rclpy(tmp_path):
    """The front ends in commands/ import their node only when they run: building the parser
    (``hmocap --help``, the record/replay/view options) loads neither rclpy nor the simulator."""
    code = ("from hmocap_ros.cli import build_parser\n"
            "build_parser([])\n"
            "build_parser(['eval', 'mocap'])\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('rclpy', 'hmocap_sim')))\n")
    done = run_hidden(code, tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]", done.stdout
