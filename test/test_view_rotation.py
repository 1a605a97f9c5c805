"""The landmark network on some views per frame set, the others' landmarks carried forward
(hmocap_ros.detection.view_rotation and the keypoint detector's use of it)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from hmocap_ros.detection.keypoint_network import NUM_LANDMARKS, ViewLandmarks
from hmocap_ros.detection.view_rotation import (
    LANDMARK_PART,
    MAX_EXTRAPOLATION_S,
    MIN_VIEWS_PER_SET,
    SkeletonHistory,
    carried_landmarks,
    views_for_rate,
    views_to_run,
)
from hmocap_ros.geometry import project_points

MS = 1_000_000


def _skeleton(offset) -> dict:
    base = {"head": (0.0, 1.6, 3.0), "left_wrist": (0.3, 1.0, 3.0), "right_wrist": (-0.3, 1.0, 3.0),
            "left_hip": (0.1, 0.9, 3.0), "right_hip": (-0.1, 0.9, 3.0), "left_ankle": (0.1, 0.1, 3.0)}
    return {k: np.asarray(v) + np.asarray(offset, float) for k, v in base.items()}


def test_history_interpolates_between_stamps_and_extrapolates_at_most_its_limit():
    h = SkeletonHistory()
    h.add(0, _skeleton((0, 0, 0)))
    h.add(40 * MS, _skeleton((0.04, 0, 0)))  # 1 m/s along x
    assert h.at(20 * MS)["head"][0] == pytest.approx(0.02)
    assert h.at(80 * MS)["head"][0] == pytest.approx(0.08)  # constant velocity ahead
    assert h.at(10_000 * MS)["head"][0] == pytest.approx(0.04 + MAX_EXTRAPOLATION_S)
    assert h.at(-5 * MS)["head"][0] == pytest.approx(0.0)  # before the oldest: the oldest
    assert h.at(20 * MS)["hips"] == pytest.approx(np.array([0.02, 0.9, 3.0]))
    h.add(20 * MS, _skeleton((5, 0, 0)))  # between kept stamps: not taken
    assert h.at(20 * MS)["head"][0] == pytest.approx(0.02)
    h.add(-100 * MS, _skeleton((1, 0, 0)))  # before the oldest: the stream started over
    assert len(h) == 1 and h.at(0)["head"][0] == pytest.approx(1.0)


def test_rotation_refreshes_every_view_within_ceil_views_over_k_sets():
    """Views without landmarks always run; then the oldest landmarks first, so over any
    ceil(V / k) consecutive sets every view runs once."""
    n, k = 5, 2
    ages: list = [None] * n
    runs = []
    for t in range(12):
        jobs = views_to_run(ages, list(range(n)), k)
        runs.append(jobs)
        for v in jobs:
            ages[v] = t
    assert runs[0] == list(range(n))  # nobody has landmarks: everyone runs
    assert all(len(j) == k for j in runs[1:])
    window = math.ceil(n / k)
    for t in range(1, 12 - window + 1):
        assert set().union(*runs[t:t + window]) == set(range(n)), (t, runs)
    # a view that lost its person runs at once; fewer than MIN_VIEWS_PER_SET are never asked
    ages[3] = None
    assert 3 in views_to_run(ages, list(range(n)), k)
    assert len(views_to_run(ages[:4], [0, 1, 2], 1)) == MIN_VIEWS_PER_SET


def test_carried_landmarks_move_with_their_parts_projection():
    """A body that moves 10 cm sideways between the two stamps: each landmark moves by its
    part's projected motion (the wrist landmarks by the wrist's, the hand points too); a part
    the skeletons lack leaves its landmarks where they were."""
    from hmocap_ros.demo import DEMO_RIG
    from hmocap_ros.geometry.rig import load_rig

    camera = load_rig(DEMO_RIG).cameras[0]
    then, now = _skeleton((0, 0, 0)), _skeleton((0.1, 0.0, 0.0))
    view = ViewLandmarks(xy=np.full((NUM_LANDMARKS, 2), 100.0), visibility=np.ones(NUM_LANDMARKS),
                         presence=np.ones(NUM_LANDMARKS), score=0.9)
    moved = carried_landmarks(camera, view, then, now)
    proj = project_points([camera], np.stack([then["left_wrist"], now["left_wrist"]])).pixels[0]
    expect = proj[1] - proj[0]
    assert np.linalg.norm(expect) > 1.0  # the motion is seen
    for i, part in enumerate(LANDMARK_PART):
        if part in ("left_wrist",):
            assert moved.xy[i] == pytest.approx(view.xy[i] + expect)
        if part in ("left_shoulder", "right_knee"):  # not in the skeletons
            assert moved.xy[i] == pytest.approx(view.xy[i])
    assert carried_landmarks(camera, view, None, now) is view


def test_views_for_rate_is_the_arithmetic_of_the_measured_costs():
    # 1/10 s per set, 30 ms of other work, 20 ms per view: 3 views fit
    assert views_for_rate(10.0, 0.020, 0.030, 4) == 3
    assert views_for_rate(100.0, 0.020, 0.030, 4) == MIN_VIEWS_PER_SET  # nothing fits: the floor
    assert views_for_rate(1.0, 0.020, 0.030, 4) == 4  # everything fits: every view
    assert views_for_rate(10.0, 0.0, 0.0, 6) == 6  # nothing measured yet: every view


@pytest.fixture(scope="module")
def walking():
    """Every third frame set with the person of the demo bag (160x120, exact silhouettes, 120
    ms apart): frames, their indices and their images."""
    from test_extremity_detection import bag_images

    from hmocap_ros.demo import DEMO_BAG
    from hmocap_ros.eval.mocap_frames import load_frames

    frames = load_frames(DEMO_BAG, "gt", max_frames=36)
    ks = [int(k) for k in np.flatnonzero(np.isfinite(frames.truth).all(axis=(1, 2)))[:36:3]]
    return frames, ks, bag_images(frames.rig.names, frames.stamps[ks])


def test_carried_landmarks_lie_nearer_the_networks_next_landmarks_than_unmoved_ones(walking):
    """The network's landmarks of one frame set carried to the next by the true skeleton's
    motion lie nearer the landmarks the network finds there than the same landmarks unmoved
    (median over the views and sets, the body landmarks 0-32)."""
    from hmocap_ros.detection.extremity_pipeline import skeleton_labels
    from hmocap_ros.detection.keypoint_detector import KeypointDetector
    from hmocap_ros.detection.params import KeypointParams

    frames, ks, images = walking
    detector = KeypointDetector(frames.rig, KeypointParams(views_per_set=0))
    found: list = []
    run = detector._infer

    def infer(*args):
        out = run(*args)
        found.append(out[0])
        return out

    detector._infer = infer
    before, moved, unmoved = None, [], []
    for k in ks:
        found.clear()
        stamp = int(frames.stamps[k])
        detector.detect(images[stamp], [m * np.uint8(255) for m in frames.mask_list(k)])
        skeleton = skeleton_labels(frames.joint_names, frames.truth[k])
        if before is not None:
            for camera, old, new in zip(frames.rig.cameras, before[0], found):
                if old is not None and new is not None:
                    carried = carried_landmarks(camera, old, before[1], skeleton)
                    moved.append(np.median(np.linalg.norm(carried.xy[:33] - new.xy[:33], axis=1)))
                    unmoved.append(np.median(np.linalg.norm(old.xy[:33] - new.xy[:33], axis=1)))
        before = (list(found), skeleton)
    assert len(moved) >= 20
    assert np.median(moved) < 0.6 * np.median(unmoved), (np.median(moved), np.median(unmoved))


def test_two_views_per_set_keep_the_keypoints_of_a_moving_person(walking):
    """With the network on two of the four views per set, the others carried, the
    triangulated keypoints stay within a few centimetres of the every-view keypoints of the
    same set (median); the network ran on every view for the first set, then on two, and the
    views' landmarks were carried."""
    from hmocap_ros.detection.extremity_pipeline import skeleton_labels
    from hmocap_ros.detection.keypoint_detector import KeypointDetector
    from hmocap_ros.detection.params import KeypointParams

    frames, ks, images = walking
    every = KeypointDetector(frames.rig, KeypointParams(views_per_set=0))
    some = KeypointDetector(frames.rig, KeypointParams(views_per_set=2, pose_rate_hz=0.0))
    gaps, runs, sources = [], [], set()
    previous = previous_stamp = None
    for j, k in enumerate(ks):
        stamp = int(frames.stamps[k])
        masks = [m * np.uint8(255) for m in frames.mask_list(k)]
        a = every.detect(images[stamp], masks, previous).as_dict()
        b = some.detect(images[stamp], masks, previous, stamp, previous_stamp).as_dict()
        runs.append(some.last_views_run)
        sources.update(s for s in some.last_sources if s)
        if j > 0:
            gaps += [float(np.linalg.norm(a[lab] - b[lab])) for lab in a.keys() & b.keys()]
        previous = skeleton_labels(frames.joint_names, frames.truth[k])
        previous_stamp = stamp
    assert runs[0] == 4 and set(runs[1:]) == {2}, runs
    assert "carried" in sources, sources
    assert len(gaps) > 100
    assert np.median(gaps) < 0.04, np.median(gaps)


def test_the_measured_cost_adds_views_where_the_rate_leaves_room(walking):
    """views_per_set is the floor; pose_rate_hz adds the views whose measured cost fits its
    period: at 0.5 poses/s every view runs, at 1,000 only the floor."""
    from hmocap_ros.detection.keypoint_detector import KeypointDetector
    from hmocap_ros.detection.params import KeypointParams

    frames, ks, images = walking
    for rate, expect in ((0.5, 4), (1000.0, 2)):
        detector = KeypointDetector(frames.rig, KeypointParams(views_per_set=2, pose_rate_hz=rate))
        for k in ks[:3]:
            stamp = int(frames.stamps[k])
            detector.detect(images[stamp], [m * np.uint8(255) for m in frames.mask_list(k)], None,
                            stamp)
        assert detector.last_views_run == expect, rate
