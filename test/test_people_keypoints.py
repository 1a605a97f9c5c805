"""Several people in the keypoint stage (``keypoints.max_people`` > 1): every person gets their
own crops and keypoints, tracked bodies by their id and the others found by the pose detector
in two views; the people's keypoints go to the tracker's slots by body id.

The rendered frame set is the simulated room of ``test_keypoint_network`` with two people
standing 1.6 m apart, both seen whole by the four 640x480 cameras.
"""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from test_keypoint_network import keypoint_targets

from hmocap_ros.detection.detections import Detections, detections_from_msg, fill_msg
from hmocap_ros.detection.keypoint_detector import KeypointDetector
from hmocap_ros.detection.params import KeypointParams
from hmocap_ros.detection.people_search import (
    is_tracked,
    landmarks_owner,
    new_people,
    occluded_bodies,
)
from hmocap_ros.detection.pose_detector import PoseDetection
from hmocap_ros.geometry import project_points


@pytest.fixture(scope="module")
def two_people():
    """One rendered frame set of two people (module docstring): rig, images, masks and per
    person {label: room position} of the places the keypoints mark."""
    from hmocap_ros.body import load_body_model
    from hmocap_sim.appearance import dress, sample_appearance
    from hmocap_sim.mocap_dataset import make_rig
    from hmocap_sim.mocap_render import FrameState, MocapRenderer, RenderOptions
    from hmocap_sim.room import build_room

    rng = np.random.default_rng(5)
    rig = make_rig(4, 640, 480)
    room = build_room(rng)
    full = load_body_model("hands", "full")
    looks = [dress(full, sample_appearance(rng)) for _ in range(2)]
    poses = np.repeat(full.rest_pose()[None], 2, axis=0)
    tx, tz = full.skeleton.translation_dofs[[0, 2]]
    poses[0, [tx, tz]] = [-0.8, 0.0]
    poses[1, [tx, tz]] = [0.8, 0.0]
    poses[0, full.skeleton.dof_index("l_shoulder_abd")] = 0.6
    poses[1, full.skeleton.dof_index("r_elbow_flex")] = 1.0
    posed = full.forward(poses)
    renderer = MocapRenderer(rig, room, [(full.faces, look) for look in looks],
                             RenderOptions(noise=False), truth_people=2)
    people = tuple(look.with_hair(posed.vertices[k], full.faces) for k, look in enumerate(looks))
    frame = renderer.render(FrameState(people=people))
    from hmocap_ros.detection.extremity_pipeline import skeleton_labels

    skeletons = [skeleton_labels(list(map(str, full.joint_names)), posed.joints[k])
                 for k in range(2)]
    truths = []
    for k in range(2):
        truth = dict(zip(map(str, full.joint_names), posed.joints[k]))
        truth.update(zip(map(str, full.end_site_names), posed.end_sites[k]))
        truths.append(keypoint_targets(truth))
    masks = [np.asarray(np.max(np.stack(each), axis=0) > 0, np.uint8) * np.uint8(255)
             for each in frame.people_silhouettes]
    return SimpleNamespace(rig=rig, images=list(frame.images), masks=masks, truths=truths,
                           skeletons=skeletons)


def _median_error(positions: dict, truth: dict) -> float:
    return float(np.median([np.linalg.norm(positions[k] - truth[k]) for k in positions if k in truth]))


def _nearest(positions: dict, truths: list) -> int:
    return int(np.argmin([_median_error(positions, t) for t in truths]))


def test_two_people_nobody_tracks_are_both_found_from_two_views(two_people):
    """With no body tracked, the pose detector's people that two views agree on each get
    their own keypoints, within 6 cm (median) of their own body, one set per person."""
    detector = KeypointDetector(two_people.rig, KeypointParams(max_people=3, views_per_set=0))
    found = detector.detect_people(two_people.images, two_people.masks, {})
    assert [p.body_id for p in found] == ["", ""]
    owners = []
    for person in found:
        positions = person.keypoints.as_dict()
        assert len(positions) >= 12
        owner = _nearest(positions, two_people.truths)
        owners.append(owner)
        assert _median_error(positions, two_people.truths[owner]) < 0.06
    assert sorted(owners) == [0, 1]


