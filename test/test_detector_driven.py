"""Detector-driven tracking (thesis sec. 2.5): skin maps, 3D extremities, IK particles, dd-hpf
with skin candidates.

Scenes with known ground truth: the tracking body in a chosen pose, exact silhouettes in the
cameras of ``config/rig_example.yaml`` at 320x240, and a detector map that is 1 exactly where
the hands are seen (the skin detector's ideal output) so that the 3D fusion is tested alone.
"""
from __future__ import annotations

import numpy as np
import pytest

from hmocap_ros.body import rest_pose
from hmocap_ros.detection.detections import Detections
from hmocap_ros.detection.greedy_assignment import classify
from hmocap_ros.detection.skin import skin_probability
from hmocap_ros.detection.skin_extremities import SkinExtremityDetector, SkinExtremityParams, surface_points, visibility
from hmocap_ros.geometry.projection import project_batch
from hmocap_ros.params import from_flat
from hmocap_ros.render import render_silhouettes
from hmocap_ros.tracking.body_fitness import SilhouetteFitness
from hmocap_ros.tracking.body_tracker import BodyTracker, TrackerParams
from hmocap_ros.tracking.detection_assignment import MAX_DISTANCE, detection_cost, reacquire_hands
from hmocap_ros.tracking.ik_proposals import IKProposer
from hmocap_sim.appearance import SHIRT_COLOURS, SKIN_TONES, TROUSER_COLOURS

STAMP0 = 1_700_000_000_000_000_000


@pytest.fixture(scope="module")
def rest(model, rig):
    return SilhouetteFitness(model, rig, 0.5).rest(None)


def arms_out(model, heading=0.5):
    """Standing, the left arm forward and bent, the right arm out to the side."""
    skel = model.skeleton
    p = rest_pose(skel).copy()
    p[:3] = (0.3, p[1], -0.2)
    for dof, value in (("root_yaw", heading), ("l_shoulder_flex", 1.2), ("l_elbow_flex", 0.9),
                       ("r_shoulder_abd", 1.3), ("r_elbow_flex", 0.3)):
        p[skel.dof_index(dof)] = value
    return p


def scene(model, rig, params):
    """Masks (M, H, W) 0/255 and hand-only detector maps (M, H, W) 0/255 of one pose."""
    verts, _ = model.pose(np.atleast_2d(params))
    uv, _ = project_batch(verts, *rig.arrays())
    h, w = rig[0].height, rig[0].width
    masks = render_silhouettes(uv, model.faces, h, w)[0] * np.uint8(255)
    hand_joints = [model.joint_index("l_wrist"), model.joint_index("r_wrist")]
    hand_vertex = np.isin(model.vertex_part, hand_joints)
    hand_faces = model.faces[hand_vertex[model.faces].all(axis=1)]
    maps = render_silhouettes(uv, hand_faces, h, w)[0] * np.uint8(255)
    return masks, maps


# ----------------------------------------------------------------------------- skin detector


def _patch(rgb01, size=(8, 8)):
    return np.full(size + (3,), np.round(np.asarray(rgb01) * 255), np.uint8)


def test_skin_probability_separates_the_simulators_skin_from_its_clothes():
    skin = [skin_probability(_patch(c)).mean() / 255 for c in SKIN_TONES]
    clothes = [skin_probability(_patch(c)).mean() / 255 for c in SHIRT_COLOURS + TROUSER_COLOURS]
    assert min(skin) > 0.5, skin
    # brown/olive cloth is skin-coloured to any chrominance detector; most clothes are not
    assert np.median(clothes) < 0.05 and max(skin) > max(clothes[:4])
    image = _patch(SKIN_TONES[2], (20, 20))
    mask = np.zeros((20, 20), np.uint8)
    mask[:10] = 255
    out = skin_probability(image, mask=mask)
    assert out.shape == (10, 10) and out[:5].min() > 128 and out[5:].max() == 0
    with pytest.raises(ValueError):
        skin_probability(np.zeros((4, 4), np.uint8))
    with pytest.raises(ValueError):
        skin_probability(image, mask=np.zeros((3, 3), np.uint8))


# ----------------------------------------------------------------------------- 3D extremities


