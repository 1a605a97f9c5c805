"""The landmark network (hmocap_ros.detection.keypoint_network), the pose detector
(pose_detector) and the whole keypoint detector.

The model files: shipped, checked against their documented sha256, a missing, corrupt or wrong
file raises ModelFileError naming it. The network on LiteRT gives the outputs of an independent
TFLite implementation (OpenCV dnn, where it reads TFLite) on the same input. On a simulated room
rendered here (4 cameras, 640x480, a subject with one arm raised sideways and the other elbow
bent): the detector finds the person with the crop upright and around the body, and turned
with the image; the network's joints land near the projected truth; KeypointDetector puts the
3D keypoints near the body model's joints and end-effectors with the sides right, and its
views' crops follow their own landmarks after the first frame set, also of a person walking.
"""
from __future__ import annotations

import hashlib
import logging
import re
from types import SimpleNamespace

import numpy as np
import pytest

from hmocap_ros.detection import (
    DEFAULT_MODEL,
    KeypointDetector,
    KeypointParams,
    ModelFileError,
    PoseDetector,
    PoseLandmarkNetwork,
    Roi,
    box_roi,
    foreground_box,
)
from hmocap_ros.detection.keypoint_network import LANDMARK_NAMES, refine_from_heatmap
from hmocap_ros.detection.keypoint_roi import alignment_roi, crop_transform
from hmocap_ros.detection.pose_detector import DEFAULT_DETECTOR_MODEL
from hmocap_ros.geometry import project_points

# landmark -> the body model's joint of the same place
JOINTS = {"left_shoulder": "l_shoulder", "right_shoulder": "r_shoulder", "left_elbow": "l_elbow",
          "right_elbow": "r_elbow", "left_wrist": "l_wrist", "right_wrist": "r_wrist",
          "left_knee": "l_knee", "right_knee": "r_knee", "left_ankle": "l_ankle",
          "right_ankle": "r_ankle"}


@pytest.fixture(scope="module")
def network():
    return PoseLandmarkNetwork()


@pytest.fixture(scope="module")
def studio():
    """The simulated room's renderer and its subject: ``render(params)`` gives per pose (N, D)
    of the body model a frame set: RGB images, silhouettes, {joint or end site: room
    position}; ``pose`` the subject's pose (one arm raised sideways, the other elbow bent)."""
    from hmocap_ros.body import load_body_model
    from hmocap_sim.appearance import dress, sample_appearance
    from hmocap_sim.mocap_dataset import make_rig
    from hmocap_sim.mocap_render import FrameState, MocapRenderer, RenderOptions
    from hmocap_sim.room import build_room

    rng = np.random.default_rng(3)
    rig = make_rig(4, 640, 480)
    room = build_room(rng)
    full = load_body_model("hands", "full")
    look = dress(full, sample_appearance(rng))
    renderer = MocapRenderer(rig, room, [(full.faces, look)], RenderOptions(noise=False))
    pose = full.rest_pose()
    pose[full.skeleton.dof_index("l_shoulder_abd")] = 0.6
    pose[full.skeleton.dof_index("r_elbow_flex")] = 1.0

    def render(params):
        posed = full.forward(np.atleast_2d(params))
        for k in range(len(posed.joints)):
            frame = renderer.render(FrameState(people=(look.with_hair(posed.vertices[k], full.faces),)))
            truth = dict(zip(map(str, full.joint_names), posed.joints[k]))
            truth.update(zip(map(str, full.end_site_names), posed.end_sites[k]))
            yield list(frame.images), list(frame.silhouettes), truth

    return SimpleNamespace(rig=rig, model=full, pose=pose, render=render)


@pytest.fixture(scope="module")
def scene(studio):
    """A rendered frame set: rig, RGB images, silhouettes, {joint or end site: room position}."""
    images, silhouettes, truth = next(studio.render(studio.pose))
    return studio.rig, images, silhouettes, truth


def keypoint_targets(truth: dict) -> dict:
    """label -> room position of the body's place that each labelled keypoint marks."""
    targets = {label: truth[joint] for label, joint in JOINTS.items()}
    targets.update(head=0.5 * (truth["head"] + truth["head_top"]),
                   left_hand=0.5 * (truth["l_wrist"] + truth["l_hand_tip"]),
                   right_hand=0.5 * (truth["r_wrist"] + truth["r_hand_tip"]),
                   left_foot=truth["l_toe"], right_foot=truth["r_toe"])
    return targets


