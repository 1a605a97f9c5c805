"""docs/client.md is true: every Python block on the page runs as written.

The app block (``Waver``) is made on a real rclpy node and fed a skeleton and a gesture through
its Room's own callbacks; the helpers block's ``print`` lines must print what their comments
say; the offline block reads the example bag that ``hmocap_examples.scenes`` writes, at the path
the page names (made in ``tmp_path``).
"""
from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "client.md"


def code_blocks() -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", DOC.read_text(), re.S | re.M)


def _block(marker: str) -> str:
    found = [b for b in code_blocks() if marker in b]
    assert len(found) == 1, f"one block of docs/client.md holds {marker!r}"
    return found[0]


def test_every_block_is_one_of_those_run_here():
    blocks = code_blocks()
    markers = ("class Waver(Node)", "nearest_hand(bodies", "RoomState(lost_after_ns=0)")
    assert len(blocks) == len(markers) and all(any(m in b for b in blocks) for m in markers)


def _run(source: str, cwd: Path | None = None) -> tuple[dict, str]:
    namespace: dict = {"__name__": "docs_client"}
    out = io.StringIO()
    with contextlib.redirect_stdout(out), (contextlib.chdir(cwd) if cwd else contextlib.nullcontext()):
        exec(compile(source, str(DOC), "exec"), namespace)  # noqa: S102  (the documented code, run as a user would)
    return namespace, out.getvalue()


def test_the_helpers_block_prints_what_it_says():
    source = _block("nearest_hand(bodies")
    _, printed = _run(source)
    expected = [line.split("#", 1)[1].strip() for line in source.splitlines()
                if line.startswith("print(") and "#" in line]
    assert printed.splitlines() == expected


def test_the_app_block_runs_on_a_node_with_room_bodies_and_a_gesture(capfd):
    import rclpy

    from hmocap_ros.client import Gesture
    from hmocap_ros.io.msg_factory import RosbagsFactory, make_header

    namespace, _ = _run(_block("class Waver(Node)"))
    context = rclpy.Context()
    rclpy.init(context=context, args=["waver", "--ros-args", "--log-level", "info"])
    try:
        from rclpy.node import Node

        original = Node.__init__

        def in_context(self, name, **kw):
            original(self, name, context=context, **kw)

        Node.__init__ = in_context
        try:
            waver = namespace["Waver"]()
        finally:
            Node.__init__ = original
        assert "tv" in waver.places.places
        factory = RosbagsFactory()
        names = ["pelvis", "head", "r_elbow", "r_wrist", "l_elbow", "l_wrist"]
        joints = [(0.0, 0.0, 1.0), (0.0, 0.0, 1.7), (0.2, 0.3, 1.3), (0.2, 0.6, 1.3), (-0.2, 0.0, 1.0),
                  (-0.2, 0.0, 0.8)]
        skeleton = factory.make(
            "hmocap_interfaces/msg/Skeleton", header=make_header(factory, 1_000_000_000, "world"), body_id="b0",
            joint_names=names, positions=[factory.make("geometry_msgs/msg/Point", x=x, y=y, z=z) for x, y, z in joints],
            parents=np.zeros(0, np.int32), confidence=np.zeros(0, np.float32), fit_error=float("nan"))
        waver.room._feed(waver.room.state.on_skeleton)(skeleton)
        assert set(waver.room.bodies) == {"b0"}
        waver.on_gesture(Gesture("pause", 1, 2.0, 0.1, 10.0, 20.0, 1_000_000_000, "world", np.array([0.2, 0.7, 1.3])))
        waver.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    log = capfd.readouterr().err
    assert "b0 points at the tv" in log, log
    assert "pause by b0 at" in log and "with the right hand, 0.10 m from the wrist" in log, log


def test_the_offline_block_reads_the_example_bag(tmp_path):
    from hmocap_examples.scenes import walk_scene

    source = _block("RoomState(lost_after_ns=0)")
    path = re.search(r'BagReader\("([^"]+)"\)', source).group(1)
    (tmp_path / path).parent.mkdir(parents=True)
    walk_scene(tmp_path / Path(path).parent)
    namespace, _ = _run(source, cwd=tmp_path)
    state = namespace["state"]
    assert state.stamp_ns > 0 and not state.bodies  # the walk ends with nobody tracked
