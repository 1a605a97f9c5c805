"""The landmark network (hmocap_ros.detection.keypoint_network) and the whole keypoint detector.

The model file: shipped, checked against its documented sha256, a missing or corrupt file
raises ModelFileError naming it. The landmarks: on a simulated room rendered here (4 cameras,
640x480, a subject with one arm raised sideways and the other elbow bent), the network's
joints land near the projected truth, and KeypointDetector puts the 3D keypoints near the
body model's joints and end-effectors with the sides right.
"""
from __future__ import annotations

import hashlib
import logging
import re

import numpy as np
import pytest

from hmocap_ros.camera_model import project_points
from hmocap_ros.detection import (DEFAULT_MODEL, KeypointDetector, KeypointParams, ModelFileError,
                                  PoseLandmarkNetwork, roi_box)
from hmocap_ros.detection.keypoint_network import (LANDMARK_NAMES, crop_transform,
                                                   refine_from_heatmap, tflite_available)

needs_tflite = pytest.mark.skipif(not tflite_available(), reason="this OpenCV has no TFLite reader (before 4.8, "
                                  "e.g. Ubuntu 24.04's 4.6): the keypoint detector is unavailable")

# landmark -> the body model's joint of the same place
JOINTS = {"left_shoulder": "l_shoulder", "right_shoulder": "r_shoulder", "left_elbow": "l_elbow",
          "right_elbow": "r_elbow", "left_wrist": "l_wrist", "right_wrist": "r_wrist",
          "left_knee": "l_knee", "right_knee": "r_knee", "left_ankle": "l_ankle",
          "right_ankle": "r_ankle"}


@pytest.fixture(scope="module")
def network():
    return PoseLandmarkNetwork()


@pytest.fixture(scope="module")
def scene():
    """A rendered frame set: rig, RGB images, silhouettes, {joint or end site: room position}."""
    from hmocap_ros.body import load_body_model
    from hmocap_ros.sim.appearance import dress, sample_appearance
    from hmocap_ros.sim.mocap_dataset import make_rig
    from hmocap_ros.sim.mocap_render import FrameState, MocapRenderer, RenderOptions
    from hmocap_ros.sim.room import build_room

    rng = np.random.default_rng(3)
    rig = make_rig(4, 640, 480)
    room = build_room(rng)
    full = load_body_model("hands", "full")
    look = dress(full, sample_appearance(rng))
    renderer = MocapRenderer(rig, room, [(full.faces, look)], RenderOptions(noise=False))
    params = full.rest_pose()[None]
    params[:, full.skeleton.dof_index("l_shoulder_abd")] = 0.6
    params[:, full.skeleton.dof_index("r_elbow_flex")] = 1.0
    posed = full.forward(params)
    frame = renderer.render(FrameState(people=(look.with_hair(posed.vertices[0], full.faces),)))
    truth = dict(zip(map(str, full.joint_names), posed.joints[0]))
    truth.update(zip(map(str, full.end_site_names), posed.end_sites[0]))
    return rig, list(frame.images), list(frame.silhouettes), truth


def test_the_shipped_model_is_the_documented_file():
    sources = (DEFAULT_MODEL.parent / "SOURCES.md").read_text()
    documented = re.search(r"\*\*sha256\*\*: `([0-9a-f]{64})`", sources).group(1)
    assert hashlib.sha256(DEFAULT_MODEL.read_bytes()).hexdigest() == documented


def test_missing_or_corrupt_model_file_names_the_file(tmp_path):
    missing = tmp_path / "nowhere" / "pose_landmark_full.tflite"
    with pytest.raises(ModelFileError, match=re.escape(str(missing))) as err:
        PoseLandmarkNetwork(missing)
    assert "not found" in str(err.value) and "SOURCES.md" in str(err.value)
    junk = tmp_path / "junk.tflite"
    junk.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    truncated = tmp_path / "truncated.tflite"
    truncated.write_bytes(DEFAULT_MODEL.read_bytes()[:200_000])
    for bad in (junk, truncated):
        with pytest.raises(ModelFileError, match=re.escape(str(bad))):
            PoseLandmarkNetwork(bad)
    with pytest.raises(ModelFileError, match=re.escape(str(missing))):
        KeypointDetector([], model_path=missing)


@needs_tflite
def test_network_matches_tflite_on_the_same_input(network):
    """Pose presence and visibilities of a fixed 256x256 pattern, as TFLite (LiteRT) computes
    them from the same pixels as float32 RGB in [0, 1] (the model's input range)."""
    y, x, c = np.mgrid[0:256, 0:256, 0:3]
    crop = ((x * 3 + y * 5 + c * 70) % 256).astype(np.uint8)
    _, visibility, _, score = network.infer(crop)
    tflite = [0.1395, 0.2286, 0.2698, 0.2965, 0.2088, 0.2280, 0.2356, 0.2754, 0.3313, 0.3470,
              0.3341, 0.9283]
    assert score == pytest.approx(0.13359, abs=2e-3)
    np.testing.assert_allclose(visibility[:12], tflite, atol=2e-3)