def test_the_shipped_models_are_the_documented_files():
    sources = (DEFAULT_MODEL.parent / "SOURCES.md").read_text()
    for model in (DEFAULT_MODEL, DEFAULT_DETECTOR_MODEL):
        section = sources[sources.index(f"## {model.name}"):]
        documented = re.search(r"\*\*sha256\*\*: `([0-9a-f]{64})`", section).group(1)
        assert hashlib.sha256(model.read_bytes()).hexdigest() == documented, model.name


def test_missing_corrupt_or_wrong_model_file_names_the_file(tmp_path):
    missing = tmp_path / "nowhere" / "pose_landmark_full.tflite"
    with pytest.raises(ModelFileError, match=re.escape(str(missing))) as err:
        PoseLandmarkNetwork(missing)
    assert "not found" in str(err.value) and "SOURCES.md" in str(err.value)
    assert "\n" not in str(err.value)
    junk = tmp_path / "junk.tflite"
    junk.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    truncated = tmp_path / "truncated.tflite"
    truncated.write_bytes(DEFAULT_MODEL.read_bytes()[:200_000])
    for bad in (junk, truncated, tmp_path):
        for model in (PoseLandmarkNetwork, PoseDetector):
            with pytest.raises(ModelFileError, match=re.escape(str(bad))) as err:
                model(bad)
            assert "\n" not in str(err.value)
    with pytest.raises(ModelFileError, match="another model"):  # each the other's file
        PoseLandmarkNetwork(DEFAULT_DETECTOR_MODEL)
    with pytest.raises(ModelFileError, match="another model"):
        PoseDetector(DEFAULT_MODEL)
    with pytest.raises(ModelFileError, match=re.escape(str(missing))):
        KeypointDetector([], model_path=missing)
    with pytest.raises(ModelFileError, match=re.escape(str(junk))):
        KeypointDetector([], detector_path=junk)


def _pattern() -> np.ndarray:
    y, x, c = np.mgrid[0:256, 0:256, 0:3]
    return ((x * 3 + y * 5 + c * 70) % 256).astype(np.uint8)


def test_network_matches_tflite_on_the_same_input(network):
    """Pose presence and visibilities of a fixed 256x256 pattern, as TFLite computes them from
    the same pixels as float32 RGB in [0, 1] (the model's input range)."""
    _, visibility, _, score = network.infer(_pattern())
    tflite = [0.1395, 0.2286, 0.2698, 0.2965, 0.2088, 0.2280, 0.2356, 0.2754, 0.3313, 0.3470,
              0.3341, 0.9283]
    assert score == pytest.approx(0.13359, abs=2e-3)
    np.testing.assert_allclose(visibility[:12], tflite, atol=2e-3)


def test_network_equals_an_independent_tflite_implementation(network, scene):
    """OpenCV dnn's own TFLite reader on the same crop of a rendered person: the raw landmarks
    agree to float32 precision over a deep network (1e-2 input pixels), the heatmaps' logits
    to 1e-2, and the refined landmarks in image pixels to 0.05 px."""
    cv2 = pytest.importorskip("cv2")
    reader = getattr(cv2.dnn, "readNetFromTFLite", None)
    if reader is None:
        pytest.skip(f"OpenCV {cv2.__version__} reads no TFLite")
    engine = getattr(cv2.dnn, "ENGINE_CLASSIC", None)
    net = reader(str(DEFAULT_MODEL)) if engine is None else reader(str(DEFAULT_MODEL), engine=engine)
    rig, images, silhouettes, _ = scene
    roi = box_roi(foreground_box(rig[0], silhouettes[0], KeypointParams()), 1.25)
    crop = cv2.warpAffine(images[0], crop_transform(roi, 256), (256, 256), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REPLICATE)
    net.setInput(cv2.dnn.blobFromImage(crop, scalefactor=1.0 / 255.0))
    raw, flag, heat = net.forward(["Identity", "Identity_1", "Identity_3"])
    ours = network._model.run(crop[None].astype(np.float32) / 255.0)
    np.testing.assert_allclose(ours[0].reshape(-1), raw.reshape(-1), atol=1e-2)
    assert float(ours[1].reshape(-1)[0]) == pytest.approx(float(flag.reshape(-1)[0]), abs=1e-3)
    np.testing.assert_allclose(ours[2].reshape(64, 64, 39).transpose(2, 0, 1),
                               heat.reshape(39, 64, 64), atol=1e-2)