def test_tracked_bodies_keep_their_keypoints_and_their_ids(two_people):
    """Two tracked bodies (their skeletons fed back by id) get the keypoints of their own
    person, whatever the order of the ids; with one body tracked, the other person is found
    as a new one."""
    truths, skeletons = two_people.truths, two_people.skeletons
    for ids in (("b0", "b1"), ("b1", "b0")):
        detector = KeypointDetector(two_people.rig, KeypointParams(max_people=2, views_per_set=0))
        bodies = {ids[0]: skeletons[0], ids[1]: skeletons[1]}
        found = detector.detect_people(two_people.images, two_people.masks, bodies)
        assert sorted(p.body_id for p in found) == ["b0", "b1"]
        for person in found:
            own = truths[0] if person.body_id == ids[0] else truths[1]
            assert _median_error(person.keypoints.as_dict(), own) < 0.05
    detector = KeypointDetector(two_people.rig, KeypointParams(max_people=2, views_per_set=0))
    found = detector.detect_people(two_people.images, two_people.masks, {"b0": skeletons[1]})
    assert [p.body_id for p in found] == ["b0", ""]
    assert _nearest(found[0].keypoints.as_dict(), truths) == 1
    assert _nearest(found[1].keypoints.as_dict(), truths) == 0


def test_a_skeleton_without_its_body_id_is_refused_with_several_people(two_people):
    from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams, ExtremityPipeline

    params = ExtremityDetectionParams(keypoints=KeypointParams(max_people=2, views_per_set=0))
    pipeline = ExtremityPipeline(two_people.rig.cameras, params)
    with pytest.raises(ValueError, match="body id"):
        pipeline.detect(two_people.images, two_people.masks, two_people.skeletons[0])
    out = pipeline.detect(two_people.images, two_people.masks, {"b0": two_people.skeletons[0]})
    assert out.person_ids == ("b0", "") and out.persons is not None
    assert len(out.person(0)) >= 12 and len(out.person(1)) >= 12


def test_the_farther_body_behind_the_nearer_is_left_out_by_depth_not_size():
    """In one view the farther body's box, mostly covered by the nearer one's, is left out,
    though it is the larger box; apart, nobody is."""
    near = np.array([100.0, 100.0, 200.0, 300.0])
    far_big = np.array([90.0, 80.0, 230.0, 320.0])
    assert occluded_bodies([near, far_big], [2.0, 4.0], 0.5) == [False, True]
    assert occluded_bodies([far_big, near], [4.0, 2.0], 0.5) == [True, False]
    apart = np.array([400.0, 100.0, 500.0, 300.0])
    assert occluded_bodies([near, apart], [2.0, 4.0], 0.5) == [False, False]
    assert occluded_bodies([near, far_big], [np.nan, 4.0], 0.5) == [False, False]


def test_landmarks_go_to_the_nearest_projected_body_and_tracked_detections_are_known():
    hips = np.array([[100.0, 200.0], [300.0, 200.0], [np.nan, np.nan]])
    assert landmarks_owner(np.array([290.0, 190.0]), hips) == 1
    assert landmarks_owner(np.array([90.0, 190.0]), hips) == 0
    assert landmarks_owner(np.array([90.0, 190.0]), np.full((2, 2), np.nan)) == -1
    detection = PoseDetection(0.9, np.array([250.0, 50.0, 350.0, 350.0]),
                              np.array([[305.0, 210.0], [305.0, 60.0], [0, 0], [0, 0]]))
    assert is_tracked(detection, hips)
    assert not is_tracked(detection, hips[[0, 2]])


def _detection_at(camera, hips, head) -> PoseDetection:
    pixels = project_points([camera], np.array([hips, head]), distort=True).pixels[0]
    box = np.concatenate([pixels.min(axis=0) - 40, pixels.max(axis=0) + 40])
    return PoseDetection(0.9, box, np.vstack([pixels, pixels]))


