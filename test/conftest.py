"""Test-wide set-up: DDS stays on loopback, each test run gets its own ROS domain.

Set here, at import time, before any test imports rclpy, and inherited by the node
processes the DDS tests start (see notes in README "Testing").
"""

import os

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
# One BLAS thread, as hmocap_ros/__init__.py sets (test modules import numpy before it).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
# A domain of its own per pytest process, so parallel runs on one machine never cross
# (Fast DDS ports stay valid for ids up to 101 on Linux).
os.environ["ROS_DOMAIN_ID"] = str(os.environ.get("HMOCAP_TEST_DOMAIN_ID") or 1 + os.getpid() % 100)
os.environ.setdefault("PYTHONUNBUFFERED", "1")


import pytest  # noqa: E402  (after the environment above)


@pytest.fixture(scope="session")
def model():
    """The tracking body model (test modules about other models define their own ``model``)."""
    from hmocap_ros.body import load_body_model

    return load_body_model("tracking")


@pytest.fixture(scope="session")
def rig():
    """The cameras of ``config/rig_example.yaml`` at half resolution (320x240)."""
    from pathlib import Path

    from hmocap_ros.rig import Rig, load_rig

    full = load_rig(Path(__file__).resolve().parents[1] / "config" / "rig_example.yaml")
    return Rig(full.frame_id, tuple(c.scaled(0.5) for c in full))


@pytest.fixture(scope="session")
def load_tool():
    """``load_tool("name")``: the module ``tools/name.py`` (the tools are scripts, not a package)."""
    import importlib.util
    import sys
    from pathlib import Path

    tools = Path(__file__).resolve().parents[1] / "tools"

    def load(name: str):
        spec = importlib.util.spec_from_file_location(name, tools / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module  # dataclasses look their module up there
        try:
            spec.loader.exec_module(module)
        finally:
            del sys.modules[spec.name]
        return module

    return load
