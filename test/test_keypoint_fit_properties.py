"""Properties of kf-hpf's keypoint fit, anthropometry and per-frame filter, each stated as
what the method promises, with keypoints made apart from the code under test where the
property is about how the two meet (the landmark offsets, the size corrections).

Scenes as in ``test_keypoint_first.py``: the tracking body posed by a retargeted CMU clip or
the ``arms_out`` pose, exact silhouettes in the cameras of ``config/rig_example.yaml`` at
320x240.
"""
from __future__ import annotations

import numpy as np
from test_body_tracking import clip_poses, subject_shape
from test_detector_driven import arms_out, scene
from test_keypoint_first import STAMP0, joints_of, keypoints, landmark_fit, named_points

from hmocap_ros.body import ENTITY_NAMES, entity_sizes
from hmocap_ros.body.anthropometry import apply_shape
from hmocap_ros.body.kinematics import end_site_positions, forward_kinematics
from hmocap_ros.body.skeleton import pose_to_local_rotations
from hmocap_ros.detection.detections import Detections
from hmocap_ros.params import from_flat
from hmocap_ros.tracking.body_tracker import BodyTracker, TrackerParams
from hmocap_ros.tracking.keypoint_anthropometry import MEASURES, KeypointShape, size_corrections
from hmocap_ros.tracking.keypoint_first import MAX_RESIDUAL, KeypointFirst, KeypointFirstParams
from hmocap_ros.tracking.keypoint_fit import ROBUST_SCALE, KeypointFit, load_keypoint_model


def moved_keypoint(det: Detections, label: str, offset, score: float | None = None) -> Detections:
    """``det`` with one keypoint moved by ``offset`` (m) and, given ``score``, scored so."""
    positions, scores = det.positions.copy(), det.scores.copy()
    k = det.labels.index(label)
    positions[k] += offset
    if score is not None:
        scores[k] = score
    return Detections("keypoints", det.labels, positions, scores)


def without(det: Detections, labels) -> Detections:
    keep = [i for i, lab in enumerate(det.labels) if lab not in labels]
    return Detections("keypoints", tuple(det.labels[i] for i in keep), det.positions[keep],
                      det.scores[keep])


def detector_landmarks(model, params: np.ndarray, rest, offsets: dict) -> Detections:
    """Where the detector's landmarks lie on a pose, by the body model's definition and
    apart from the fit's kinematics: each body point read off the forward kinematics by
    name (as :func:`~test_keypoint_first.named_points`), moved by its landmark's offset
    turned from the rest frame of the joint it hangs on (an end site's: its parent joint's)
    into that joint's posed frame (score 0.9)."""
    rot, root = pose_to_local_rotations(model.skeleton, params[None])
    transforms, joints = forward_kinematics(rot, root, rest.joints, model.parents)
    ends = end_site_positions(transforms, rest.end_sites, model.end_site_parents, rest.joints)
    joint_names, end_names = list(model.joint_names), list(model.end_site_names)
    out = {}

    def landmark(label, point, joint):
        out[label] = point + transforms[0, joint, :3, :3] @ offsets.get(label, np.zeros(3))

    def end(name):
        e = end_names.index(name)
        return ends[0, e], int(model.end_site_parents[e])

    top, head = end("head_top")
    landmark("head", 0.5 * (joints[0, joint_names.index("head")] + top), head)
    for side, s in (("left", "l"), ("right", "r")):
        tip, hand = end(f"{s}_hand_tip")
        landmark(f"{side}_hand", 0.5 * (joints[0, joint_names.index(f"{s}_wrist")] + tip), hand)
        landmark(f"{side}_foot", *end(f"{s}_toe"))
        for part in ("shoulder", "elbow", "wrist", "hip", "knee", "ankle"):
            j = joint_names.index(f"{s}_{part}")
            landmark(f"{side}_{part}", joints[0, j], j)
    labels = tuple(out)
    return Detections("keypoints", labels, np.array([out[k] for k in labels]),
                      np.full(len(labels), 0.9))


# ----------------------------------------------------------------------------- keypoint fit