def test_surface_points_and_normals_of_a_ball():
    n = 25
    ijk = np.indices((n, n, n)).transpose(1, 2, 3, 0)
    centre = np.array([12.0, 12.0, 12.0])
    occ = np.linalg.norm(ijk - centre, axis=-1) <= 8.0
    pts, normals = surface_points(occ, np.zeros(3), 0.01)
    radial = pts - 0.01 * centre
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    assert len(pts) < occ.sum() / 2  # the shell, not the volume
    np.testing.assert_allclose(np.linalg.norm(pts - 0.12, axis=1), 0.08, atol=0.011)
    assert np.einsum("ij,ij->i", normals, radial).min() > 0.8


def test_visibility_sees_the_front_of_a_ball_only(rig):
    n = 21
    ijk = np.indices((n, n, n)).transpose(1, 2, 3, 0)
    occ = np.linalg.norm(ijk - 10.0, axis=-1) <= 9.0
    voxel = 0.02
    origin = np.array([0.3, 0.8, -0.2]) - 10 * voxel
    pts, normals = surface_points(occ, origin, voxel)
    eta = visibility(pts, normals, list(rig), voxel)
    total = eta.sum(axis=0)
    assert np.all((np.abs(total - 1) < 1e-9) | (total == 0))
    for c, cam in enumerate(rig):
        towards = (cam.position - (origin + 10 * voxel))
        towards /= np.linalg.norm(towards)
        facing = (pts - (origin + 10 * voxel)) @ towards
        seen = eta[c] > 0
        assert seen.any()
        assert facing[seen].min() > -0.01  # nothing on the far side is seen
    views = np.array([True, False, True, True])
    assert not visibility(pts, normals, list(rig), voxel, views=views)[1].any()


def test_reacquisition_gives_a_lost_hand_a_candidate_within_reach():
    shoulders = np.array([[0.2, 1.4, 0.0], [-0.2, 1.4, 0.0]])
    reach = np.array([0.7, 0.7])
    head = np.array([0.0, 1.65, 0.0])
    face = np.array([0.0, 1.6, 0.08])
    left_far = np.array([0.6, 1.0, 0.3])     # the left hand, where the tracker has no arm
    shoe = np.array([0.1, 0.05, 0.1])        # brown shoes look like skin
    cands = np.array([face, shoe, left_far])
    assigned = np.full((3, 3), np.nan)
    assigned[1] = [-0.5, 1.0, 0.0]           # the right hand was found by eq. 2.19
    hands = reacquire_hands(np.vstack([cands, assigned[1]]), assigned, shoulders, reach, head, 0.3)
    np.testing.assert_allclose(hands[0], left_far)  # not the face, not the shoe
    np.testing.assert_allclose(hands[1], assigned[1])
    # nothing within reach: the hand stays undetected
    hands = reacquire_hands(cands[:2], assigned, shoulders, reach, head, 0.3)
    assert np.isnan(hands[0]).all()
    # within the left arm's reach, but on the right of the body (nearer the right shoulder):
    # another skin blob of the right arm, not the lost left hand
    right_side = np.array([-0.35, 1.1, 0.3])
    assert np.linalg.norm(right_side - shoulders[0]) < reach[0]
    hands = reacquire_hands(np.vstack([right_side, assigned[1]]), assigned, shoulders, reach,
                            head, 0.3)
    assert np.isnan(hands[0]).all()


def test_detection_cost_eq_2_20_matches_each_detection_to_its_own_kind():
    assigned = np.full((5, 3), np.nan)
    assigned[0] = [0.5, 1.0, 0.0]            # a left hand
    assigned[2] = [0.0, 1.7, 0.0]            # the head: not in eq. 2.20
    ee = np.zeros((2, 5, 3))
    ee[:, 0] = [0.5, 1.1, 0.0]               # pose 0: left hand 10 cm off
    ee[:, 1] = [-0.5, 1.0, 0.0]
    ee[:, 3] = [0.5, 0.0, 0.0]
    ee[1, 0] = [0.0, 0.2, 0.0]               # pose 1: a hand far off, a foot kicked up to it
    ee[1, 4] = [0.5, 1.0, 0.0]
    cost = detection_cost(assigned, ee)
    assert cost[0] == pytest.approx(0.1)
    assert cost[1] > 0.5                     # the foot does not explain the hand
    assigned[3] = [0.5, 0.0, 0.05]           # a detected left foot: nearest of the feet
    np.testing.assert_allclose(detection_cost(assigned, ee)[0], (0.1 + 0.05) / 2)
    assert np.all(detection_cost(np.full((5, 3), np.nan), ee) == 0)


