"""Keypoint-first tracking: the body fitted to labelled 3D keypoints, the silhouettes' check
of the keypoints, anthropometry from keypoints and the kf-hpf tracker.

Scenes with known ground truth: the tracking body posed by a retargeted CMU clip (or the
``arms_out`` pose), exact silhouettes in the cameras of ``config/rig_example.yaml`` at
320x240, and "keypoints" that are the body model's points of the true pose
(:data:`~hmocap_ros.tracking.keypoint_fit.MODEL_POINTS`) with Gaussian noise, some of them
moved on purpose.
"""
from __future__ import annotations

import numpy as np
import pytest
from test_body_tracking import clip_poses, render_masks, scaled_to_height, subject_shape
from test_detector_driven import arms_out

from hmocap_ros.body import ENTITY_NAMES, entity_sizes, sample_pose
from hmocap_ros.body.anthropometry import apply_shape
from hmocap_ros.body.kinematics import end_site_positions, forward_kinematics
from hmocap_ros.body.pose_points import PosePoints
from hmocap_ros.body.skeleton import pose_to_local_rotations
from hmocap_ros.detection.detections import Detections
from hmocap_ros.geometry.projection import project_batch
from hmocap_ros.params import from_flat
from hmocap_ros.render import render_silhouettes
from hmocap_ros.tracking.body_fitness import SilhouetteFitness
from hmocap_ros.tracking.body_tracker import BodyTracker, TrackerParams
from hmocap_ros.tracking.keypoint_anthropometry import MEASURES, KeypointShape
from hmocap_ros.tracking.keypoint_first import KeypointFirstParams, contradicted
from hmocap_ros.tracking.keypoint_fit import KeypointFit, load_keypoint_model

STAMP0 = 1_700_000_000_000_000_000


def landmark_fit(model) -> KeypointFit:
    """A fit with the shipped landmark offsets: its body points are where the detector's
    keypoints lie on the true pose, as the tracker expects them."""
    return KeypointFit(model, offsets=load_keypoint_model()["offsets"])


def named_points(model, params: np.ndarray, rest) -> Detections:
    """The keypoints of a pose read off the body by name, independently of the fit's own
    mapping: ``left_wrist`` is the joint ``l_wrist``, ``left_hand`` the midpoint of
    ``l_wrist`` and ``l_hand_tip``, ``head`` of ``head`` and ``head_top``, ``left_foot`` the
    end site ``l_toe`` (score 0.9)."""
    joints, ends = PosePoints.of(model, rest).points(params[None])
    joint = {n: joints[0, i] for i, n in enumerate(model.joint_names)}
    end = {n: ends[0, i] for i, n in enumerate(model.end_site_names)}
    out = {"head": 0.5 * (joint["head"] + end["head_top"])}
    for side, s in (("left", "l"), ("right", "r")):
        out[f"{side}_hand"] = 0.5 * (joint[f"{s}_wrist"] + end[f"{s}_hand_tip"])
        out[f"{side}_foot"] = end[f"{s}_toe"]
        for part in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle"):
            out[f"{side}_{part}"] = joint[f"{s}_{part}"]
    labels = tuple(out)
    return Detections("keypoints", labels, np.array([out[k] for k in labels]),
                      np.full(len(labels), 0.9))


def keypoints(fit: KeypointFit, params: np.ndarray, rest, rng, noise=0.015, score=0.9,
              moved: dict | None = None) -> Detections:
    """The body points of a pose as labelled keypoints, with noise; ``moved``: label -> offset."""
    points = fit.body_points(params[None], rest)[0] + rng.normal(0.0, noise, (len(fit.labels), 3))
    for label, offset in (moved or {}).items():
        points[fit.labels.index(label)] += offset
    return Detections("keypoints", fit.labels, points, np.full(len(fit.labels), score))


def joints_of(model, params, rest):
    return PosePoints.of(model, rest).points(params)[0]


def test_pose_points_equal_the_forward_kinematics(model):
    rng = np.random.default_rng(0)
    poses = sample_pose(model.skeleton, rng, 20)
    rest = apply_shape(model, subject_shape())
    joints, ends = PosePoints.of(model, rest).points(poses)
    rot, root = pose_to_local_rotations(model.skeleton, poses)
    transforms, expected = forward_kinematics(rot, root, rest.joints, model.parents)
    np.testing.assert_allclose(joints, expected, atol=1e-12)
    np.testing.assert_allclose(ends, end_site_positions(transforms, rest.end_sites,
                                                        model.end_site_parents, rest.joints),
                               atol=1e-12)


