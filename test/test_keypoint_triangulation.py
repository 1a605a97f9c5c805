"""Robust multi-view triangulation of landmarks (hmocap_ros.detection.keypoint_triangulation).

Synthetic cases with known answers: a 3D landmark set (BlazePose's 33 landmarks of a person
standing at the room centre, facing +z) projected into 4-5 calibrated cameras with lens
distortion, then views made wrong on purpose (a limb off, sides swapped, a view missing).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hmocap_ros.detection.keypoint_detector import foreground_box, previous_pixels
from hmocap_ros.detection.keypoint_network import LANDMARK_NAMES, NUM_LANDMARKS, ViewLandmarks
from hmocap_ros.detection.keypoint_roi import box_roi, skeleton_roi
from hmocap_ros.detection.keypoint_triangulation import (
    HEAD_OFFSET,
    HIP_WIDENING,
    KEYPOINT_LABELS,
    Keypoints3D,
    triangulate_views,
)
from hmocap_ros.detection.params import KeypointParams
from hmocap_ros.geometry import look_at, project_points

# (x, y, z) of the left landmarks (the subject's left is +x when facing +z; y up), mirrored for
# the right ones; the nose on the midline.
_LEFT = {
    "eye_inner": (0.015, 1.66, 0.09), "eye": (0.032, 1.66, 0.085), "eye_outer": (0.045, 1.66, 0.08),
    "ear": (0.075, 1.63, 0.0), "mouth": (0.025, 1.58, 0.09), "shoulder": (0.18, 1.42, 0.0),
    "elbow": (0.42, 1.40, 0.02), "wrist": (0.66, 1.40, 0.05), "pinky": (0.74, 1.39, 0.04),
    "index": (0.75, 1.41, 0.07), "thumb": (0.72, 1.42, 0.09), "hip": (0.10, 0.95, 0.0),
    "knee": (0.11, 0.52, 0.02), "ankle": (0.11, 0.08, 0.0), "heel": (0.11, 0.03, -0.05),
    "foot_index": (0.12, 0.01, 0.15),
}
SWAP = np.array([LANDMARK_NAMES.index(n.replace("left", "R").replace("right", "left")
                                      .replace("R", "right")) for n in LANDMARK_NAMES]
                + list(range(33, NUM_LANDMARKS)))


def _landmarks_3d() -> np.ndarray:
    points = np.zeros((NUM_LANDMARKS, 3))
    points[33:] = (0.0, 0.95, 0.0)
    points[0] = (0.0, 1.62, 0.10)
    for name, xyz in _LEFT.items():
        key = "mouth_left" if name == "mouth" else f"left_{name}"
        other = "mouth_right" if name == "mouth" else f"right_{name}"
        points[LANDMARK_NAMES.index(key)] = xyz
        points[LANDMARK_NAMES.index(other)] = (-xyz[0], xyz[1], xyz[2])
    return points


def _cameras(n=4):
    angles = np.deg2rad(45.0 + 360.0 / n * np.arange(n))
    return [look_at(f"cam_{k + 1}", (3.5 * np.sin(a), 2.4, 3.5 * np.cos(a)), (0.0, 1.0, 0.0),
                    D=(-0.05, 0.01, 0.0, 0.0, 0.0)) for k, a in enumerate(angles)]


def _views(cameras, points, rng, noise_px=0.5):
    pixels = project_points(cameras, points).pixels
    ones = np.ones(NUM_LANDMARKS)
    return [ViewLandmarks(xy=p + rng.normal(0.0, noise_px, p.shape), visibility=ones,
                          presence=ones, score=1.0) for p in pixels]


def _expected(points) -> dict[str, np.ndarray]:
    """The labels' positions from the synthetic landmarks (the module's documented rules)."""
    idx = {n: i for i, n in enumerate(LANDMARK_NAMES)}
    out = {}
    for side in ("left", "right"):
        out[f"{side}_hand"] = points[[idx[f"{side}_index"], idx[f"{side}_pinky"]]].mean(axis=0)
        out[f"{side}_foot"] = points[idx[f"{side}_foot_index"]]
        for part in ("shoulder", "elbow", "wrist", "knee", "ankle", "hip"):
            out[f"{side}_{part}"] = points[idx[f"{side}_{part}"]].copy()
    out["left_hip"][0] += HIP_WIDENING
    out["right_hip"][0] -= HIP_WIDENING
    ears = 0.5 * (points[idx["left_ear"]] + points[idx["right_ear"]])
    forward = points[idx["nose"]] - ears  # across the ears' axis (x) here: (0, dy, dz)
    forward[0] = 0.0
    forward /= np.linalg.norm(forward)
    up = np.cross(forward, (1.0, 0.0, 0.0))
    out["head"] = ears + HEAD_OFFSET[0] * forward + HEAD_OFFSET[1] * up
    return out


def _check(result: Keypoints3D, expected, tolerance=0.01, labels=KEYPOINT_LABELS):
    got = result.as_dict()
    for label in labels:
        assert label in got, f"{label} missing"
        error = np.linalg.norm(got[label] - expected[label])
        assert error < tolerance, f"{label} off by {1000 * error:.0f} mm"


def test_clean_views_give_every_label_at_its_place():
    rng = np.random.default_rng(0)
    points, cameras = _landmarks_3d(), _cameras()
    result = triangulate_views(cameras, _views(cameras, points, rng))
    assert result.labels == KEYPOINT_LABELS
    _check(result, _expected(points))
    assert np.all(result.views_used == 4)
    assert np.all(result.scores > 0.9) and np.all(result.scores <= 1.0)
    # the head is above and behind the ears' midpoint
    ears = 0.5 * (points[7] + points[8])
    head = result.as_dict()["head"]
    assert head[1] > ears[1] + 0.02 and head[2] < ears[2] - 0.05


def test_an_outlier_view_is_left_out():
    rng = np.random.default_rng(1)
    points, cameras = _landmarks_3d(), _cameras()
    views = _views(cameras, points, rng)
    wrong = views[2].xy.copy()
    wrong[[15, 17, 19, 21]] += (60.0, -40.0)  # the left hand found on something else
    views[2] = dataclasses.replace(views[2], xy=wrong)
    result = triangulate_views(cameras, views)
    _check(result, _expected(points))
    used = dict(zip(result.labels, result.views_used))
    assert used["left_hand"] == 3 and used["left_wrist"] == 3 and used["right_hand"] == 4
    score = dict(zip(result.labels, result.scores))
    assert score["left_hand"] < score["right_hand"]  # a confident view disagrees
    plain = triangulate_views(cameras, views, params=KeypointParams(max_reprojection_px=1e4))
    assert np.linalg.norm(plain.as_dict()["left_hand"] - _expected(points)["left_hand"]) > 0.03


@pytest.mark.parametrize("swapped", [(1,), (0, 3)])
def test_swapped_sides_of_a_minority_of_views_are_renamed(swapped):
    rng = np.random.default_rng(2)
    points, cameras = _landmarks_3d(), _cameras(5)
    views = _views(cameras, points, rng)
    for v in swapped:  # seen as from behind: the network swapped the subject's sides
        views[v] = dataclasses.replace(views[v], xy=views[v].xy[SWAP])
    result = triangulate_views(cameras, views)
    _check(result, _expected(points))
    assert np.all(result.views_used == 5)
    kept = triangulate_views(cameras, views, params=KeypointParams(resolve_swaps=False))
    assert np.min(dict(zip(kept.labels, kept.views_used))["left_hand"]) < 5


def test_the_previous_skeleton_names_the_sides_when_most_views_are_swapped():
    rng = np.random.default_rng(3)
    points, cameras = _landmarks_3d(), _cameras()
    views = _views(cameras, points, rng)
    for v in (0, 1, 2):
        views[v] = dataclasses.replace(views[v], xy=views[v].xy[SWAP])
    expected = _expected(points)
    mirrored = triangulate_views(cameras, views)  # the views' majority wins without a skeleton
    assert np.linalg.norm(mirrored.as_dict()["left_hand"] - expected["right_hand"]) < 0.01
    previous = {k: v + 0.05 for k, v in expected.items() if k not in ("head", "left_hand")}
    result = triangulate_views(cameras, views, previous=previous)
    _check(result, expected)


def test_missing_views_and_too_few_views():
    rng = np.random.default_rng(4)
    points, cameras = _landmarks_3d(), _cameras()
    views = _views(cameras, points, rng)
    result = triangulate_views(cameras, [None, views[1], views[2], None])
    _check(result, _expected(points), tolerance=0.02)  # two views: less precise
    assert np.all(result.views_used == 2)
    empty = triangulate_views(cameras, [None, views[1], None, None])
    assert empty.labels == () and empty.positions.shape == (0, 3)
    weak = dataclasses.replace(views[3], score=0.1)  # no person in that crop
    assert triangulate_views(cameras, [None, views[1], None, weak]).labels == ()
    with pytest.raises(ValueError, match="one view"):
        triangulate_views(cameras, views[:3])


def test_a_landmark_off_the_silhouette_is_not_used():
    rng = np.random.default_rng(5)
    points, cameras = _landmarks_3d(), _cameras()
    views = _views(cameras, points, rng)
    masks = []
    for camera, view in zip(cameras, views):  # half-resolution masks: the body's box
        mask = np.zeros((camera.height // 2, camera.width // 2), np.uint8)
        x0, y0 = np.floor(view.xy[:33].min(axis=0) / 2).astype(int) - 2
        x1, y1 = np.ceil(view.xy[:33].max(axis=0) / 2).astype(int) + 2
        mask[y0:y1, x0:x1] = 255
        masks.append(mask)
    hand = views[1].xy[[15, 17, 19]]
    x0, y0 = np.floor(hand.min(axis=0) / 2).astype(int) - 8
    x1, y1 = np.ceil(hand.max(axis=0) / 2).astype(int) + 8
    masks[1][y0:y1, x0:x1] = 0  # the segmentation lost the left hand in view 2
    params = KeypointParams(outside_mask_weight=0.0)
    result = triangulate_views(cameras, views, masks, params=params)
    used = dict(zip(result.labels, result.views_used))
    assert used["left_hand"] == 3 and used["right_hand"] == 4
    _check(result, _expected(points))
    full = triangulate_views(cameras, views, [None] * 4, params=params)
    assert dict(zip(full.labels, full.views_used))["left_hand"] == 4


def test_crops_from_the_foreground_and_from_the_previous_skeleton():
    camera = _cameras()[0]
    params = KeypointParams()
    mask = np.zeros((240, 320), np.uint8)  # half resolution
    mask[50:150, 100:140] = 255  # the person
    mask[60:70, 141:160] = 255  # an arm the segmentation cut off, touching the body's box
    mask[200:210, 10:20] = 255  # something else
    x0, y0, x1, y1 = foreground_box(camera, mask, params)
    assert (x1 - x0, y1 - y0) == pytest.approx((120.0, 200.0))  # full-image pixels
    roi = box_roi((x0, y0, x1, y1), params.box_margin)
    assert roi.side == pytest.approx(params.box_margin * 200.0) and roi.rotation == 0.0
    assert (roi.cx, roi.cy) == pytest.approx((2 * 130.0 - 0.5, 199.5))
    assert foreground_box(camera, np.zeros_like(mask), params) is None
    previous = _expected(_landmarks_3d())
    pixels = previous_pixels(camera, previous)
    crop = skeleton_roi(pixels, params.previous_box_pad)
    corners = crop.corners()
    points = np.array(list(pixels.values()))
    assert corners[:, 0].min() < points[:, 0].min() and corners[:, 0].max() > points[:, 0].max()
    assert corners[:, 1].min() < points[:, 1].min() and corners[:, 1].max() > points[:, 1].max()
    assert abs(crop.rotation) < 0.15  # standing: the crop stays upright
    leaning = dict(previous)
    for side in ("left", "right"):  # the trunk along the image's right direction
        leaning[f"{side}_shoulder"] = previous[f"{side}_hip"] + 0.5 * camera.R[0]
    turned = skeleton_roi(previous_pixels(camera, leaning), params.previous_box_pad)
    assert turned.rotation == pytest.approx(np.pi / 2, abs=0.1)
    leaning = dict(previous)
    leaning.update(left_shoulder=previous["left_shoulder"] - 0.3 * camera.R[0],
                   right_shoulder=previous["right_shoulder"] - 0.3 * camera.R[0])
    assert -np.pi / 2 < skeleton_roi(previous_pixels(camera, leaning), 0.2).rotation < -0.3
    del leaning["left_hip"]
    assert skeleton_roi(previous_pixels(camera, leaning), 0.2) is None  # no hips: no crop
    assert previous_pixels(camera, None) == {}
    with pytest.raises(ValueError, match="min_views"):
        KeypointParams(min_views=1)


def test_landmarks_of_wide_angle_lenses_are_undistorted_before_triangulation():
    """Wide-angle lenses (k1 = -0.3) bend a person near the image edge by tens of pixels: the
    landmarks are undistorted before the DLT, which then puts every label within a centimetre
    (the 0.5 px landmark noise). Triangulated in the distorted images they land 2-17 cm off."""
    rng = np.random.default_rng(1)
    points = _landmarks_3d() + np.array([1.2, 0.0, -0.6])  # off centre: near the images' edges
    angles = np.deg2rad(45.0 + 90.0 * np.arange(4))
    cameras = [look_at(f"cam_{k + 1}", (2.6 * np.sin(a), 2.4, 2.6 * np.cos(a)), (0.0, 1.0, 0.0),
                       D=(-0.3, 0.1, 0.0, 0.0, 0.0)) for k, a in enumerate(angles)]
    ideal = [look_at(c.name, (2.6 * np.sin(a), 2.4, 2.6 * np.cos(a)), (0.0, 1.0, 0.0))
             for c, a in zip(cameras, angles)]
    bend = np.linalg.norm(project_points(cameras, points).pixels
                          - project_points(ideal, points).pixels, axis=-1)
    assert np.nanmax(bend) > 20.0  # the lens matters here
    result = triangulate_views(cameras, _views(cameras, points, rng))
    _check(result, _expected(points), tolerance=0.01)


def test_a_view_that_disagrees_with_all_others_is_left_out_and_named():
    """A fifth camera whose landmarks are another pose altogether (another person, a wrong
    crop): the other four views place every label, and the result names that view as left
    out; with four agreeing views none is."""
    rng = np.random.default_rng(3)
    points, cameras = _landmarks_3d(), _cameras(5)
    views = _views(cameras, points, rng)
    other = _views(cameras, points + np.array([0.8, 0.0, 0.5]), rng)
    views[4] = other[4]
    result = triangulate_views(cameras, views)
    _check(result, _expected(points))
    assert result.views_left_out == (4,)
    assert triangulate_views(cameras[:4], views[:4]).views_left_out == ()