def test_a_wrong_keypoint_pulls_the_fit_by_the_square_root_of_its_score(model):
    """Every keypoint right but the left wrist, 20 cm off, beyond Huber's threshold
    (ROBUST_SCALE keypoint stds), where its pull on the pose is the threshold times the
    square root of its score: scored 0.35 instead of 0.9, it moves the fitted wrist
    sqrt(0.35 / 0.9) = 0.62 times as far (within 0.05: the arm's stiffness is not quite
    linear over the 2-3 cm it is pulled)."""
    rest = apply_shape(model, None)
    params = arms_out(model)
    fit = KeypointFit(model)
    wrist = model.joint_index("l_wrist")
    true_wrist = joints_of(model, params[None], rest)[0, wrist]
    away = np.array([0.0, 0.2, 0.0])
    assert np.linalg.norm(away) / 0.03 > 2 * ROBUST_SCALE  # beyond the threshold at any score
    right = named_points(model, params, rest)
    pulls = {}
    for score in (0.9, 0.35):
        result = fit.fit(moved_keypoint(right, "left_wrist", away, score), rest, params)
        pulls[score] = np.linalg.norm(joints_of(model, result.params[None], rest)[0, wrist]
                                      - true_wrist)
    assert pulls[0.9] > 0.01, pulls  # the wrong keypoint does pull
    assert abs(pulls[0.35] / pulls[0.9] - np.sqrt(0.35 / 0.9)) < 0.05, pulls


def test_landmark_offsets_fit_keypoints_made_apart_from_the_fit_to_the_right_joints(model):
    """Noise-free landmarks of the shipped offsets (keypoint_model.json), made by
    :func:`detector_landmarks` and not by the fit's kinematics, a pose every tenth frame of
    the wave: the fit with the offsets puts the joints within 3 mm of the truth on average
    (its convergence), the fit without them 1 cm or more off (the offsets are 1-3 cm)."""
    rest = apply_shape(model, None)
    offsets = load_keypoint_model()["offsets"]
    assert max(np.linalg.norm(v) for v in offsets.values()) > 0.02
    poses = clip_poses(model, 300, 100)[::10]
    errors = {}
    for name, fit in (("offsets", landmark_fit(model)), ("none", KeypointFit(model))):
        prior, errs = None, []
        for truth in poses:
            result = fit.fit(detector_landmarks(model, truth, rest, offsets), rest, prior,
                             periods=10)
            errs.append(np.linalg.norm(joints_of(model, result.params[None], rest)[0]
                                       - joints_of(model, truth[None], rest)[0], axis=1).mean())
            prior = result.params
        errors[name] = float(np.mean(errs))
    assert errors["offsets"] < 0.003 and errors["none"] > 0.01, errors


# ----------------------------------------------------------------------------- anthropometry


def test_the_measures_are_the_keypoints_medians_divided_by_the_size_corrections(model):
    """With the shipped (non-unit) corrections, every measure is the median over the frames
    divided by its correction: the shoulders' distance and the hips' by hand, all of them
    against the same keypoints measured with unit corrections (exact up to rounding)."""
    corrections = size_corrections(load_keypoint_model()["size_corrections"])
    assert np.abs(corrections - 1.0).max() > 0.05
    shape = subject_shape()
    rest = apply_shape(model, shape)
    fit = KeypointFit(model)
    rng = np.random.default_rng(8)
    corrected = KeypointShape(model, corrections)
    plain = KeypointShape(model, np.ones(len(MEASURES)))
    frames = [keypoints(fit, params, rest, rng) for params in clip_poses(model, 0, 9, shape)]
    for det in frames:
        corrected.add(det)
        plain.add(det)
    for measure, a, b in (("clavicles", "left_shoulder", "right_shoulder"),
                          ("hip_width", "left_hip", "right_hip")):
        m = MEASURES.index(measure)
        median = np.median([np.linalg.norm(d.position(a) - d.position(b)) for d in frames])
        np.testing.assert_allclose(corrected.measures()[m], median / corrections[m], rtol=1e-12)
    np.testing.assert_allclose(corrected.measures(), plain.measures() / corrections, rtol=1e-12)