def test_fit_follows_noisy_keypoints_of_a_clip(model):
    """Keypoints with 1.5 cm of noise on every axis, a pose every fifth frame of the wave
    (0.2 s apart): the fitted joints stay within 2.5 cm of the truth on average, from the
    first frame (no prior) on; the prior alone (the last fit) is twice as far off."""
    fit = KeypointFit(model)
    rest = apply_shape(model, None)
    poses = clip_poses(model, 300, 100)[::5]
    rng = np.random.default_rng(1)
    prior, errors, still = None, [], []
    for truth in poses:
        det = named_points(model, truth, rest)
        det = Detections("keypoints", det.labels,
                         det.positions + rng.normal(0.0, 0.015, det.positions.shape), det.scores)
        result = fit.fit(det, rest, prior, periods=5)
        true_joints = joints_of(model, truth[None], rest)[0]
        errors.append(np.linalg.norm(joints_of(model, result.params[None], rest)[0]
                                     - true_joints, axis=1).mean())
        if prior is not None:
            still.append(np.linalg.norm(joints_of(model, prior[None], rest)[0]
                                        - true_joints, axis=1).mean())
        prior = result.params
    assert np.mean(errors) < 0.025 and errors[0] < 0.04, errors
    assert np.mean(errors[1:]) < np.mean(still) / 2, (np.mean(errors), np.mean(still))
    assert fit.fit(Detections.empty("keypoints"), rest) is None


@pytest.fixture(scope="module")
def arms_scene(model, rig):
    params = arms_out(model)
    verts, _ = model.pose(params[None])
    uv, _ = project_batch(verts, *rig.arrays())
    masks = render_silhouettes(uv, model.faces, rig[0].height, rig[0].width)[0] * np.uint8(255)
    return params, masks


def test_the_silhouettes_drop_a_wrist_put_in_empty_space(model, rig, arms_scene):
    """Every keypoint right but the left wrist and hand, 35 cm off into the air where no view
    shows anything: the check drops those two and nothing else; the tracker then puts the
    wrist within 6 cm of the truth, where the keypoints alone drag it 15+ cm away."""
    params, masks = arms_scene
    fitness = SilhouetteFitness(model, rig, 0.5)
    obs = fitness.observe(list(masks))
    fit = landmark_fit(model)
    rest = fitness.rest(None)
    rng = np.random.default_rng(2)
    away = {"left_wrist": np.array([0.0, 0.35, -0.1]), "left_hand": np.array([0.0, 0.35, -0.1])}
    wrong = keypoints(fit, params, rest, rng, noise=0.005, moved=away)
    named = dict(zip(wrong.labels, wrong.positions))
    assert sorted(contradicted(named, obs, KeypointFirstParams())) == ["left_hand", "left_wrist"]
    right = keypoints(fit, params, rest, rng, noise=0.005)
    assert contradicted(dict(zip(right.labels, right.positions)), obs, KeypointFirstParams()) == []
    names = list(model.joint_names)
    wrist = names.index("l_wrist")
    truth = joints_of(model, params[None], rest)[0]
    alone = fit.fit(wrong, rest, params)
    dragged = np.linalg.norm(joints_of(model, alone.params[None], rest)[0][wrist] - truth[wrist])
    tracker = BodyTracker(model, rig, from_flat(TrackerParams, {
        "method": "kf-hpf", "filter.particles": 120,
        "startup.min_foreground": 30, "keypoints.shape_frames": 0}), np.random.default_rng(0))
    for f in range(4):
        res = tracker.update(list(masks), STAMP0 + f * 40_000_000,
                             keypoints(fit, params, rest, rng, noise=0.005, moved=away))
    assert res.state == "tracking"
    assert set(tracker.last_keypoints[1]) == {"left_wrist", "left_hand"}
    assert "l_elbow" in tracker.last_keypoints[2]
    error = np.linalg.norm(res.joints[wrist] - truth[wrist])
    assert dragged > 0.15 and error < 0.06, (dragged, error)


