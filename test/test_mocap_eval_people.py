"""Scoring several people (``hmocap eval mocap``'s ``persons``) on synthetic arrays.

People are matched to tracked bodies per frame set by the Hungarian method on the mean joint
distance with a gate; a swap of two tracks costs each person exactly one id switch per swap.
"""

from __future__ import annotations

import numpy as np

from hmocap_ros.eval.metrics import LIMB_JOINTS, MATCH_GATE_MM, id_switches, match_people
from hmocap_ros.eval.people_scores import match_frames, score_people

NAMES = LIMB_JOINTS


def _people(rng, n_frames=20, n_people=2):
    """(P, F, J, 3) people standing 2 m apart, walking slowly."""
    base = rng.normal(0.0, 0.3, (n_people, 1, len(NAMES), 3))
    base[:, :, :, 0] += 2.0 * np.arange(n_people)[:, None, None]
    drift = np.linspace(0.0, 0.5, n_frames)[None, :, None, None] * np.array([0.0, 0.0, 1.0])
    return base + drift


def test_hungarian_matches_the_nearest_overall_and_gates():
    rng = np.random.default_rng(0)
    truth = _people(rng, 1, 3)[:, 0]  # (3, J, 3)
    tracks = truth[[2, 0]] + rng.normal(0.0, 0.01, (2, len(NAMES), 3))  # person 1 untracked
    np.testing.assert_array_equal(match_people(truth, tracks), [1, -1, 0])
    # a track 0.6 m off is outside the gate
    far = truth[[0]] + np.array([0.6, 0.0, 0.0])
    np.testing.assert_array_equal(match_people(truth, far), [-1, -1, -1])
    np.testing.assert_array_equal(match_people(truth, far, gate_mm=700.0), [0, -1, -1])
    # bodies without a pose (NaN) and people without truth are never matched
    posed = np.concatenate([np.full((1, len(NAMES), 3), np.nan), truth[[1]]])
    absent = truth.copy()
    absent[2] = np.nan
    np.testing.assert_array_equal(match_people(absent, posed), [-1, 1, -1])
    assert match_people(truth, np.zeros((0, len(NAMES), 3))).tolist() == [-1, -1, -1]


def test_hungarian_beats_greedy():
    """Greedy nearest-first would give track 0 to person 0 (0.1 m) and leave person 1 with a
    1 m track; the assignment minimising the sum gives 0.2 + 0.2 m."""
    truth = np.zeros((2, 1, 3))
    truth[1, 0, 0] = 0.3
    tracks = np.zeros((2, 1, 3))
    tracks[0, 0, 0] = 0.1
    tracks[1, 0, 0] = -0.2
    np.testing.assert_array_equal(match_people(truth, tracks, gate_mm=1500.0), [1, 0])


def test_id_switches_count_changes_of_the_matched_body():
    assert id_switches(np.array([0, 0, 0])) == 0
    assert id_switches(np.array([0, 0, 1, 1, 0])) == 2
    assert id_switches(np.array([0, -1, -1, 1])) == 1  # against the last matched body
    assert id_switches(np.array([-1, 0, -1, 0])) == 0
    assert id_switches(np.array([], dtype=int)) == 0


def test_a_swap_of_two_tracks_counts_one_switch_per_person():
    rng = np.random.default_rng(1)
    n = 20
    truth = _people(rng, n)  # (2, F, J, 3)
    noise = rng.normal(0.0, 0.02, (n, 2, len(NAMES), 3))
    estimates = truth.transpose(1, 0, 2, 3) + noise  # (F, T, J, 3): track t follows person t
    estimates[12:] = estimates[12:, ::-1]  # the tracks swap people at frame 12
    matched = match_frames(truth, estimates)
    np.testing.assert_array_equal(matched[0], [0] * 12 + [1] * 8)
    np.testing.assert_array_equal(matched[1], [1] * 12 + [0] * 8)
    persons = score_people(truth, estimates, NAMES, person_ids=("body_0", "body_1"),
                           body_ids=("b0", "b1"))
    assert [p["person_id"] for p in persons] == ["body_0", "body_1"]
    for p in persons:
        assert p["id_switches"] == 1
        assert p["frames"] == n and p["frames_with_pose"] == n
        assert p["frames_seen"] == n and p["frames_tracked"] == n and p["tracked_share"] == 1.0
        assert 15.0 < p["mean_mm"] < 45.0  # 3D noise of 20 mm per axis: ~32 mm
        assert abs(p["limb_joints_mm"] - p["mean_mm"]) < 1e-9  # every joint is a limb joint
        assert p["body_frames"] == {"b0": 12, "b1": 8} or p["body_frames"] == {"b0": 8, "b1": 12}
    # swapping back costs one more each
    estimates[16:] = estimates[16:, ::-1]
    persons = score_people(truth, estimates, NAMES, person_ids=("a", "b"), body_ids=("b0", "b1"))
    assert [p["id_switches"] for p in persons] == [2, 2]


def test_unmatched_frames_and_views():
    """A person lost for some frame sets, and seen by fewer than two cameras in some."""
    rng = np.random.default_rng(2)
    n = 10
    truth = _people(rng, n)
    estimates = truth.transpose(1, 0, 2, 3).copy()
    estimates[:4, 1] = np.nan  # person 1 not tracked in the first 4 frame sets
    estimates[4:6, 1] += np.array([1.0, 0.0, 0.0])  # then 1 m off (beyond the gate) for 2
    truth[1, 8:] = np.nan  # and leaves the room for the last 2
    views = np.full((2, n), 4)
    views[1, :2] = 1  # seen by one camera only at first
    persons = score_people(truth, estimates, NAMES, person_ids=("a", "b"), body_ids=("b0", "b1"),
                           views=views)
    a, b = persons
    assert a["frames_tracked"] == a["frames_seen"] == n and a["id_switches"] == 0
    assert a["mean_mm"] == 0.0
    assert b["frames"] == 8 and b["frames_with_pose"] == 2
    assert b["frames_seen"] == 6 and b["frames_tracked"] == 2
    assert abs(b["tracked_share"] - 2 / 6) < 1e-12
    assert b["seen_by"] == ">= 2 cameras" and a["body_frames"] == {"b0": n}
    assert b["per_frame_mm"][:6] == [None] * 6
    assert MATCH_GATE_MM < 1000.0
