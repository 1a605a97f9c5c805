"""The one-euro smoothing of the keypoints (hmocap_ros.detection.keypoint_smoothing): a still
keypoint loses a third of its jitter (MediaPipe's settings), a moving one follows with little lag, and a keypoint that was
missing for longer than the gap, or a stamp that goes back, starts its filter over."""
from __future__ import annotations

import numpy as np

from hmocap_ros.detection.keypoint_smoothing import KeypointSmoother


def test_still_keypoints_lose_their_jitter_and_moving_ones_follow():
    rng = np.random.default_rng(4)
    smoother = KeypointSmoother(("a", "b"))
    period = 40_000_000  # 25 fps
    still, moving = [], []
    for k in range(75):
        t = k * period * 1e-9
        truth = np.array([[0.0, 0.0, 1.0], [1.5 * t, 0.0, 1.0]])  # b walks at 1.5 m/s
        seen = truth + rng.normal(0.0, 0.01, (2, 3))  # 1 cm jitter
        out = smoother.filter(("a", "b"), seen, k * period)
        if k >= 10:
            still.append(np.linalg.norm(out[0] - truth[0]))
            moving.append(np.linalg.norm(out[1] - truth[1]))
    jitter = 0.01 * np.sqrt(3) * 0.92  # mean norm of the raw 3D jitter
    assert np.mean(still) < 0.75 * jitter, np.mean(still)  # MediaPipe's settings: about 0.63
    assert np.mean(moving) < 1.5 * jitter, np.mean(moving)  # a 6 cm step per frame: little lag


def test_a_gap_or_a_stamp_going_back_starts_the_filter_over():
    smoother = KeypointSmoother(("a",))
    here, there = np.array([[0.0, 0.0, 0.0]]), np.array([[0.5, 0.0, 0.0]])
    smoother.filter(("a",), here, 0)
    np.testing.assert_allclose(smoother.filter(("a",), there, 2_000_000_000), there)  # 2 s later
    smoother.filter(("a",), here, 2_040_000_000)
    np.testing.assert_allclose(smoother.filter(("a",), there, 1_000_000_000), there)  # back in time
    assert smoother.filter((), np.zeros((0, 3)), 3_000_000_000).shape == (0, 3)
    smoother.reset()
    np.testing.assert_allclose(smoother.filter(("a",), here, 3_000_000_000), here)
