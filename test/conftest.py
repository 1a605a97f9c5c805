"""Test-wide set-up: DDS stays on loopback with the package's one-host Fast DDS profile, each test
run gets its own ROS domain.

Set here, at import time, before any test imports rclpy, and inherited by the node
processes the DDS tests start (see notes in README "Testing").

Domain ids are taken with :func:`allocate_domain_id`: an id is held by an exclusive lock on
``<temp dir>/hmocap_ros_dds_domain_<id>.lock`` for the life of the pytest process, so two
pytest runs on one machine never share an id. A test that needs a domain apart from the run's
asks the ``free_domain_id`` fixture for one.
"""

import fcntl
import os
import random
import tempfile
from pathlib import Path

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
# The one-host profile (a shared-memory segment for full-size frames), by the variable of Fast DDS 2
# and of Fast DDS 3, as hmocap_ros.processes.dds_profile_env sets them.
for _var in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE"):
    os.environ[_var] = str(Path(__file__).resolve().parents[1] / "config" / "fastdds_local.xml")
# One BLAS thread, as hmocap_ros/__init__.py sets (test modules import numpy before it).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

# Fast DDS ports stay valid for domain ids up to 101 on Linux.
DOMAIN_IDS = range(1, 102)
_held_domains: dict[int, object] = {}  # id -> the open lock file (closing it releases the id)
_domain_order = random.Random(os.getpid()).sample(DOMAIN_IDS, len(DOMAIN_IDS))


def allocate_domain_id() -> int:
    """A ROS domain id no other pytest process on this machine holds, locked until this one exits."""
    for domain_id in _domain_order:
        if domain_id in _held_domains:
            continue
        lock = open(Path(tempfile.gettempdir()) / f"hmocap_ros_dds_domain_{domain_id}.lock", "w")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        _held_domains[domain_id] = lock
        return domain_id
    raise RuntimeError(f"every ROS domain id in {DOMAIN_IDS} is held by another test run")


# A domain of its own per pytest process, so parallel runs on one machine never cross.
os.environ["ROS_DOMAIN_ID"] = str(allocate_domain_id())
os.environ.setdefault("PYTHONUNBUFFERED", "1")


import pytest  # noqa: E402  (after the environment above)


@pytest.fixture
def free_domain_id() -> int:
    """A ROS domain id apart from the run's and from every other run's (held until the run ends)."""
    return allocate_domain_id()


@pytest.fixture(scope="session")
def model():
    """The tracking body model (test modules about other models define their own ``model``)."""
    from hmocap_ros.body import load_body_model

    return load_body_model("tracking")


@pytest.fixture(scope="session")
def rig():
    """The cameras of ``config/rig_example.yaml`` at half resolution (320x240)."""
    from pathlib import Path

    from hmocap_ros.geometry.rig import Rig, load_rig

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


# ----------------------------------------------------------------------------- make test-mutants
_mutant_outcomes: dict[str, str] = {}


def pytest_runtest_logreport(report) -> None:
    """Note the outcome of each ``test_mutant_is_caught[name]`` for the summary below."""
    if "test_mutant_is_caught[" not in report.nodeid:
        return
    name = report.nodeid.rsplit("[", 1)[1].rstrip("]")
    if report.when == "call" or (report.when == "setup" and not report.passed):
        if hasattr(report, "wasxfail"):
            _mutant_outcomes[name] = "survives (strict xfail)" if report.skipped else "CAUGHT, but marked xfail"
        else:
            _mutant_outcomes[name] = "caught" if report.passed else "SURVIVES"


def pytest_terminal_summary(terminalreporter) -> None:
    """After ``make test-mutants``: every mutant, its breakage, the tests that must catch it
    and whether they did (a survivor is either a strict xfail with its reason or a failure)."""
    if not _mutant_outcomes:
        return
    import test_mutants

    write = terminalreporter.write_line
    terminalreporter.section("mutants")
    for name, mutant in test_mutants.MUTANTS.items():
        if name not in _mutant_outcomes:
            continue
        breakage = " ".join((mutant.apply.__doc__ or "").strip().split("\n\n")[0].split())
        write(f"{name}: {_mutant_outcomes[name]} -- {breakage}")
        for node in mutant.catching:
            write(f"    {node}")
        if mutant.survives:
            write(f"    reason it survives: {mutant.survives}")
