"""A tracked body's tf2 frames and per-joint confidence (hmocap_ros.tracking.body_frames), and
how the tracker keeps up with frame sets that come faster than it tracks them: the frame
period from the stamps, the queue that takes the newest set and counts the skipped ones, and
the motion model scaled to the time between the sets it tracked. No DDS here (see
test_body_tracker_node.py for the node)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hmocap_ros.body.anthropometry import BodyShape, apply_shape
from hmocap_ros.frame_sets import FramePeriod, FrameSetQueue
from hmocap_ros.io import tf
from hmocap_ros.tracking import body_frames as bf
from hmocap_ros.tracking.body_tracker import MAX_ELAPSED_PERIODS, VELOCITY_GAIN, BodyTracker
from hmocap_ros.tracking.params import TrackerParams

PERIOD = 40_000_000
T0 = 1_700_000_000_000_000_000


def _pose(model, seed: int) -> np.ndarray:
    """A random pose within the limits, pelvis somewhere in the room, turned by some yaw."""
    rng = np.random.default_rng(seed)
    skel = model.skeleton
    params = model.rest_pose().copy()
    angles = np.setdiff1d(np.arange(skel.n_dofs), skel.translation_dofs)
    lo, hi = np.maximum(skel.lower[angles], -1.0), np.minimum(skel.upper[angles], 1.0)
    params[angles] = lo + (hi - lo) * rng.random(angles.size)
    params[skel.translation_dofs] = [rng.uniform(-1, 1), 0.95, rng.uniform(-1, 1)]
    return params


def _chain(transforms: list) -> dict:
    """Each frame's 4x4 pose in the root frame, composed along the parents."""
    by_child = {t.child: t for t in transforms}
    poses = {}

    def pose(frame):
        if frame not in by_child:
            return np.eye(4)
        if frame not in poses:
            t = by_child[frame]
            poses[frame] = pose(t.parent) @ t.matrix
        return poses[frame]

    return {child: pose(child) for child in by_child}


def test_rotations_to_quaternions_matches_the_single_conversion():
    rotations = Rotation.random(500, random_state=1).as_matrix()
    half_turns = np.stack([Rotation.from_rotvec(np.pi * a).as_matrix() for a in np.eye(3)])
    matrices = np.concatenate([rotations, half_turns, np.eye(3)[None]])
    q = tf.rotations_to_quaternions(matrices)
    expected = np.array([tf.rotation_to_quaternion(m) for m in matrices])
    np.testing.assert_allclose(q, expected, atol=1e-12)
    assert np.all(q[:, 3] >= 0)
    with pytest.raises(ValueError, match="rows \\[1\\]"):
        tf.rotations_to_quaternions(np.stack([np.eye(3), np.diag([1.0, 1.0, -1.0])]))
    with pytest.raises(ValueError):
        tf.rotations_to_quaternions(np.eye(3))


def test_body_frames_put_every_joint_where_the_skeleton_has_it(model):
    shape = BodyShape.neutral().with_entity("legs", bone=1.05)
    rest = apply_shape(model, shape).joints
    for seed in range(3):
        params = _pose(model, seed)
        transforms = bf.joint_transforms(model, params, rest)
        _, joints = model.pose(params, shape)
        np.testing.assert_allclose(transforms[:, :3, 3], joints, atol=1e-12)
        frames = bf.body_transforms(model.joint_names, model.parents, transforms, "b0", "room")
        names = ["body_b0"] + [bf.joint_frame(n, "b0") for n in model.joint_names[1:]]
        assert [t.child for t in frames] == names
        parents = {t.child: t.parent for t in frames}
        assert parents["body_b0"] == "room"
        assert parents["waist_b0"] == parents["l_hip_b0"] == "body_b0"
        assert parents["chest_b0"] == "waist_b0"
        assert parents["l_wrist_b0"] == "l_elbow_b0" and parents["head_b0"] == "neck_b0"
        poses = _chain(frames)
        for j, name in enumerate(names):
            np.testing.assert_allclose(poses[name][:3, 3], joints[j], atol=1e-9)
            # the frame turns with its joint: REP-155 axes carried by the joint's rotation
            np.testing.assert_allclose(poses[name][:3, :3], transforms[j, :3, :3] @ bf.REP155_AXES,
                                       atol=1e-9)