def test_classify_is_the_greedy_solution_of_eq_2_19():
    targets = np.array([[0.0, 1.0, 0.0], [0.5, 1.0, 0.0], [0.25, 1.6, 0.0]])
    cands = np.array([[0.45, 1.0, 0.0], [0.1, 1.0, 0.0], [0.25, 1.55, 0.0], [2.0, 0.0, 0.0]])
    out = classify(cands, targets, (0.35, 0.35, 0.25))
    np.testing.assert_allclose(out, cands[[1, 0, 2]])
    # a candidate serves one target only; a target out of reach gets none
    out = classify(cands[:1], targets, (0.35, 0.35, 0.25))
    assert np.isnan(out[0]).all() and np.allclose(out[1], cands[0]) and np.isnan(out[2]).all()
    assert np.isnan(classify(np.zeros((0, 3)), targets, (0.35, 0.35, 0.25))).all()


def skin_detections(rig, masks, maps, joints=None) -> Detections:
    cand = SkinExtremityDetector(list(rig), SkinExtremityParams(mask_scale=1.0, voxel=0.025)
                                 ).detect(list(masks), list(maps), joints)
    return Detections("skin", ("unknown",) * len(cand.positions), cand.positions, cand.scores,
                      cand.normals, cand.surface, cand.probability)


def test_skin_detector_finds_the_hands_in_3d(model, rig, rest):
    params = arms_out(model)
    masks, maps = scene(model, rig, params)
    ik = IKProposer(model)
    truth = ik.end_effectors(params[None], rest)[0]  # l_hand, r_hand, head, l_foot, r_foot
    _, joints = model.pose(params[None])
    # the previous pose: hands 15-20 cm away from where they are now
    targets = truth[:3] + np.array([[0.1, -0.1, 0.08], [-0.12, 0.1, 0.0], [0.0, 0.0, 0.0]])
    for box_joints in (joints[0], None):  # around the last skeleton, or the room's hull
        found = skin_detections(rig, masks, maps, box_joints)
        assigned = classify(found.positions, targets, MAX_DISTANCE[:3])
        err = np.linalg.norm(assigned[:2] - truth[:2], axis=1)
        assert err.max() < 0.05, err
        assert len(found.points) == len(found.probability) > 500
        assert np.all(found.scores > 0) and np.allclose(np.linalg.norm(found.normals, axis=1), 1)
    # a view without its map or its mask is left out, not an error
    detector = SkinExtremityDetector(list(rig), SkinExtremityParams(mask_scale=1.0, voxel=0.025))
    again = detector.detect([masks[0], masks[1], masks[2], None], [None, maps[1], maps[2], None],
                            joints[0])
    assert again.positions.shape[1] == 3
    assert len(detector.detect(list(masks), [None] * 4, joints[0]).positions) == 0
    assert len(detector.detect([np.zeros_like(m) for m in masks], list(maps)).positions) == 0


# ----------------------------------------------------------------------------- IK particles