def test_new_people_need_two_views_that_agree(two_people):
    """Detections of two people in three views make two people, each from its own three
    views; a person detected in one view only makes none; a pair of views whose detections do
    not triangulate to one point makes none."""
    cams = list(two_people.rig.cameras)
    a = (np.array([-0.8, 1.0, 0.0]), np.array([-0.8, 1.9, 0.0]))
    b = (np.array([0.8, 1.0, 0.0]), np.array([0.8, 1.9, 0.0]))
    per_view = [[_detection_at(c, *a), _detection_at(c, *b)] for c in cams[:3]] + [[]]
    people = new_people(cams, per_view, 20.0, 4)
    assert len(people) == 2
    assert sorted(len(p.detections) for p in people) == [3, 3]
    hips = sorted(float(p.hips[0]) for p in people)
    assert abs(hips[0] + 0.8) < 0.01 and abs(hips[1] - 0.8) < 0.01
    assert new_people(cams, [[_detection_at(cams[0], *a)], [], [], []], 20.0, 4) == []
    c = (np.array([0.5, 1.0, -0.9]), np.array([0.5, 1.9, -0.9]))
    wrong = [[_detection_at(cams[0], *a)], [_detection_at(cams[1], *c)], [], []]
    assert new_people(cams, wrong, 20.0, 4) == []
    assert len(new_people(cams, per_view, 20.0, 1)) == 1


def test_people_travel_in_the_message_and_go_to_their_slots():
    """Detections of two people (a tracked body and a new one) survive the message, and the
    people tracker gives each slot its own: the tracked body's to its slot, the new person
    to a slot that follows nobody."""
    from geometry_msgs.msg import Point, Vector3
    from hmocap_interfaces.msg import Extremities

    from hmocap_ros.body import load_body_model
    from hmocap_ros.geometry.rig import load_rig
    from hmocap_ros.tracking.params import TrackerParams
    from hmocap_ros.tracking.people_tracker import PeopleTracker

    det = Detections.of_people("keypoints", [
        ("b1", ("head", "left_hand"), np.ones((2, 3)), np.full(2, 0.9)),
        ("", ("head",), np.full((1, 3), 2.0), np.full(1, 0.8))])
    back = detections_from_msg(fill_msg(Extremities(), det, Point, Vector3))
    assert back.person_ids == ("b1", "") and list(back.persons) == [0, 0, 1]
    assert back.person(1).labels == ("head",)
    one = detections_from_msg(fill_msg(Extremities(), Detections.empty("skin"), Point, Vector3))
    assert one.persons is None

    rig = load_rig(Path(__file__).resolve().parents[1] / "config" / "rig_example.yaml")
    people = PeopleTracker(load_body_model("tracking"), rig, TrackerParams(method="kf-hpf"),
                           np.random.default_rng(0), max_people=3)
    slots = people._people_per_slot(back)
    assert slots is not None and len(slots) == 3
    assert slots[0].labels == ("head",)  # b0 follows nobody: it takes the new person
    assert slots[1].labels == ("head", "left_hand")  # b1's own
    assert len(slots[2]) == 0


def test_a_body_is_fitted_without_the_bodies_in_front_of_it(two_people):
    """Each body's masks lose the other body's rendered silhouette in the views where the
    other stands nearer, and keep it where this body stands in front; a slot that follows
    nobody loses every tracked body."""
    from hmocap_ros.body import load_body_model
    from hmocap_ros.tracking.other_bodies import masks_without_others, render_bodies

    model = load_body_model("tracking")
    rig = two_people.rig
    poses = np.repeat(model.rest_pose()[None], 2, axis=0)
    tx, tz = model.skeleton.translation_dofs[[0, 2]]
    poses[0, [tx, tz]] = [-0.3, 0.0]
    poses[1, [tx, tz]] = [0.3, 0.0]
    posed = model.forward(poses)
    pelvis = poses[:, model.skeleton.translation_dofs]
    masks = [np.full((c.height // 2, c.width // 2), 255, np.uint8) for c in rig.cameras]
    masks[3] = None
    rendered = render_bodies(rig.cameras, masks, [(posed.vertices[0], pelvis[0]),
                                                  (posed.vertices[1], pelvis[1])], model.faces)
    cases = set()
    for k in (0, 1):
        own = masks_without_others(masks, rendered, k)
        other = rendered[1 - k]
        assert own[3] is None
        for v in range(3):
            removed = own[v] == 0
            in_front = other.depths[v] < rendered[k].depths[v]
            cases.add(bool(in_front))
            if in_front:
                assert removed.any() and np.array_equal(removed, other.silhouettes[v])
            else:
                assert not removed.any()
    assert cases == {True, False}
    nobody = masks_without_others(masks, [rendered[0], rendered[1], None], 2)
    union = rendered[0].silhouettes[0] | rendered[1].silhouettes[0]
    assert np.array_equal(nobody[0] == 0, union)