def test_kf_hpf_starts_from_keypoints_and_runs_on_silhouettes_without_them(model, rig,
                                                                           arms_scene):
    """A track starts on the first frame set with keypoints (no silhouette start-up): a pose
    at once, within 3 cm of the truth; a frame set without keypoints runs the silhouette
    filter and says why; with keypoints back, keypoint-first again."""
    params, masks = arms_scene
    fit = landmark_fit(model)
    rest = apply_shape(model, None)
    rng = np.random.default_rng(3)
    tracker = BodyTracker(model, rig, from_flat(TrackerParams, {
        "method": "kf-hpf", "filter.particles": 60,
        "startup.min_foreground": 30, "keypoints.shape_frames": 0}), np.random.default_rng(0))
    truth = joints_of(model, params[None], rest)[0]
    res = tracker.update(list(masks), STAMP0, keypoints(fit, params, rest, rng, noise=0.005))
    assert res.state == "tracking" and res.has_pose
    assert np.linalg.norm(res.joints - truth, axis=1).mean() < 0.03
    assert res.confidence is not None and res.confidence.shape == (len(truth),)
    res = tracker.update(list(masks), STAMP0 + 40_000_000, None)
    assert res.state == "tracking" and tracker.fallback_reason == "no keypoints in the frame set"
    res = tracker.update(list(masks), STAMP0 + 80_000_000,
                         keypoints(fit, params, rest, rng, noise=0.005))
    assert tracker.fallback_reason == "" and res.timings["fit"] > 0
    assert np.linalg.norm(res.joints - truth, axis=1).mean() < 0.04
    # a budget that pays for no particle: the fit is the pose, at once (one evaluation: the
    # fit cost of the estimate, which judges the track)
    res = tracker.update(list(masks), STAMP0 + 120_000_000,
                         keypoints(fit, params, rest, rng, noise=0.005), budget_s=0.0)
    assert res.layers == () and res.timings["evaluations"] == 1 and res.has_pose


def test_anthropometry_from_keypoints_beats_the_model_and_the_stature_alone(model):
    """A second of noisy keypoints of a subject unlike the model: every entity the keypoints
    measure comes within 1.5 cm, and the mean entity error is below both the model's own
    proportions (31 mm) and the model scaled to the subject's true height (15 mm)."""
    shape = subject_shape()
    rest = apply_shape(model, shape)
    fit = KeypointFit(model)
    rng = np.random.default_rng(4)
    measured = KeypointShape(model, np.ones(len(MEASURES)))
    for params in clip_poses(model, 0, 25, shape):
        measured.add(keypoints(fit, params, rest, rng))
    estimate = measured.shape()
    truth = entity_sizes(model, shape)
    error = np.abs(entity_sizes(model, estimate) - truth)
    neutral = np.abs(entity_sizes(model, None) - truth)
    stature = np.abs(entity_sizes(model, scaled_to_height(model, shape)) - truth)
    seen = [ENTITY_NAMES.index(m) for m in MEASURES if m != "head"]
    assert error[seen].max() < 0.015, dict(zip(ENTITY_NAMES, error.round(4)))
    assert error.mean() < 0.5 * stature.mean() and error.mean() < 0.25 * neutral.mean()


def test_the_keypoints_place_a_forearm_the_silhouettes_lost(model, rig):
    """The left forearm and hand are missing from every mask (a sleeve the colour of the
    wall) and the left elbow has no keypoint, so the left arm's blocks are uncertain and
    filtered: the silhouettes cannot say where the forearm is, the wrist and hand keypoints
    can. With the check asking more contradicting views than there are (so that it keeps
    them), their term in the layers holds the wrist within a centimetre or two of the truth
    on every frame; the silhouettes alone let the forearm drift towards the body."""
    params = arms_out(model)
    verts, _ = model.pose(np.atleast_2d(params))
    uv, _ = project_batch(verts, *rig.arrays())
    lost = np.isin(model.vertex_part, [model.joint_index("l_elbow"), model.joint_index("l_wrist")])
    kept = model.faces[~lost[model.faces].any(axis=1)]
    masks = render_silhouettes(uv, kept, rig[0].height, rig[0].width)[0] * np.uint8(255)
    fit = landmark_fit(model)
    rest = apply_shape(model, None)
    rng = np.random.default_rng(5)
    tracker = BodyTracker(model, rig, from_flat(TrackerParams, {
        "method": "kf-hpf", "filter.particles": 120,
        "startup.min_foreground": 30, "keypoints.shape_frames": 0,
        "keypoints.check_views": len(rig) + 1}), np.random.default_rng(0))
    truth = joints_of(model, params[None], rest)[0]
    wrist = model.joint_index("l_wrist")
    errors = []
    for f in range(8):
        det = keypoints(fit, params, rest, rng, noise=0.005)
        keep = [i for i, lab in enumerate(det.labels) if lab != "left_elbow"]
        det = Detections("keypoints", tuple(det.labels[i] for i in keep), det.positions[keep],
                         det.scores[keep])
        res = tracker.update(list(masks), STAMP0 + f * 40_000_000, det)
        errors.append(np.linalg.norm(res.joints[wrist] - truth[wrist]))
        assert f == 0 or ("l_shoulder" in tracker.last_keypoints[2] and res.layers)
    # 6 mm on average; on the silhouettes alone the forearm drifts 2-5 cm towards the body
    assert np.mean(errors[1:]) < 0.015, errors


