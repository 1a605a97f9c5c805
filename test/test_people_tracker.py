"""Several people (``PeopleTracker``): one body tracker per person, never two on one person.

Synthetic scenes as in ``test_body_tracking``: exact silhouettes of the body model in the
cameras of ``config/rig_example.yaml`` at 320x240; the subject performs a CMU clip, a
bystander stands elsewhere in the room.
"""
from __future__ import annotations

import numpy as np
import pytest
from test_body_tracking import SMALL as SMALL_BUDGET
from test_body_tracking import STAMP0, clip_poses, render_masks, subject_shape

from hmocap_ros.params import from_flat
from hmocap_ros.tracking.body_tracker import BodyTracker, TrackerParams
from hmocap_ros.tracking.people_tracker import PeopleTracker, body_ids

#: the tracker tests' small budget, with the hierarchical filter
SMALL = from_flat(TrackerParams, {**SMALL_BUDGET, "method": "hpf"})


@pytest.fixture(scope="module")
def scene(model, rig):
    """(masks of subject and bystander together (F, M, H, W), subject's joints (F, J, 3),
    bystander's pelvis (3,), masks of the subject alone)."""
    shape = subject_shape()
    params = clip_poses(model, 60, 5, shape, position=(-0.4, 0.3), heading=-1.0)
    subject, joints = render_masks(model, rig, params, shape)
    bystander = model.rest_pose(None).copy()
    bystander[model.skeleton.translation_dofs[[0, 2]]] = [1.0, -0.8]  # seen whole by 3 views
    other, other_joints = render_masks(model, rig, bystander[None])
    return np.maximum(subject, other[0][None]), joints, other_joints[0, 0], subject


def _run(tracker, masks, frames):
    return [tracker.update(list(masks[f]), STAMP0 + f * 40_000_000) for f in frames]


def test_body_ids():
    assert body_ids("b0", 3) == ("b0", "b1", "b2")
    assert body_ids("body_7", 2) == ("body_7", "body_8")
    assert body_ids("alice", 2) == ("alice", "alice_1")


def test_two_people_get_a_track_each_and_never_share_one(model, rig, scene):
    masks, joints, bystander, _ = scene
    people = PeopleTracker(model, rig, SMALL, np.random.default_rng(0),
                           max_people=2)
    for results in _run(people, masks, range(3)):
        assert len(results) == 2
    assert all(r.state == "tracking" for r in results)
    # one slot on each person, whoever the rig saw best first
    pelvis = [r.joints[0] for r in results]
    near_bystander = [np.linalg.norm((p - bystander)[[0, 2]]) < 0.2 for p in pelvis]
    assert sorted(near_bystander) == [False, True], pelvis
    subject = results[near_bystander.index(False)]
    assert np.linalg.norm(subject.joints - joints[2], axis=1).mean() < 0.08
    # the second slot drifts onto the first one's person, a little off: it fits worse, so it
    # is the one reset, and it starts again on the person nobody follows
    a, b = people.trackers
    b.estimate = a.estimate.copy()
    b.estimate[0] += 0.05
    b.particles = a.particles.copy()
    b.particles[:, 0] += 0.05
    b._previous_estimate = None
    people.update(list(masks[3]), STAMP0 + 3 * 40_000_000)
    assert a.state == "tracking" and b.state == "searching"
    results = people.update(list(masks[4]), STAMP0 + 4 * 40_000_000)
    assert b.state != "searching"
    assert np.linalg.norm((results[0].joints[0] - results[1].joints[0])[[0, 2]]) > 1.0


def test_one_slot_is_the_single_person_tracker_bit_for_bit(model, rig, scene):
    masks = scene[0]
    single = BodyTracker(model, rig, SMALL, np.random.default_rng(3))
    people = PeopleTracker(model, rig, SMALL, np.random.default_rng(3), max_people=2)
    for f in range(2):
        a = single.update(list(masks[f]), STAMP0 + f)
        b = people.update(list(masks[f]), STAMP0 + f)[0]
        assert a.state == b.state
        np.testing.assert_array_equal(a.joints, b.joints)


def test_a_second_slot_waits_while_only_one_person_is_there(model, rig, scene):
    subject_only = scene[3]
    people = PeopleTracker(model, rig, SMALL, np.random.default_rng(0),
                           max_people=2, ids=("user", "guest"))
    results = _run(people, subject_only, range(3))[-1]
    assert [r.state for r in results] == ["tracking", "searching"]
    assert not results[1].has_pose
    assert people.ids == ("user", "guest")
    with pytest.raises(ValueError, match="distinct"):
        PeopleTracker(model, rig, SMALL, max_people=2, ids=("a", "a"))
