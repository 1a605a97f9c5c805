"""The package builds without setuptools' warnings: every shipped data folder is a listed package
(no "Package would be ignored"), no option setuptools does not know (``tests_require``), and the
installed tree holds the data files."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_setup_py_builds_quietly_with_the_data(tmp_path):
    build = subprocess.run([sys.executable, "setup.py", "build", "--build-base", str(tmp_path / "build"),
                            "egg_info", "--egg-base", str(tmp_path)],
                           cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, build.stderr
    text = build.stdout + build.stderr
    for warning in ("would be ignored", "Unknown distribution option", "SetuptoolsDeprecationWarning",
                    "is absent from the `packages`"):
        assert warning not in text, text
    lib = tmp_path / "build" / "lib" / "hmocap_ros" / "data"
    assert (lib / "demo" / "mocap_4cam.mcap").is_file() and (lib / "bvh" / "13_26.bvh").is_file()
    assert any((lib / "models").iterdir())