def test_heatmap_refinement_moves_a_confident_landmark_to_the_peak():
    rows, cols = np.mgrid[0:64, 0:64]
    heat = np.full((2, 64, 64), -20.0)  # logits: nothing anywhere
    heat[0] = 8.0 - 0.5 * ((rows - 20.0) ** 2 + (cols - 31.0) ** 2)  # a sharp peak at cell (20, 31)
    start = np.array([[31.5 * 4, 20.6 * 4], [100.0, 100.0]])  # input pixels, 4 per cell
    refined = refine_from_heatmap(start, heat)
    np.testing.assert_allclose(refined[0], [31.0 * 4, 20.0 * 4], atol=0.05)
    np.testing.assert_array_equal(refined[1], start[1])  # below the confidence: kept


def test_crop_transform_maps_the_turned_square_onto_the_input():
    matrix = crop_transform(Roi(150.0, 150.0, 200.0), 256)
    corners = np.array([[50.0, 50.0, 1.0], [250.0, 250.0, 1.0]]) @ matrix.T
    np.testing.assert_allclose(corners, [[0.0, 0.0], [256.0, 256.0]], atol=1e-9)
    turned = Roi(150.0, 150.0, 200.0, rotation=np.pi / 2)
    # the square's up axis along the image's right (+u): the image's right becomes the crop's up
    centre = np.array([150.0, 150.0, 1.0])
    np.testing.assert_allclose(crop_transform(turned, 256) @ centre, [128.0, 128.0], atol=1e-9)
    np.testing.assert_allclose(crop_transform(turned, 256) @ (centre + (100.0, 0.0, 0.0)),
                               [128.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(np.c_[turned.corners(), np.ones(4)] @ crop_transform(turned, 256).T,
                               [[0, 0], [256, 0], [256, 256], [0, 256]], atol=1e-9)
    # MediaPipe's alignment: centre at the first point, side 2 x 1.25 x the distance, the
    # second point straight up in the crop
    roi = alignment_roi((100.0, 200.0), (100.0 + 30.0, 200.0 - 40.0))
    assert (roi.cx, roi.cy, roi.side) == pytest.approx((100.0, 200.0, 125.0))
    assert roi.rotation == pytest.approx(np.arctan2(30.0, 40.0))
    up = crop_transform(roi, 256) @ np.array([130.0, 160.0, 1.0])
    np.testing.assert_allclose(up, [128.0, 128.0 - 256 * 50.0 / 125.0], atol=1e-9)
    assert alignment_roi((5.0, 5.0), (5.0, 5.0)) is None
    with pytest.raises(ValueError):
        Roi(10.0, 10.0, 0.5)


def test_pose_detector_finds_the_person_upright_and_turned(scene):
    """On each rendered view the best detection's hips' centre lies on the projected hips'
    midpoint (within a tenth of the person's height), its box (BlazePose's detector boxes the
    head) holds the projected head, and its crop is upright (within 15 degrees) and holds every
    projected joint. The view turned a quarter clockwise (np.rot90 k=-1: the head points to
    the image's right) gives the crop turned by 90 degrees, and the landmarks of that crop land
    on the turned joints."""
    rig, images, silhouettes, truth = scene
    detector = PoseDetector()
    network = PoseLandmarkNetwork()
    joints = np.array([truth[j] for j in JOINTS.values()])
    hips = 0.5 * (truth["l_hip"] + truth["r_hip"])
    index = [LANDMARK_NAMES.index(n) for n in JOINTS]
    for v, camera in enumerate(rig):
        pix = project_points([camera], np.vstack([joints, hips, truth["head"]])).pixels[0]
        height = np.ptp(pix[:, 1])
        found = detector.detect(images[v])
        assert found and found[0].score > 0.8
        best = found[0]
        x0, y0, x1, y1 = best.box
        assert x0 < pix[-1, 0] < x1 and y0 < pix[-1, 1] < y1, (best.box, pix[-1])
        assert np.linalg.norm(best.keypoints[0] - pix[-2]) < 0.1 * height
        roi = best.roi()
        assert abs(roi.rotation) < np.radians(15) and height < roi.side < 3 * height
        corners = roi.corners()
        assert np.all(corners.min(axis=0) < pix.min(axis=0))
        assert np.all(corners.max(axis=0) > pix.max(axis=0))
        # a quarter turn clockwise: pixel (u, v) moves to (H - 1 - v, u)
        turned = np.ascontiguousarray(np.rot90(images[v], k=-1))
        found = detector.detect(turned)
        assert found and found[0].score > 0.8
        roi = found[0].roi()
        assert abs(roi.rotation - np.pi / 2) < np.radians(15), np.degrees(roi.rotation)
        moved = np.c_[camera.height - 1 - pix[:, 1], pix[:, 0]]
        landmarks = network.run(turned, roi)
        errors = np.linalg.norm(landmarks.xy[index] - moved[:-2], axis=1)
        assert landmarks.score > 0.9 and np.median(errors) < 8.0, np.round(errors)
    assert detector.detect(np.zeros((480, 640, 3), np.uint8)) == []


def test_landmarks_land_on_the_rendered_body(network, scene):
    rig, images, silhouettes, truth = scene
    index = [LANDMARK_NAMES.index(n) for n in JOINTS]
    expected = project_points(list(rig), np.array([truth[j] for j in JOINTS.values()])).pixels
    errors = []
    for v, camera in enumerate(rig):
        roi = box_roi(foreground_box(camera, silhouettes[v], KeypointParams()), 1.15)
        view = network.run(images[v], roi)
        assert view.xy.shape == (39, 2) and view.score > 0.9
        assert np.all((view.visibility >= 0) & (view.visibility <= 1))
        errors.append(np.linalg.norm(view.xy[index] - expected[v], axis=1))
        # another crop of the same person: the landmarks stay in image pixels
        shifted = network.run(images[v], Roi(roi.cx + 20.0, roi.cy - 8.0, roi.side * 1.1))
        assert np.median(np.linalg.norm(shifted.xy[:33] - view.xy[:33], axis=1)) < 4.0
        turned = network.run(images[v], Roi(roi.cx, roi.cy, roi.side, rotation=0.3))
        assert np.median(np.linalg.norm(turned.xy[:33] - view.xy[:33], axis=1)) < 5.0
    errors = np.array(errors)  # (views, joints) pixels
    assert np.median(errors) < 6.0, np.round(errors)
    assert np.mean(errors < 15.0) > 0.9, np.round(errors)


def test_detector_finds_the_labelled_keypoints_in_3d(scene, caplog):
    rig, images, silhouettes, truth = scene
    detector = KeypointDetector(rig)
    try:
        result = detector.detect(images, silhouettes)
        targets = keypoint_targets(truth)
        found = result.as_dict()
        for label, target in targets.items():
            assert label in found, label
            error = np.linalg.norm(found[label] - target)
            assert error < 0.08, f"{label} off by {1000 * error:.0f} mm"
        assert np.all(result.scores > 0.5) and np.all(result.views_used >= 3)
        assert set(detector.last_timings) >= {"roi", "network", "triangulation", "total"}
        assert sum(k.startswith("network/") for k in detector.last_timings) == 4
        assert detector.last_sources == ["detector"] * 4  # the first crops: the pose detector
        again = detector.detect(images, silhouettes)
        assert detector.last_sources == ["track"] * 4  # then each view's own landmarks
        moved = {k: np.linalg.norm(again.as_dict()[k] - p) for k, p in found.items()}
        assert max(moved.values()) < 0.03, moved
        # a missing view, an image of the wrong size and an empty mask are skipped, once logged
        caplog.set_level(logging.WARNING, logger="hmocap_ros.detection.keypoint_detector")
        views = [None, images[1][:240], images[2], images[3]]
        masks = [silhouettes[0], silhouettes[1], silhouettes[2], np.zeros_like(silhouettes[3])]
        for _ in range(2):
            partial = detector.detect(views, masks, previous=found)
        assert len([r for r in caplog.records if "skips camera" in r.message]) == 3
        assert partial.labels == ()  # one view left
        assert detector.last_sources[0] is None and detector.last_sources[3] is None
        detector.reset()
        with_previous = detector.detect(images, [None] * 4, previous=found)
        assert detector.last_sources == ["skeleton"] * 4  # no track: the previous skeleton
        assert np.linalg.norm(with_previous.as_dict()["left_hand"] - targets["left_hand"]) < 0.08
        detector.reset()
        without_masks = detector.detect(images, [None] * 4)
        assert detector.last_sources == ["detector"] * 4
        assert np.linalg.norm(without_masks.as_dict()["left_hand"] - targets["left_hand"]) < 0.08
    finally:
        detector.close()


#: the walk of :func:`test_each_views_crop_follows_a_walking_person`: frame sets, and the
#: subject's step (m, along the room's x and z) between two of them
WALK_SETS, WALK_STEP = 5, 0.2


def test_each_views_crop_follows_a_walking_person(studio):
    """The subject walks diagonally across the room, 0.28 m between frame sets (1.1 m in all):
    after the pose detector's first crops, each view's crop comes from its own landmarks of
    the set before (``track``), and follows the person, so every labelled keypoint is found
    in every set, within 65 mm of its place (today at most 51 mm, median 22). Baseline: the
    first set's keypoints held still, 0.28 to 1.1 m off."""
    rig = studio.rig
    tx, tz = (studio.model.skeleton.dof_index(d) for d in ("root_tx", "root_tz"))
    poses = np.repeat(studio.pose[None], WALK_SETS, axis=0)
    poses[:, tx] += WALK_STEP * np.arange(WALK_SETS)
    poses[:, tz] += WALK_STEP * np.arange(WALK_SETS)
    detector = KeypointDetector(rig)
    found, targets = [], []
    try:
        for k, (images, silhouettes, truth) in enumerate(studio.render(poses)):
            found.append(detector.detect(images, silhouettes).as_dict())
            assert detector.last_sources == ["detector" if k == 0 else "track"] * len(rig), k
            targets.append(keypoint_targets(truth))
    finally:
        detector.close()
    # (sets, labels) mm
    errors = 1000 * np.array([[np.linalg.norm(f[label] - p) if label in f else np.inf
                               for label, p in t.items()] for f, t in zip(found, targets)])
    held = 1000 * np.array([[np.linalg.norm(found[0][label] - p) for label, p in t.items()]
                            for t in targets])
    assert np.all(errors < 65.0), np.round(errors)
    assert np.all(np.median(errors, axis=1) < 35.0), np.round(errors)
    assert np.all(errors[1:].mean(axis=1) < 0.2 * held[1:].mean(axis=1)), (errors, held)


def test_ssd_anchors_decoding_and_weighted_nms_follow_mediapipe():
    from hmocap_ros.detection.pose_detector import decode_detections, ssd_anchors, weighted_nms

    anchors = ssd_anchors()
    # strides 8, 16 (2 anchors a cell) and three layers of 32 merged (6 a cell): 2254 anchors
    assert anchors.shape == (28 * 28 * 2 + 14 * 14 * 2 + 7 * 7 * 6, 2) == (2254, 2)
    np.testing.assert_allclose(anchors[:2], [[0.5 / 28, 0.5 / 28]] * 2)
    np.testing.assert_allclose(anchors[1568], [0.5 / 14, 0.5 / 14])
    np.testing.assert_allclose(anchors[-1], [6.5 / 7, 6.5 / 7])
    raw = np.zeros((3, 12))
    raw[0, :4] = [22.4, -11.2, 44.8, 89.6]  # centre offset (0.1, -0.05) of the input, size 0.2 x 0.4
    raw[0, 4:6] = [0.0, 22.4]  # keypoint 0: 0.1 below the anchor
    logits = np.array([3.0, -3.0, 200.0])  # sigmoid 0.95, 0.05 (dropped), clipped to 100 -> 1
    scores, boxes, keypoints = decode_detections(raw, logits, np.array([[0.5, 0.5]] * 3))
    assert scores == pytest.approx([1 / (1 + np.exp(-3.0)), 1.0])
    np.testing.assert_allclose(boxes[0], np.array([0.5, 0.25, 0.7, 0.65]) * 224, atol=1e-9)
    np.testing.assert_allclose(keypoints[0, 0], [0.5 * 224, 0.6 * 224], atol=1e-9)
    # two overlapping boxes merge into their score-weighted mean; a distant one stays apart
    boxes = np.array([[0, 0, 10, 10], [1, 0, 11, 10], [50, 50, 60, 60]], float)
    points = np.array([np.full((4, 2), 0.0), np.full((4, 2), 3.0), np.full((4, 2), 55.0)])
    merged = weighted_nms(np.array([0.6, 0.9, 0.7]), boxes, points)
    assert [m[0] for m in merged] == [0.9, 0.7]
    np.testing.assert_allclose(merged[0][1], (0.9 * boxes[1] + 0.6 * boxes[0]) / 1.5)
    np.testing.assert_allclose(merged[0][2], np.full((4, 2), 0.9 * 3.0 / 1.5))
    np.testing.assert_allclose(merged[1][2], points[2])
