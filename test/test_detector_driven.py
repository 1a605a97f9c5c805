"""Detector-driven tracking (thesis sec. 2.5): skin maps, 3D extremities, IK particles, dd-hpf.

Scenes with known ground truth: the tracking body in a chosen pose, exact silhouettes in the
cameras of ``config/rig_example.yaml`` at 320x240, and a detector map that is 1 exactly where
the hands are seen (the skin detector's ideal output) so that the 3D fusion is tested alone.
"""
from __future__ import annotations

import numpy as np
import pytest

from hmocap_ros.body import rest_pose
from hmocap_ros.params import from_flat
from hmocap_ros.render import project_batch, render_silhouettes
from hmocap_ros.segmentation.skin import skin_probability
from hmocap_ros.sim.appearance import SHIRT_COLOURS, SKIN_TONES, TROUSER_COLOURS
from hmocap_ros.tracking.body_fitness import SilhouetteFitness
from hmocap_ros.tracking.body_tracker import BodyTracker, TrackerParams
from hmocap_ros.tracking.extremity_detection import (ExtremityDetector, ExtremityParams, classify,
                                                     detection_cost, geodesic_extrema,
                                                     reacquire_hands, surface_points, visibility)
from hmocap_ros.tracking.ik_proposals import IKProposer

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


def test_geodesic_extrema_are_the_ends_of_the_limbs():
    # a star: a 5x5 core (the centre) with four bars, the one along +x bent back along +y
    occ = np.zeros((40, 40, 5), bool)
    occ[18:23, 2:38, :] = True        # bar along y through the core
    occ[2:38, 18:23, :] = True        # bar along x
    occ[34:38, 23:37, :] = True       # the +x bar bends towards +y: its tip is at (36, 36)
    voxel = 0.01
    tips = geodesic_extrema(occ, np.zeros(3), voxel, np.array([0.2, 0.2, 0.02]), 4, 0.02)
    expected = voxel * np.array([[20, 2, 2], [20, 37, 2], [2, 20, 2], [36, 36, 2]])
    assert tips.shape == (4, 3)
    d = np.linalg.norm(tips[:, None] - expected[None], axis=2)
    # each end found once, within a voxel or two (the tip mean lies inside the bar)
    assert np.all(d.min(axis=0) < 0.025) and len(set(np.argmin(d, axis=1))) == 4, d.round(3)
    # the farthest end along the body (the bent bar: about 30 voxels of path) comes first
    assert np.argmin(d[0]) == 3
    assert len(geodesic_extrema(np.zeros((3, 3, 3), bool), np.zeros(3), 0.01, np.zeros(3), 3, 0.02)) == 0


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


def test_extremity_detector_finds_the_hands_in_3d(model, rig, rest):
    params = arms_out(model)
    masks, maps = scene(model, rig, params)
    ik = IKProposer(model)
    truth = ik.end_effectors(params[None], rest)[0]  # l_hand, r_hand, head, l_foot, r_foot
    _, joints = model.pose(params[None])
    detector = ExtremityDetector(list(rig), ExtremityParams(mask_scale=1.0, voxel=0.025))
    # the previous pose: hands 15-20 cm away from where they are now
    targets = truth + np.array([[0.1, -0.1, 0.08], [-0.12, 0.1, 0.0], [0.0, 0.0, 0.0],
                                [0.1, 0.05, 0.1], [-0.1, 0.05, -0.1]])
    found = detector.detect(list(masks), list(maps), joints[0], targets)
    assert found.found[[0, 1, 3, 4]].all()
    err = np.linalg.norm(found.assigned[[0, 1]] - truth[[0, 1]], axis=1)
    assert err.max() < 0.05, err
    # the feet are the hull's geodesic extremes (mean of the hull within 8 cm of the tip)
    err = np.linalg.norm(found.assigned[[3, 4]] - truth[[3, 4]], axis=1)
    assert err.max() < 0.08, err
    assert len(found.detections) == 4  # hands and feet: the set C_t of eq. 2.20
    assert len(found.surface) == len(found.probability) > 500
    # a view without its map or its mask is left out, not an error
    maps_missing = [None, maps[1], maps[2], None]
    masks_missing = [masks[0], masks[1], masks[2], None]
    again = detector.detect(masks_missing, maps_missing, joints[0], targets)
    assert again.assigned.shape == (5, 3)
    none = detector.detect(list(masks), [None] * 4, joints[0], targets)
    assert not none.found[:3].any() and len(none.candidates) == 0 and none.found[3:].all()


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


def test_dd_hpf_tracks_with_detector_maps_and_runs_without(model, rig, rest):
    params = arms_out(model)
    masks, maps = scene(model, rig, params)
    tracker = BodyTracker(model, rig, from_flat(TrackerParams, {
        "method": "dd-hpf", "filter.particles": 100, "weighting.working_scale": 0.5,
        "startup.min_foreground": 30, "startup.estimate_shape": False}),
        np.random.default_rng(0))
    truth = model.pose(params[None])[1][0]
    errors = []
    for f in range(3):
        res = tracker.update(list(masks), STAMP0 + f, list(maps))
        errors.append(np.linalg.norm(res.joints - truth, axis=1))
    assert res.state == "tracking" and res.extremities is not None
    assert res.extremities.found[[0, 1]].all() and res.timings["detection"] > 0
    assert not res.extremities.found[3:].any()  # the tracker's detector leaves the feet out
    # against the A-pose at the true root and heading: the raised arms are what it misses
    a_pose = rest_pose(model.skeleton).copy()
    for dof in ("root_tx", "root_ty", "root_tz", "root_yaw"):
        a_pose[model.skeleton.dof_index(dof)] = params[model.skeleton.dof_index(dof)]
    base = np.linalg.norm(model.pose(a_pose[None])[1][0] - truth, axis=1)
    wrists = [model.joint_index("l_wrist"), model.joint_index("r_wrist")]
    figures = {"mean": errors[-1].mean(), "wrist": errors[-1][wrists].mean(),
               "a_pose_mean": base.mean(), "a_pose_wrist": base[wrists].mean()}
    # today 19 mm mean and 34 mm wrists; the A-pose 79 mm and 485 mm
    assert figures["mean"] < 0.04 and figures["mean"] < 0.5 * figures["a_pose_mean"], figures
    assert figures["wrist"] < 0.08 and figures["wrist"] < 0.3 * figures["a_pose_wrist"], figures
    # without maps (a foreground node that does not publish them) it runs as hpf-apo
    res = tracker.update(list(masks), STAMP0 + 10)
    assert res.state == "tracking" and res.extremities is None
    # the wrong number of maps is logged and ignored
    res = tracker.update(list(masks), STAMP0 + 11, [maps[0]])
    assert res.state == "tracking" and not res.extremities.found[:3].any()