def test_the_tracker_measures_the_shape_of_a_new_track_from_its_keypoints(model, rig):
    """kf-hpf's start: the shape of a subject unlike the model, solved from the keypoints of the
    track's first frame sets, is nearer the truth than the model scaled to the subject's true
    height, on the mean over the entities; the track's fit uses it."""
    shape = subject_shape()
    rest = apply_shape(model, shape)
    fit = landmark_fit(model)
    rng = np.random.default_rng(6)
    poses = clip_poses(model, 0, 8, shape)
    masks, _ = render_masks(model, rig, poses, shape)
    tracker = BodyTracker(model, rig, from_flat(TrackerParams, {
        "method": "kf-hpf", "filter.particles": 40,
        "startup.min_foreground": 30, "keypoints.shape_frames": 8}), np.random.default_rng(0))
    # these keypoints are the model's own points: no bias of the network's to correct
    tracker.keypoint_shape.corrections = np.ones(len(MEASURES))
    for f, params in enumerate(poses):
        tracker.update(list(masks[f]), STAMP0 + f * 40_000_000,
                       keypoints(fit, params, rest, rng, noise=0.01))
    truth = entity_sizes(model, shape)
    error = np.abs(entity_sizes(model, tracker.shape) - truth).mean()
    stature = np.abs(entity_sizes(model, scaled_to_height(model, shape)) - truth).mean()
    assert len(tracker.keypoint_shape) == 8 and error < 0.7 * stature, (error, stature)


def test_joints_without_keypoints_keep_their_prediction_with_a_low_confidence(model, rig,
                                                                            arms_scene):
    """The legs' keypoints gone after the first frame sets (the person's legs out of the
    cameras' view, say): the legs stay where they were (no jump) and their confidence drops
    below 0.1, while the seen joints keep theirs."""
    params, masks = arms_scene
    fit = landmark_fit(model)
    rest = apply_shape(model, None)
    rng = np.random.default_rng(7)
    tracker = BodyTracker(model, rig, from_flat(TrackerParams, {
        "method": "kf-hpf", "filter.particles": 40,
        "startup.min_foreground": 30, "keypoints.shape_frames": 0}), np.random.default_rng(0))
    legs = ("left_knee", "left_ankle", "left_foot", "right_knee", "right_ankle", "right_foot")
    knees = [model.joint_index("l_knee"), model.joint_index("r_knee")]
    for f in range(3):
        res = tracker.update(list(masks), STAMP0 + f * 40_000_000,
                             keypoints(fit, params, rest, rng, noise=0.005))
    before = res.joints[knees].copy()
    det = keypoints(fit, params, rest, rng, noise=0.005)
    keep = [i for i, lab in enumerate(det.labels) if lab not in legs]
    det = Detections("keypoints", tuple(det.labels[i] for i in keep), det.positions[keep],
                     det.scores[keep])
    res = tracker.update(list(masks), STAMP0 + 3 * 40_000_000, det, budget_s=0.0)
    assert np.linalg.norm(res.joints[knees] - before, axis=1).max() < 0.03
    confidence = res.confidence
    assert confidence[knees].max() < 0.1 and confidence[model.joint_index("pelvis")] > 0.5


