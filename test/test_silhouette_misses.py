"""``tools/silhouette_misses.py``: the split of the subject pixels the foreground misses."""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "hmocap_ros" / "data" / "demo"


@pytest.fixture(scope="module")
def tool(load_tool):
    return load_tool("silhouette_misses")


def test_misses_are_split_without_remainder(tool):
    out = tool.split_misses(DEMO / "mocap_4cam.mcap", max_frames=4)
    assert len(out) == 4
    for c in out.values():
        assert c.subject > 1000 and 0.8 < c.recall <= 1.0 and 0.5 < c.precision <= 1.0
        assert c.shadow + c.background + c.cleanup == c.missed
        assert c.shadow_by_fifth.sum() == c.shadow
        assert sum(len(r) for r in c.shadow_ratios) == c.shadow
    # the shipped scene's subject loses pixels to the shadow test (its shaded parts) ...
    assert sum(c.shadow for c in out.values()) > 0
    # ... and none without it; what the shadow test took is then found
    off = tool.split_misses(DEMO / "mocap_4cam.mcap", {"shadow_suppression": False}, max_frames=4)
    assert all(c.shadow == 0 for c in off.values())
    assert sum(c.missed for c in off.values()) < sum(c.missed for c in out.values())


def test_a_bag_without_ground_truth_is_a_clear_error(tool, capsys):
    assert tool.main([str(DEMO / "gestures_depth.mcap")]) == 2
    assert "needs /camera_rig" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        tool.main([str(DEMO / "mocap_4cam.mcap"), "-p", "no_such=1"])