def test_size_corrections_that_model_the_keypoints_bias_give_the_true_shape(model):
    """Keypoints of a subject unlike the model spread 8 % about their centroid (a detector
    that sees every distance 8 % long), measured with corrections of 1.08: the shape comes
    within 1.5 cm of the truth on every entity the keypoints measure, as unbiased keypoints
    do (``test_anthropometry_from_keypoints_beats_the_model_and_the_stature_alone``); left
    uncorrected, the bias puts the entities up to 6 cm off."""
    shape = subject_shape()
    rest = apply_shape(model, shape)
    fit = KeypointFit(model)
    rng = np.random.default_rng(9)
    measured = KeypointShape(model, np.full(len(MEASURES), 1.08))
    for params in clip_poses(model, 0, 25, shape):
        det = keypoints(fit, params, rest, rng)
        centre = det.positions.mean(axis=0)
        measured.add(Detections("keypoints", det.labels,
                                centre + 1.08 * (det.positions - centre), det.scores))
    error = np.abs(entity_sizes(model, measured.shape()) - entity_sizes(model, shape))
    seen = [ENTITY_NAMES.index(m) for m in MEASURES if m != "head"]
    assert error[seen].max() < 0.015, dict(zip(ENTITY_NAMES, error.round(4)))


# ----------------------------------------------------------------------------- kf-hpf


def test_a_keypoint_the_fit_cannot_reach_makes_its_block_uncertain(model):
    """Confident keypoints (0.9): all right, every block is explained; the left wrist 20 cm
    from where the elbow and hand keypoints put it, the fit cannot reach it (a residual of
    over 10 cm, above MAX_RESIDUAL, the others' under 5 cm) and the left elbow's block, the
    one it decides, is uncertain, and no other."""
    rest = apply_shape(model, None)
    params = arms_out(model)
    kf = KeypointFirst(model, KeypointFirstParams(), 60, 0.5, None)
    rng = np.random.default_rng(10)
    right = named_points(model, params, rest)
    right = Detections("keypoints", right.labels,
                       right.positions + rng.normal(0.0, 0.005, right.positions.shape),
                       right.scores)
    fit = kf.fitter.fit(right, rest, params)
    assert fit.residuals.max() < MAX_RESIDUAL and kf.uncertain_blocks(fit, right) == []
    wrong = moved_keypoint(right, "left_wrist", [0.0, 0.2, 0.0])
    fit = kf.fitter.fit(wrong, rest, params)
    residual = fit.residuals[fit.labels.index("left_wrist")]
    assert kf.uncertain_blocks(fit, wrong) == ["l_elbow"], residual
    assert residual > 0.1 and np.delete(fit.residuals, fit.labels.index("left_wrist")).max() < 0.05


def test_a_kept_wrong_keypoint_out_of_reach_moves_the_pose_no_more_than_a_missing_one(model,
                                                                                     rig):
    """A track started on right keypoints; then the left wrist and hand keypoints 1 m above
    the truth, out of the arm's reach, kept by a check that asks more views than there are.
    Beyond CAP from every particle a keypoint adds the same cost to each: it moves the
    pose only through the fit's bounded (Huber) pull, which the silhouettes undo, so the
    wrist stays as near the truth as when the two keypoints are not detected at all (within
    5 cm: what is left of the fit's pull after the 60-particle filter, 0-2 cm, and the
    filter's spread between runs); uncapped, the term drags it 30 cm up."""
    params = arms_out(model)
    masks, _ = scene(model, rig, params)
    fit = landmark_fit(model)
    rest = apply_shape(model, None)
    wrist = model.joint_index("l_wrist")
    true_wrist = joints_of(model, params[None], rest)[0, wrist]
    hand = ("left_wrist", "left_hand")
    worst = {}
    for case in ("kept", "missing"):
        rng = np.random.default_rng(11)
        tracker = BodyTracker(model, rig, from_flat(TrackerParams, {
            "method": "kf-hpf", "filter.particles": 60, "startup.min_foreground": 30,
            "keypoints.shape_frames": 0, "keypoints.check_views": len(rig) + 1}),
            np.random.default_rng(0))
        errors = []
        for f in range(6):
            det = keypoints(fit, params, rest, rng, noise=0.005,
                            moved={k: np.array([0.0, 1.0, 0.0]) for k in hand} if f >= 2 else None)
            if f >= 2 and case == "missing":
                det = without(det, hand)
            res = tracker.update(list(masks), STAMP0 + f * 40_000_000, det)
            errors.append(np.linalg.norm(res.joints[wrist] - true_wrist))
            assert f < 2 or case == "missing" or set(tracker.last_keypoints[0]) >= set(hand)
        worst[case] = max(errors[2:])
    assert worst["kept"] < worst["missing"] + 0.05, worst
