"""Gesture localization (thesis sec. 3.2.4): votes, Parzen density, temporal smoothing (eq. 3.4),
volume test (eq. 3.5), on planted toy gestures and on a hand-made one-test forest."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from fixtures.toy_depth import add_sensor_noise, toy_detector_params, toy_forest, toy_frame

from hmocap_ros.gestures import DetectorParams, FeatureParams, Forest, GestureDetector, Tree
from hmocap_ros.gestures.depth_features import depth_to_metres
from hmocap_ros.gestures.grid_votes import forest_grid_proba, forest_grid_votes, grid_shape, pad_for_forest
from hmocap_ros.gestures.params import DepthFormat

SHAPE = (240, 320)
FRAME_NS = 33_333_333


def near_forest() -> Forest:
    """One plain test: d(x) - d(far outside) = d - 10 < -8, i.e. "nearer than 2 m" votes class 1
    (outside the image reads the background depth here)."""
    tree = Tree(feature=np.array([[0, 0, 1e6, 0], [0, 0, 0, 0], [0, 0, 0, 0]], np.float32),
                threshold=np.array([-8.0, 0, 0], np.float32),
                left=np.array([1, -1, -1], np.int32), right=np.array([2, -1, -1], np.int32),
                counts=np.array([[1, 1], [0, 5], [5, 0]], np.float32), depth=np.array([0, 1, 1], np.int16))
    return Forest([tree], ("background", "near"), FeatureParams(feature_type="plain", outside="background"))


def square_scene(u=80, v=60, half=10, shape=(120, 160), depth=1.5) -> np.ndarray:
    img = np.full(shape, 3.0, np.float32)
    img[v - half:v + half + 1, u - half:u + half + 1] = depth
    return img


def test_a_near_square_is_localized_at_its_centre_with_its_depth():
    params = DetectorParams(stride=2, parzen_sigma_px=3.0, alpha=1.0, volume_radius_px_m=12.0)
    det = GestureDetector(near_forest(), params)
    found = det.update(square_scene(u=70, v=50), 0)
    assert len(found) == 1
    d = found[0]
    assert (d.class_id, d.name) == (1, "near")
    assert abs(d.u - 70) <= 1.0 and abs(d.v - 50) <= 1.0
    assert d.depth_m == pytest.approx(1.5)
    assert d.score > 0.9 and 0.8 < d.volume <= 1.0  # the 8 px disk lies inside the 21 px voting square
    assert d.stamp_ns == 0
    assert det.probability_image().shape == (120, 160)
    assert det.probability_image()[50, 70] == pytest.approx(d.score, abs=0.05)


def test_temporal_smoothing_follows_eq_3_4():
    alpha = 0.8
    det = GestureDetector(near_forest(), DetectorParams(stride=2, parzen_sigma_px=3.0, alpha=alpha,
                                                        min_score=0.5, min_volume=0.0))
    seen, empty = square_scene(), np.full((120, 160), 3.0, np.float32)
    assert det.update(seen, 0)  # p'_1 = alpha p (the state starts at zero)
    p_seen = det.density / alpha
    assert p_seen.max() == pytest.approx(1.0, abs=0.02)
    expected = alpha * p_seen
    for k, (frame, detected) in enumerate([(empty, False), (empty, False), (seen, True), (seen, True)], start=1):
        found = det.update(frame, k * FRAME_NS)
        p = p_seen if frame is seen else np.zeros_like(p_seen)
        expected = alpha * p + (1 - alpha) * expected
        np.testing.assert_allclose(det.density, expected, rtol=1e-5, atol=1e-7)
        assert bool(found) == detected  # 0.16 and 0.03 fall below min_score, 0.8 + 0.2 * 0.03 does not

    # Stamps going back (a looping bag) or a gap restart the state: p' = alpha p again.
    det.update(seen, FRAME_NS)
    np.testing.assert_allclose(det.density, alpha * p_seen, rtol=1e-6)
    det.update(seen, 2 * FRAME_NS)
    det.update(seen, 2 * FRAME_NS + int(2e9))
    np.testing.assert_allclose(det.density, alpha * p_seen, rtol=1e-6)
    det.update(square_scene(shape=(100, 160)), 3 * int(1e9))  # a new image size restarts too
    assert det.density.shape[:2] == grid_shape(100, 160, 2)[:2]


def test_volume_disk_shrinks_with_depth():
    """Eq. 3.5: the disk is volume_radius / d pixels, so a fixed-size voting square fills it at 1.5 m
    only partly when seen nearer and fully when further."""
    params = DetectorParams(stride=1, parzen_sigma_px=3.0, alpha=1.0, volume_radius_px_m=12.0, min_score=0.0,
                            min_volume=0.0)
    volumes = {}
    for depth in (0.5, 1.5):  # radius 24 px vs 8 px around a 21 x 21 px square
        det = GestureDetector(near_forest(), params)
        found = det.update(square_scene(depth=depth), 0)
        assert (found[0].u, found[0].v) == (80, 60)
        volumes[depth] = found[0].volume
    assert volumes[1.5] > 0.85
    assert 0.15 < volumes[0.5] < 0.35  # about 21^2 / (pi 24^2) = 0.24


def test_invalid_frames_give_no_detection():
    det = GestureDetector(near_forest(), DetectorParams(stride=2))
    assert det.update(np.zeros((120, 160), np.uint16), 0) == []  # no depth at all
    assert np.all(det.class_map == -1)
    nan = np.full((120, 160), np.nan, np.float32)
    assert det.update(nan, FRAME_NS) == []
    assert det.update(np.full((1, 1), 1000, np.uint16), 2 * FRAME_NS) == []  # smaller than the grid
    with pytest.raises(ValueError):
        det.update(np.zeros((120, 160, 3), np.uint16), 3 * FRAME_NS)  # not a depth image
    with pytest.raises(ValueError):
        GestureDetector(near_forest(), DetectorParams(max_depth_m=12.0))  # beyond the background depth


def test_grid_votes_equal_the_forest_prediction_at_each_grid_pixel():
    forest = toy_forest(shape=SHAPE)
    rng = np.random.default_rng(11)
    for cls in (0, 1, 2):
        raw, _ = toy_frame(rng, SHAPE, cls)
        depth = depth_to_metres(raw, DepthFormat(), forest.features.background_depth_m)
        for stride in (3, 4):
            class_map, grid_depth = forest_grid_votes(forest.flat(), pad_for_forest(depth, forest.flat()), stride)
            gh, gw, off = grid_shape(*SHAPE, stride)
            ys, xs = np.mgrid[off:SHAPE[0]:stride, off:SHAPE[1]:stride]
            assert class_map.shape == (gh, gw) == ys.shape
            np.testing.assert_array_equal(grid_depth, depth[ys, xs])
            valid = depth[ys, xs] < 10.0
            np.testing.assert_array_equal(class_map[~valid], -1)
            proba = forest.predict_proba(depth, np.zeros(valid.sum()), xs[valid], ys[valid])
            grid_proba = forest_grid_proba(forest.flat(), pad_for_forest(depth, forest.flat()), stride)
            np.testing.assert_allclose(grid_proba[valid], proba, atol=1e-6)
            assert np.all(grid_proba[~valid] == 0)
            # Exact argmax with ties to background, as the kernel (and its early exit) must give.
            want = np.where(proba[:, 1:].max(1) > proba[:, 0], proba[:, 1:].argmax(1) + 1, 0)
            close = np.abs(np.sort(proba, 1)[:, -1] - np.sort(proba, 1)[:, -2]) < 1e-5  # float-order ties
            np.testing.assert_array_equal(class_map[valid][~close], want[~close])


@pytest.mark.parametrize("cls, uv, depth_m", [(1, (200, 120), 2.0), (2, (90, 80), 2.6), (1, (60, 170), 1.6)])
def test_detector_finds_a_planted_gesture_among_clutter(cls, uv, depth_m):
    forest = toy_forest(shape=SHAPE)
    rng = np.random.default_rng(cls * 100 + uv[0])
    clean, label = toy_frame(rng, SHAPE, cls, uv=uv, depth_m=depth_m, noise=False)
    det = GestureDetector(forest, toy_detector_params(SHAPE))
    for k in range(4):  # a still gesture over a few noisy frames
        found = det.update(add_sensor_noise(rng, clean / 1000.0), k * FRAME_NS)
    assert found, "gesture not detected"
    best = found[0]
    assert best.class_id == cls
    assert np.hypot(best.u - uv[0], best.v - uv[1]) <= 4.0
    assert best.depth_m == pytest.approx(depth_m, abs=0.05)
    assert best.score >= det.params.min_score and best.volume >= det.params.min_volume


def test_walls_and_clutter_rarely_trigger_a_detection():
    """Rooms without people: the toy forest never saw most of these shapes as negatives (a clutter
    disc at a hand's depth does look like a palm), so allow one scene in eight."""
    forest = toy_forest(shape=SHAPE)
    rng = np.random.default_rng(21)
    det = GestureDetector(forest, toy_detector_params(SHAPE))
    scenes_with_detections = 0
    for _scene in range(24):
        clean, _ = toy_frame(rng, SHAPE, 0, person=False, n_clutter=8, noise=False)
        det.reset()
        found = [det.update(add_sensor_noise(rng, clean / 1000.0), j * FRAME_NS) for j in range(3)]
        scenes_with_detections += any(found)
    assert scenes_with_detections <= 3


def test_detector_state_survives_a_forest_update():
    det = GestureDetector(near_forest(), DetectorParams(stride=2, parzen_sigma_px=3.0))
    det.update(square_scene(), 0)
    before = det.density.copy()
    det.set_forest(near_forest())  # same classes (an online forest that grew): state kept
    np.testing.assert_array_equal(det.density, before)
    other = dataclasses.replace(near_forest())
    other.class_names = ("background", "other")
    det.set_forest(other)
    assert det.density is None


def test_forest_and_pixel_sizes_follow_the_cameras_focal_length():
    """A forest trained on 320x240 frames (f = 262.5 px) finds the gesture in a 640x480 frame of the
    same camera model (f = 525 px): its offsets (pixel*metres, proportional to f) and the detector's
    pixel sizes (given for 525 px) are rescaled, from camera_info's fx or, without it, from the
    image width relative to the training frames."""
    small = toy_forest(shape=SHAPE)
    forest = Forest(small.trees, small.class_names, small.features, small.kind,
                    {"training": dict(small.meta["training"], focal_px=262.5)})
    for shape, focal in ((SHAPE, 262.5), ((480, 640), 525.0)):
        scale = focal / 262.5
        rng = np.random.default_rng(5)
        uv = (int(150 * scale), int(110 * scale))
        clean, _ = toy_frame(rng, shape, 1, uv=uv, depth_m=2.0, focal_px=focal, noise=False)
        for camera_focal in (focal, None):
            det = GestureDetector(forest, DetectorParams(), focal_px=camera_focal)
            for k in range(3):
                found = det.update(add_sensor_noise(rng, clean / 1000.0), k * FRAME_NS)
            assert det.offset_scale == pytest.approx(scale)
            assert det.active_params.stride == round(4 * focal / 525.0)
            assert det.active_params.parzen_sigma_px == pytest.approx(6.0 * focal / 525.0)
            assert found and found[0].class_id == 1, found
            assert np.hypot(found[0].u - uv[0], found[0].v - uv[1]) <= 4.0 * scale
    # Unknown training focal length (an old forest): the offsets are used as they are.
    det = GestureDetector(small, DetectorParams(), focal_px=525.0)
    det.update(np.full((48, 64), 2000, np.uint16), 0)
    assert det.offset_scale == 1.0 and det.active_params.stride == 4
    with pytest.raises(ValueError):
        det.set_focal(-1.0)