def test_ik_solutions_put_the_hand_on_the_detection(model, rig, rest):
    ik = IKProposer(model)
    truth = arms_out(model)
    reference = arms_out(model)
    dofs = ik.dofs("l_arm")
    reference[dofs] = rest_pose(model.skeleton)[dofs]  # the arm lost: hanging down
    target = ik.end_effectors(truth[None], rest)[0, 0]
    rng = np.random.default_rng(0)
    values, dist = ik.solve("l_arm", target, reference, rest, rng)
    assert len(values) >= 10 and dist.max() <= ik.params.tolerance
    x = np.repeat(reference[None], len(values), axis=0)
    x[:, dofs] = values
    hands = ik.end_effectors(x, rest)[:, 0]
    assert np.linalg.norm(hands - target, axis=1).max() <= ik.params.tolerance + 1e-9
    lower, upper = model.skeleton.lower[dofs], model.skeleton.upper[dofs]
    assert np.all(values >= lower - 1e-9) and np.all(values <= upper + 1e-9)
    # the swivel family, not one solution: the elbows differ
    elbows = model.pose(x)[1][:, model.joint_index("l_elbow")]
    assert np.ptp(elbows, axis=0).max() > 0.05
    # out of reach: no solutions, no IK particles
    far = target + np.array([2.0, 0.0, 0.0])
    assert len(ik.solve("l_arm", far, reference, rest, rng)[0]) == 0
    particles = np.repeat(reference[None], 200, axis=0)
    det = np.full((5, 3), np.nan)
    det[0] = target
    made = ik.apply(particles, det, reference, rest, rng)
    assert made["r_arm"] == 0 and 60 < made["l_arm"] < 140  # start share 0.5
    moved = np.any(particles[:, dofs] != reference[dofs], axis=1)
    assert moved.sum() == made["l_arm"]
    # the IK survival rate moves the share within [0.25, 0.75]
    w = np.where(moved, 1.0, 0.0)
    for _ in range(10):
        rates = ik.update_fraction(particles, w, det, rest)
    assert rates["l_arm"] > 0.99 and ik.fraction["l_arm"] == pytest.approx(0.75)
    for _ in range(20):
        ik.update_fraction(particles, 1.0 - w, det, rest)
    assert ik.fraction["l_arm"] == pytest.approx(0.25) and ik.fraction["r_arm"] == 0.5


def _a_pose_baseline(model, params, truth):
    """Joint errors of the A-pose at the true root and heading: what missing arms cost."""
    a_pose = rest_pose(model.skeleton).copy()
    for dof in ("root_tx", "root_ty", "root_tz", "root_yaw"):
        a_pose[model.skeleton.dof_index(dof)] = params[model.skeleton.dof_index(dof)]
    return np.linalg.norm(model.pose(a_pose[None])[1][0] - truth, axis=1)


def _dd_tracker(model, rig):
    return BodyTracker(model, rig, from_flat(TrackerParams, {
        "method": "dd-hpf", "filter.particles": 100, "startup.working_width": 160,
        "startup.min_foreground": 30, "startup.estimate_shape": False}),
        np.random.default_rng(0))


@pytest.mark.slow  # dd-hpf's quick cover: test_extension_points.py (a registered detector)
def test_dd_hpf_tracks_with_skin_detections_and_runs_without(model, rig, rest):
    params = arms_out(model)
    masks, maps = scene(model, rig, params)
    tracker = _dd_tracker(model, rig)
    truth = model.pose(params[None])[1][0]
    detections = skin_detections(rig, masks, maps)
    errors = []
    for f in range(3):
        res = tracker.update(list(masks), STAMP0 + f, detections)
        errors.append(np.linalg.norm(res.joints - truth, axis=1))
    assert res.state == "tracking" and res.extremities is not None
    assert res.extremities.found[[0, 1]].all() and res.timings["detection"] > 0
    assert not res.extremities.found[3:].any()  # skin sees no feet
    base = _a_pose_baseline(model, params, truth)
    wrists = [model.joint_index("l_wrist"), model.joint_index("r_wrist")]
    figures = {"mean": errors[-1].mean(), "wrist": errors[-1][wrists].mean(),
               "a_pose_mean": base.mean(), "a_pose_wrist": base[wrists].mean()}
    assert figures["mean"] < 0.04 and figures["mean"] < 0.5 * figures["a_pose_mean"], figures
    assert figures["wrist"] < 0.08 and figures["wrist"] < 0.3 * figures["a_pose_wrist"], figures
    # without detections (no extremity_detection node) it runs as hpf-apo
    res = tracker.update(list(masks), STAMP0 + 10)
    assert res.state == "tracking" and res.extremities is None
    # an empty detection set: nothing found, nothing breaks
    res = tracker.update(list(masks), STAMP0 + 11, Detections.empty("skin"))
    assert res.state == "tracking" and not res.extremities.found[:3].any()