def test_kf_hpf_waits_for_keypoints_to_start_before_the_silhouette_start_up(model, rig,
                                                                           arms_scene):
    """Given a keypoint detector's frame sets without keypoints, a new track waits up to
    KEYPOINT_START_WAIT_S of stamps for keypoints (no silhouette start-up, which costs
    seconds per frame), then starts from the silhouettes; without a detector (None) the
    silhouette start-up runs at once."""
    from hmocap_ros.tracking.body_tracker import KEYPOINT_START_WAIT_S

    params, masks = arms_scene
    settings = {"method": "kf-hpf", "filter.particles": 60, "startup.particles": 30,
                "startup.frames": 1, "startup.min_foreground": 30, "keypoints.shape_frames": 0}
    tracker = BodyTracker(model, rig, from_flat(TrackerParams, settings), np.random.default_rng(0))
    period = 40_000_000
    waited = int(KEYPOINT_START_WAIT_S * 1e9) // period
    for f in range(waited):
        res = tracker.update(list(masks), STAMP0 + f * period, Detections.empty("keypoints"))
        assert res.state == "searching" and not res.has_pose and res.timings["hull"] == 0
    res = tracker.update(list(masks), STAMP0 + waited * period, Detections.empty("keypoints"))
    assert res.state != "searching" and res.timings["hull"] > 0
    # keypoints that come while it waits start the track at once
    tracker.reset()
    fit = landmark_fit(model)
    rest = apply_shape(model, None)
    tracker.update(list(masks), STAMP0, Detections.empty("keypoints"))
    res = tracker.update(list(masks), STAMP0 + period,
                         keypoints(fit, params, rest, np.random.default_rng(3), noise=0.005))
    assert res.state == "tracking" and res.has_pose and res.timings["hull"] == 0
    # no detector: the silhouette start-up at once
    fresh = BodyTracker(model, rig, from_flat(TrackerParams, settings), np.random.default_rng(0))
    res = fresh.update(list(masks), STAMP0, None)
    assert res.state != "searching" and res.timings["hull"] > 0


def test_live_track_goes_on_from_its_prediction_without_keypoints_its_confidence_falling(
        model, rig, arms_scene):
    """Live (a budget given), a keypoint-first track whose keypoints stop (the keypoint stage
    late or down) publishes its prediction, no silhouette filter run, every joint's confidence
    falling set after set; keypoints back, the fit takes over again. A live tracker without a
    track never starts one from the silhouettes, however long the keypoints stay away."""
    params, masks = arms_scene
    fit = landmark_fit(model)
    rest = apply_shape(model, None)
    rng = np.random.default_rng(11)
    settings = {"method": "kf-hpf", "filter.particles": 40, "startup.particles": 30,
                "startup.frames": 1, "startup.min_foreground": 30, "keypoints.shape_frames": 0}
    tracker = BodyTracker(model, rig, from_flat(TrackerParams, settings), np.random.default_rng(0))
    period = 40_000_000
    for f in range(3):
        res = tracker.update(list(masks), STAMP0 + f * period,
                             keypoints(fit, params, rest, rng, noise=0.005), budget_s=0.0)
    fitted, held = res.confidence.copy(), res.joints.copy()
    confidences = []
    for f in range(3, 9):
        res = tracker.update(list(masks), STAMP0 + f * period, None, budget_s=0.0)
        assert res.state == "tracking" and res.has_pose and res.layers == ()
        assert res.timings["hull"] == 0 and res.timings["filter"] == 0
        assert np.linalg.norm(res.joints - held, axis=1).max() < 0.03
        confidences.append(res.confidence)
    assert tracker.fallback_reason.startswith("no keypoints")
    assert (confidences[0] < fitted).all()
    assert all((b < a).all() for a, b in zip(confidences, confidences[1:]))
    res = tracker.update(list(masks), STAMP0 + 9 * period,
                         keypoints(fit, params, rest, rng, noise=0.005), budget_s=0.0)
    assert tracker.fallback_reason == "" and res.timings["fit"] > 0
    assert res.confidence.mean() > confidences[-1].mean() + 0.2
    # no track and no keypoints, live: no silhouette start-up
    fresh = BodyTracker(model, rig, from_flat(TrackerParams, settings), np.random.default_rng(0))
    for f in range(0, 80, 8):
        res = fresh.update(list(masks), STAMP0 + f * period, None, budget_s=0.05)
        assert res.state == "searching" and res.timings["hull"] == 0