def test_heatmap_refinement_moves_a_confident_landmark_to_the_peak():
    rows, cols = np.mgrid[0:64, 0:64]
    heat = np.full((2, 64, 64), -20.0)  # logits: nothing anywhere
    heat[0] = 8.0 - 0.5 * ((rows - 20.0) ** 2 + (cols - 31.0) ** 2)  # a sharp peak at cell (20, 31)
    start = np.array([[31.5 * 4, 20.6 * 4], [100.0, 100.0]])  # input pixels, 4 per cell
    refined = refine_from_heatmap(start, heat)
    np.testing.assert_allclose(refined[0], [31.0 * 4, 20.0 * 4], atol=0.05)
    np.testing.assert_array_equal(refined[1], start[1])  # below the confidence: kept


def test_crop_transform_is_the_square_about_the_box():
    matrix, scale = crop_transform((100.0, 50.0, 200.0, 250.0))  # 100 x 200: side 200
    assert scale == pytest.approx(256 / 200)
    corners = np.array([[50.0, 50.0, 1.0], [250.0, 250.0, 1.0]]) @ matrix.T
    np.testing.assert_allclose(corners, [[0.0, 0.0], [256.0, 256.0]], atol=1e-9)
    turned, _ = crop_transform((100.0, 50.0, 200.0, 250.0), rotation=np.pi / 2)
    # turned a quarter counter-clockwise: the image's right (+u) becomes the crop's up (-v)
    centre = np.array([150.0, 150.0, 1.0])
    np.testing.assert_allclose(turned @ centre, [128.0, 128.0], atol=1e-9)
    np.testing.assert_allclose(turned @ (centre + (100.0, 0.0, 0.0)), [128.0, 0.0], atol=1e-9)
    with pytest.raises(ValueError):
        crop_transform((10.0, 10.0, 10.0, 10.0))


@needs_tflite
def test_landmarks_land_on_the_rendered_body(network, scene):
    rig, images, silhouettes, truth = scene
    index = [LANDMARK_NAMES.index(n) for n in JOINTS]
    expected = project_points(list(rig), np.array([truth[j] for j in JOINTS.values()])).pixels
    errors = []
    for v, camera in enumerate(rig):
        box = roi_box(camera, silhouettes[v], None, KeypointParams())
        view = network.run(images[v], box)
        assert view.xy.shape == (39, 2) and view.score > 0.9
        assert np.all((view.visibility >= 0) & (view.visibility <= 1))
        errors.append(np.linalg.norm(view.xy[index] - expected[v], axis=1))
        # another crop of the same person: the landmarks stay in image pixels
        x0, y0, x1, y1 = box
        shifted = network.run(images[v], (x0 + 12.0, y0 - 8.0, x1 + 30.0, y1 + 10.0))
        assert np.median(np.linalg.norm(shifted.xy[:33] - view.xy[:33], axis=1)) < 4.0
        turned = network.run(images[v], box, rotation=0.3)
        assert np.median(np.linalg.norm(turned.xy[:33] - view.xy[:33], axis=1)) < 5.0
    errors = np.array(errors)  # (views, joints) pixels
    assert np.median(errors) < 6.0, np.round(errors)
    assert np.mean(errors < 15.0) > 0.9, np.round(errors)


@needs_tflite
def test_detector_finds_the_labelled_keypoints_in_3d(scene, caplog):
    rig, images, silhouettes, truth = scene
    detector = KeypointDetector(rig)
    try:
        result = detector.detect(images, silhouettes)
        targets = {label: truth[joint] for label, joint in JOINTS.items()}
        targets.update(head=0.5 * (truth["head"] + truth["head_top"]),
                       left_hand=0.5 * (truth["l_wrist"] + truth["l_hand_tip"]),
                       right_hand=0.5 * (truth["r_wrist"] + truth["r_hand_tip"]),
                       left_foot=truth["l_toe"], right_foot=truth["r_toe"])
        found = result.as_dict()
        for label, target in targets.items():
            assert label in found, label
            error = np.linalg.norm(found[label] - target)
            assert error < 0.08, f"{label} off by {1000 * error:.0f} mm"
        assert np.all(result.scores > 0.5) and np.all(result.views_used >= 3)
        assert set(detector.last_timings) >= {"roi", "network", "triangulation", "total"}
        assert sum(k.startswith("network/") for k in detector.last_timings) == 4
        # a missing view, an image of the wrong size and an empty mask are skipped, once logged
        caplog.set_level(logging.WARNING, logger="hmocap_ros.detection.keypoint_detector")
        views = [None, images[1][:240], images[2], images[3]]
        masks = [silhouettes[0], silhouettes[1], silhouettes[2], np.zeros_like(silhouettes[3])]
        for _ in range(2):
            partial = detector.detect(views, masks, previous=found)
        assert len([r for r in caplog.records if "skips camera" in r.message]) == 3
        assert partial.labels == ()  # one view left
        with_previous = detector.detect(images, [None] * 4, previous=found)
        assert np.linalg.norm(with_previous.as_dict()["left_hand"] - targets["left_hand"]) < 0.08
    finally:
        detector.close()
