"""``tools/multiview_shadow_trial.py``: the multi-view shadow test only ever adds the person."""
from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEMO_BAG = ROOT / "hmocap_ros" / "data" / "demo" / "mocap_4cam.mcap"


def _tool():
    spec = importlib.util.spec_from_file_location("multiview_shadow_trial",
                                                  ROOT / "tools" / "multiview_shadow_trial.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
    finally:
        del sys.modules[spec.name]
    return module


def test_the_test_turns_shadow_pixels_to_foreground_only():
    tool = _tool()
    ns = argparse.Namespace(floor_lift=0.5, wall_margin=0.2, dilate=3, scale=0.25)
    out = tool.score(str(DEMO_BAG), ns)
    tp0, fp0, fn0 = out["model"]
    tp1, fp1, fn1 = out["multi-view"]
    assert tp0 + fn0 == tp1 + fn1 > 10_000          # the same subject pixels are scored
    assert tp1 > tp0 and fn1 < fn0                  # it finds subject pixels the model lost
    assert fp1 >= fp0                               # and can only add, never remove
    # with the hull's floor above the person nothing is carved and nothing changes
    ns.floor_lift = 3.0
    again = tool.score(str(DEMO_BAG), ns)
    assert (again["multi-view"] == again["model"]).all()
