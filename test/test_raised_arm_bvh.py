"""tools/raised_arm_bvh.py: the tuning clips with a hand held up."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hmocap_ros.sim.bvh import forward_kinematics, load_bvh, parse_bvh

ROOT = Path(__file__).resolve().parents[1]

TINY = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT LeftArm
  {
    OFFSET 1 0 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    JOINT LeftForeArm
    {
      OFFSET 1 0 0
      CHANNELS 3 Zrotation Yrotation Xrotation
      End Site
      {
        OFFSET 1 0 0
      }
    }
  }
}
MOTION
Frames: 5
Frame Time: 0.5
0 0 0 0 0 0 0 0 0 0 0 0
1 0 0 0 0 0 1 1 1 1 1 1
2 0 0 0 0 0 2 2 2 2 2 2
3 0 0 0 0 0 3 3 3 3 3 3
4 0 0 0 0 0 4 4 4 4 4 4
"""


@pytest.fixture
def tool(load_tool):
    return load_tool("raised_arm_bvh")


def test_posed_clip_cuts_the_window_and_poses_the_arm(tool):
    out = parse_bvh(tool.posed_clip(TINY, (80, 0, 0), (5, 6, 7), window=(1.0, 2.0)))
    # frame 0 (the T-pose) first, then the frames from 1.0 s to 2.0 s (2 and 3)
    np.testing.assert_array_equal(out.motion[:, 0], [0, 2, 3])
    np.testing.assert_array_equal(out.motion[1:, 6:9], [[80, 0, 0]] * 2)
    np.testing.assert_array_equal(out.motion[1:, 9:12], [[5, 6, 7]] * 2)
    np.testing.assert_array_equal(out.motion[0], 0)  # the T-pose untouched
    with pytest.raises(ValueError, match="outside the clip"):
        tool.posed_clip(TINY, (0, 0, 0), (0, 0, 0), window=(1.0, 9.0))


@pytest.mark.parametrize("clip, above, beside", [
    ("13_29_left_arm_up", (0.25, 0.45), (0.2, 0.35)),
    ("13_29_left_hand_over_head", (0.1, 0.25), (0.0, 0.2)),
])
def test_shipped_clips_hold_the_hand_up(clip, above, beside):
    """The committed clips: the left hand tip over the head top by ``above`` metres and
    ``beside`` it on the floor, in every frame after the T-pose (13_29's units, 0.056444 m)."""
    bvh = load_bvh(ROOT / "tools" / "tuning_bvh" / f"{clip}.bvh")
    ends = forward_kinematics(bvh, scale=0.056444).end_sites[1:]
    names = list(bvh.end_site_names)
    head, tip = ends[:, names.index("Head_end")], ends[:, names.index("LeftHandIndex1_end")]
    up = tip[:, 1] - head[:, 1]
    side = np.linalg.norm((tip - head)[:, [0, 2]], axis=1)
    assert above[0] < up.min() and up.max() < above[1]
    assert beside[0] <= side.min() and side.max() < beside[1]