def test_frame_names_are_rep155s_where_the_human_model_has_a_counterpart(model):
    """REP-155's links (ros4hri/human_description) for the joints that have one; the tracking
    skeleton's own names for the rest; every frame suffixed with the body id."""
    rep155 = {"body", "waist", "head", *(f"{s}_{j}" for s in "lr"
                                         for j in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle"))}
    names = {bf.rep155_frame_name(j) for j in model.joint_names}
    assert names & rep155 == rep155  # every REP-155 link the tracking skeleton has a joint for
    assert names - rep155 == {"chest", "neck", "l_clavicle", "r_clavicle"}
    assert bf.body_frame("b0") == "body_b0" and bf.joint_frame("pelvis", "b0") == "body_b0"
    assert bf.joint_frame("spine", "b1") == "waist_b1" and bf.joint_frame("l_wrist", "b1") == "l_wrist_b1"


def test_body_frame_axes_follow_rep155_forward_left_up(model):
    params = model.rest_pose().copy()
    skel = model.skeleton
    params[skel.dof_index("root_yaw")] = np.pi / 2  # turned to its left: faces room +X
    transforms = bf.joint_transforms(model, params, model.joints_rest)
    frames = bf.body_transforms(model.joint_names, model.parents, transforms, "b", "room")
    body = _chain(frames)["body_b"]
    x, y, z = body[:3, :3].T
    np.testing.assert_allclose(z, [0, 1, 0], atol=1e-9)   # up: room +Y
    np.testing.assert_allclose(x, [1, 0, 0], atol=1e-9)   # forward: faces +Z turned left -> +X
    np.testing.assert_allclose(y, [0, 0, -1], atol=1e-9)  # the person's left
    # at rest every joint frame is parallel to the body frame
    for pose in _chain(frames).values():
        np.testing.assert_allclose(pose[:3, :3], body[:3, :3], atol=1e-9)


def test_confidence_is_lower_for_a_joint_whose_particles_spread_more(model):
    rng = np.random.default_rng(0)
    base = model.rest_pose()
    particles = np.tile(base, (400, 1))
    skel = model.skeleton
    particles[:, skel.dof_index("l_elbow_flex")] += rng.normal(0.0, 0.3, 400)   # the left forearm
    particles[:, skel.dof_index("r_elbow_flex")] += rng.normal(0.0, 0.05, 400)  # a little the right
    weights = rng.random(400)
    spread = bf.joint_spread(model, particles, weights, model.joints_rest)
    index = model.joint_index
    assert spread[index("pelvis")] < 1e-12 and spread[index("l_elbow")] < 1e-12
    assert spread[index("l_wrist")] > spread[index("r_wrist")] > 0.0
    # the weighted RMS distance of the wrist's positions from their weighted mean
    keep = np.argsort(weights)[-bf.SPREAD_PARTICLES:]
    w = weights[keep] / weights[keep].sum()
    wrists = model.pose(particles[keep])[1][:, index("l_wrist")]
    mean = w @ wrists
    assert spread[index("l_wrist")] == pytest.approx(np.sqrt(w @ np.sum((wrists - mean) ** 2, axis=1)))
    confidence = bf.joint_confidence(spread)
    assert np.all((confidence >= 0) & (confidence <= 1))
    assert confidence[index("pelvis")] == pytest.approx(1.0)
    assert confidence[index("l_wrist")] < confidence[index("r_wrist")] < 1.0
    assert bf.joint_confidence([0.05])[0] == pytest.approx(np.exp(-1.0))
    assert bf.joint_confidence([np.nan, np.inf])[0] == 0.0


def test_an_agreeing_detection_raises_the_confidence_a_far_one_does_not():
    spread = np.array([0.05, 0.05, 0.05, 0.05])
    joints = np.zeros((4, 3))
    detected = np.array([[0.0, 0.0, 0.01], [0.0, 0.0, 0.5], [np.nan] * 3, [0.0, 0.01, 0.0]])
    scores = np.array([0.9, 0.9, 0.9, 0.0])
    plain = bf.joint_confidence(spread)
    raised = bf.joint_confidence(spread, joints, detected, scores)
    assert raised[0] > plain[0] + 0.4                 # close and sure
    np.testing.assert_allclose(raised[1:], plain[1:], atol=1e-12)  # far, none, score 0
    assert np.all(raised <= 1.0)


def test_frame_period_is_the_median_stamp_difference():
    period = FramePeriod()
    assert period.period_ns is None and period.periods(10 * PERIOD) == 1
    for k in (0, 1, 2, 3, 6, 7, 8, 12, 13):  # frames missing here and there
        period.add(T0 + k * PERIOD + (k % 2) * 1_000_000)  # and 1 ms of jitter
    assert abs(period.period_ns - PERIOD) <= 1_000_000
    assert period.periods(PERIOD + 3_000_000) == 1 and period.periods(3 * PERIOD) == 3
    assert period.periods(0) == period.periods(-PERIOD) == 1
    period.add(T0 - 100 * PERIOD)  # the stream started again
    assert period.period_ns is None
    counter = FramePeriod()  # stamps that number frames: no period
    for k in (1, 2, 3, 10):
        counter.add(k)
    assert counter.period_ns is None and counter.periods(7) == 1


def test_latest_only_queue_takes_the_newest_and_counts_what_it_skips():
    queue = FrameSetQueue(latest_only=True)
    now = 0
    for k in range(3):
        queue.put(T0 + k * PERIOD, {"k": k}, now)
    first = queue.take(idle_since_ns=0, now_ns=now + 1000)
    assert first.stamp_ns == T0 + 2 * PERIOD and first.items == {"k": 2}
    assert first.passed_over == (T0, T0 + PERIOD) and first.missing == 0 and first.skipped == 2
    assert first.waited_ns == 1000 and len(queue) == 0 and queue.take(0, now) is None
    # the tracker worked 0.5 s: frames 3-9 and 12 were dropped by a bounded DDS queue, 10, 11
    # and 13 came in right after
    idle = 10**9
    for k in (10, 11, 13):
        queue.put(T0 + k * PERIOD, {"k": k}, idle + 2_000_000)
    second = queue.take(idle_since_ns=idle, now_ns=idle + 8_000_000)
    assert second.stamp_ns == T0 + 13 * PERIOD
    assert second.passed_over == (T0 + 10 * PERIOD, T0 + 11 * PERIOD)
    assert second.missing == 7 + 1 and second.skipped == 10
    # the stream paused while the tracker was idle: the gap is not frames lost
    queue.put(T0 + 100 * PERIOD, {"k": 100}, idle + 10**10)
    third = queue.take(idle_since_ns=idle + 10**9, now_ns=idle + 10**10)
    assert third.skipped == 0


def test_every_set_queue_takes_them_oldest_first_and_counts_only_gaps():
    queue = FrameSetQueue(latest_only=False)
    for k in (0, 1, 2, 3, 5):
        queue.put(T0 + k * PERIOD, {"k": k}, 0)
    taken = [queue.take(idle_since_ns=0, now_ns=1) for _ in range(5)]
    assert [p.items["k"] for p in taken] == [0, 1, 2, 3, 5]
    assert [p.skipped for p in taken] == [0, 0, 0, 0, 1]  # frame 4 never came
    assert all(p.passed_over == () for p in taken)


@pytest.fixture(scope="module")
def tracker(model, rig):
    return BodyTracker(model, rig, TrackerParams(), np.random.default_rng(0))


def test_motion_model_scales_with_the_periods_between_tracked_sets(tracker):
    lpf = tracker.schedule.filter
    assert tracker._filter_for(1) is lpf
    for k in (2, MAX_ELAPSED_PERIODS):
        scaled = tracker._filter_for(k)
        np.testing.assert_array_equal(scaled.stds[:-1], k * lpf.stds[:-1])
        np.testing.assert_array_equal(scaled.stds[-1], lpf.stds[-1])  # the next frame's kernel
        assert tracker._filter_for(k) is scaled
    # periods counted from the stamps tracked and seen
    tracker.reset()
    tracker._stamps = ()
    for k in range(-10, 0):
        tracker.saw(T0 + k * PERIOD)
    for k in (0, 1):
        tracker._note_stamp(T0 + k * PERIOD)
    assert tracker._elapsed == (1, 1)
    tracker.saw(T0 + 2 * PERIOD)
    tracker._note_stamp(T0 + 4 * PERIOD)
    assert tracker._elapsed == (1, 3)
    # the velocity step spans one period, three have passed since
    skel = tracker.skel
    tracker.estimate = tracker.model.rest_pose().copy()
    tracker._previous_estimate = tracker.estimate.copy()
    tracker._previous_estimate[skel.translation_dofs] -= [0.05, 0.0, 0.02]
    tracker.particles = np.tile(tracker.estimate, (5, 1))
    predicted = tracker._predict()
    gain = VELOCITY_GAIN
    np.testing.assert_allclose(predicted[skel.translation_dofs] - tracker.estimate[skel.translation_dofs],
                               gain * 3 * np.array([0.05, 0.0, 0.02]), atol=1e-12)
    np.testing.assert_allclose(tracker.particles[:, skel.translation_dofs],
                               predicted[skel.translation_dofs][None].repeat(5, 0))
    # a long gap extrapolates MAX_ELAPSED_PERIODS at most
    tracker._note_stamp(T0 + 30 * PERIOD)
    tracker.particles = np.tile(tracker.estimate, (5, 1))
    predicted = tracker._predict()
    step = predicted[skel.translation_dofs] - tracker.estimate[skel.translation_dofs]
    np.testing.assert_allclose(step, gain * MAX_ELAPSED_PERIODS / 3 * np.array([0.05, 0.0, 0.02]), atol=1e-12)
    tracker.reset()


