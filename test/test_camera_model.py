"""Tests of hmocap_ros.geometry against OpenCV and synthetic scenes with known geometry."""

import dataclasses

import cv2
import numpy as np
import pytest

from hmocap_ros.geometry import (
    ROOM_UP,
    PinholeCamera,
    distort_normalized,
    look_at,
    matrix_to_quaternion,
    pixel_rays,
    project_points,
    quaternion_to_matrix,
    triangulate,
    undistort_normalized,
)

ROOM_CENTRE = np.array([0.0, 1.0, 0.0])
PLUMB_BOB = (-0.05, 0.012, 0.0008, -0.0005, -0.002)
RATIONAL = (0.3, -0.1, 0.0007, -0.0004, 0.02, 0.35, -0.08, 0.03)


def corner_rig(D=PLUMB_BOB, model="plumb_bob"):
    """Four cameras 2.5 m high in the corners of a 6 x 5 m room, looking at its centre."""
    corners = [(-3.0, 2.5, -2.5), (3.0, 2.5, -2.5), (3.0, 2.5, 2.5), (-3.0, 2.5, 2.5)]
    return [
        look_at(f"cam_{i + 1}", c, ROOM_CENTRE, fx=520.0 + 3 * i, fy=521.0 + 2 * i, cx=318.0 + i, cy=241.0 - i,
                D=D, distortion_model=model)
        for i, c in enumerate(corners)
    ]


def room_points(rng, n):
    """Random points in the tracking volume (a person-sized box around the room centre)."""
    return rng.uniform((-1.0, 0.0, -1.0), (1.0, 2.0, 1.0), size=(n, 3))


def cv2_undistort(pixels, K, D, P, criteria):
    """``cv2.undistortPoints`` with stopping criteria: OpenCV 4.7 and later take them there,
    4.6 (Ubuntu 24.04's) only in ``undistortPointsIter``; copies, since 4.6 refuses read-only
    arrays (a camera's K and D)."""
    K, D = np.array(K), np.array(D)
    P = None if P is None else np.array(P)
    if hasattr(cv2, "undistortPointsIter"):
        return cv2.undistortPointsIter(pixels, K, D, None, P, criteria)
    return cv2.undistortPoints(pixels, K, D, None, None, P, criteria)


def cv2_project(camera, points):
    rvec, _ = cv2.Rodrigues(camera.R)
    pixels, _ = cv2.projectPoints(points.reshape(-1, 1, 3), rvec, camera.t, camera.K, camera.D)
    return pixels.reshape(-1, 2)


@pytest.mark.parametrize("D,model", [(PLUMB_BOB, "plumb_bob"), (RATIONAL, "rational_polynomial"), ((), "plumb_bob")])
def test_project_matches_cv2(D, model):
    rng = np.random.default_rng(0)
    points = room_points(rng, 500)
    for camera in corner_rig(D, model):
        pixels, depth = camera.project(points)
        np.testing.assert_allclose(pixels, cv2_project(camera, points), atol=1e-6, rtol=0)
        np.testing.assert_allclose(depth, camera.world_to_camera(points)[:, 2], atol=1e-12)
        assert np.all(depth > 0)


def test_project_points_multi_camera_and_batches():
    rng = np.random.default_rng(1)
    cameras = corner_rig()
    points = room_points(rng, 24).reshape(2, 3, 4, 3)
    result = project_points(cameras, points)
    assert result.pixels.shape == (4, 2, 3, 4, 2)
    assert result.depth.shape == (4, 2, 3, 4)
    assert result.visible.shape == (4, 2, 3, 4)
    for m, camera in enumerate(cameras):
        expected = cv2_project(camera, points.reshape(-1, 3)).reshape(2, 3, 4, 2)
        np.testing.assert_allclose(result.pixels[m], expected, atol=1e-6, rtol=0)
        single, depth = camera.project(points)
        np.testing.assert_array_equal(single, result.pixels[m])
        np.testing.assert_array_equal(depth, result.depth[m])
    # Every camera sees the whole tracking volume.
    assert result.visible.all()


def test_visibility_mask():
    camera = look_at("cam", (0.0, 1.0, -4.0), (0.0, 1.0, 0.0), D=PLUMB_BOB)
    points = np.array([
        [0.0, 1.0, 0.0],  # straight ahead: pixel at the principal point
        [0.0, 1.0, -5.0],  # behind the camera
        [4.0, 1.0, -3.9],  # far to the side, 84 deg off-axis: outside the image
        [0.0, 1.0, -4.0],  # at the camera centre
        [30.0, 1.0, -3.5],  # 89 deg off-axis: the lens polynomial folds back here
    ])
    pixels, depth = camera.project(points)
    np.testing.assert_allclose(pixels[0], (camera.cx, camera.cy), atol=1e-9)
    np.testing.assert_array_equal(camera.visible(points), [True, False, False, False, False])
    np.testing.assert_array_equal(project_points([camera], points).visible[0], camera.visible(points))
    # Pixel-centre convention: the image spans [-0.5, W - 0.5).
    np.testing.assert_array_equal(
        camera.in_image([[-0.5, 0.0], [-0.51, 0.0], [639.49, 479.49], [639.5, 0.0], [0.0, 479.5]]),
        [True, False, True, False, False],
    )


def test_look_at_orientation_room_up():
    camera = look_at("cam", (0.0, 2.5, -3.0), ROOM_CENTRE)
    np.testing.assert_allclose(camera.position, (0.0, 2.5, -3.0), atol=1e-12)
    np.testing.assert_allclose(camera.optical_axis,
                               (ROOM_CENTRE - camera.position) / np.linalg.norm(ROOM_CENTRE - camera.position))
    # The target projects to the principal point; a point above it (+Y) is higher in the image (smaller v).
    (target_px, above_px, right_px), _ = camera.project(
        [ROOM_CENTRE, ROOM_CENTRE + (0, 0.5, 0), ROOM_CENTRE + (-0.5, 0, 0)])
    np.testing.assert_allclose(target_px, (319.5, 239.5), atol=1e-9)
    assert above_px[1] < target_px[1] - 50
    # Looking along +Z with +Y up, the room's -X axis is on the image right (right-handed frame).
    assert right_px[0] > target_px[0] + 50
    assert np.isclose(np.linalg.det(camera.R), 1.0)
    with pytest.raises(ValueError, match="parallel"):
        look_at("cam", (0.0, 3.0, 0.0), (0.0, 0.0, 0.0), up=ROOM_UP)


def test_pose_quaternion_round_trip():
    rng = np.random.default_rng(2)
    for camera in corner_rig():
        q = camera.pose_quaternion()
        assert q[3] >= 0 and np.isclose(np.linalg.norm(q), 1.0)
        np.testing.assert_allclose(quaternion_to_matrix(q), camera.R.T, atol=1e-12)
        again = PinholeCamera.from_pose(camera.name, camera.width, camera.height, camera.K, camera.position, q,
                                        D=camera.D)
        assert again.isclose(camera, atol=1e-12)
    # A rotation of 90 deg about +Y turns the optical axis (z) into room +X.
    s = np.sqrt(0.5)
    camera = PinholeCamera.from_pose("cam", 640, 480,
                                     np.diag([500.0, 500.0, 1.0]) + [[0, 0, 320], [0, 0, 240], [0, 0, 0]],
                                     (1.0, 2.0, 3.0), (0.0, s, 0.0, s))
    np.testing.assert_allclose(camera.optical_axis, (1.0, 0.0, 0.0), atol=1e-12)
    np.testing.assert_allclose(camera.position, (1.0, 2.0, 3.0), atol=1e-12)
    # Random quaternions survive matrix round trips up to the canonical sign (w >= 0).
    quats = rng.normal(size=(20, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    for q in quats:
        back = matrix_to_quaternion(quaternion_to_matrix(q))
        np.testing.assert_allclose(back, q * np.sign(q[3]), atol=1e-12)
    with pytest.raises(ValueError, match="unit quaternion"):
        PinholeCamera.from_pose("cam", 640, 480, camera.K, (0, 0, 0), (0.0, 0.0, 0.0, 1.1))


@pytest.mark.parametrize("D", [PLUMB_BOB, RATIONAL])
def test_undistort_matches_cv2_and_inverts_distortion(D):
    camera = corner_rig(D, "plumb_bob" if len(D) == 5 else "rational_polynomial")[1]
    u, v = np.meshgrid(np.linspace(-0.5, 639.5, 33), np.linspace(-0.5, 479.5, 25))
    pixels = np.stack([u, v], axis=-1)  # (25, 33, 2) batch
    xy = camera.undistort_points(pixels)
    assert xy.shape == pixels.shape and np.all(np.isfinite(xy))
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    ref = cv2_undistort(pixels.reshape(-1, 1, 2), camera.K, camera.D, None, criteria).reshape(pixels.shape)
    np.testing.assert_allclose(xy, ref, atol=1e-10)
    # Exact inverse of the distortion: re-distorting gives the pixels back.
    redistorted = distort_normalized(xy, camera.D)
    again = np.stack([camera.fx * redistorted[..., 0] + camera.cx, camera.fy * redistorted[..., 1] + camera.cy],
                     axis=-1)
    np.testing.assert_allclose(again, pixels, atol=1e-9)
    np.testing.assert_allclose(undistort_normalized(distort_normalized(xy, D), D), xy, atol=1e-12)
    # undistort_pixels equals cv2.undistortPoints with P = K.
    ref_px = cv2_undistort(pixels.reshape(-1, 1, 2), camera.K, camera.D, camera.K, criteria)
    np.testing.assert_allclose(camera.undistort_pixels(pixels), ref_px.reshape(pixels.shape), atol=1e-7)


def test_back_project_round_trip():
    rng = np.random.default_rng(3)
    points = room_points(rng, 300)
    for camera in corner_rig():
        pixels, depth = camera.project(points)
        np.testing.assert_allclose(camera.back_project(pixels, depth), points, atol=1e-9)
        rays = camera.back_project(pixels)
        np.testing.assert_allclose(np.linalg.norm(rays, axis=-1), 1.0, atol=1e-12)
        expected = (points - camera.position) / np.linalg.norm(points - camera.position, axis=-1, keepdims=True)
        np.testing.assert_allclose(rays, expected, atol=1e-9)
    cameras = corner_rig()
    pixels = project_points(cameras, points).pixels
    origins, directions = pixel_rays(cameras, pixels)
    assert origins.shape == (4, 3) and directions.shape == (4, 300, 3)
    # Every ray passes through its point: the cross product with (point - origin) vanishes.
    offsets = points[None] - origins[:, None]
    np.testing.assert_allclose(np.cross(directions, offsets), 0.0, atol=1e-8)


def test_triangulate_noise_free_and_masked():
    rng = np.random.default_rng(4)
    cameras = corner_rig(RATIONAL, "rational_polynomial")
    points = room_points(rng, 200)
    pixels = project_points(cameras, points).pixels
    np.testing.assert_allclose(triangulate(cameras, pixels), points, atol=1e-6)
    # Drop random views but keep at least two per point; a point with one view is NaN.
    valid = rng.random((4, 200)) > 0.4
    valid[:2, :] = valid[:2, :] | (valid.sum(axis=0) < 2)
    valid[:, 0] = [True, False, False, False]
    pixels_masked = np.where(valid[..., None], pixels, 1e6)  # garbage where invalid
    result = triangulate(cameras, pixels_masked, valid)
    assert np.all(np.isnan(result[0]))
    np.testing.assert_allclose(result[1:], points[1:], atol=1e-6)
    # NaN pixels count as invalid without a mask.
    pixels_nan = np.where(valid[..., None], pixels, np.nan)
    np.testing.assert_allclose(triangulate(cameras, pixels_nan)[1:], points[1:], atol=1e-6)


def test_triangulate_noise_is_small():
    rng = np.random.default_rng(5)
    cameras = corner_rig()
    points = room_points(rng, 500)
    pixels = project_points(cameras, points).pixels + rng.normal(scale=0.5, size=(4, 500, 2))
    error = np.linalg.norm(triangulate(cameras, pixels) - points, axis=-1)
    assert np.median(error) < 0.005  # half a pixel at ~4 m and f = 520 px is ~4 mm


def test_camera_info_dict_round_trip():
    camera = corner_rig(RATIONAL, "rational_polynomial")[2]
    info = camera.to_camera_info_dict()
    assert set(info) == {"width", "height", "K", "D", "distortion_model", "R", "P", "frame_id"}
    assert info["K"].shape == (3, 3) and info["R"].shape == (3, 3) and info["P"].shape == (3, 4)
    assert info["D"].shape == (8,) and info["distortion_model"] == "rational_polynomial"
    assert info["frame_id"] == "cam_3_optical_frame"
    np.testing.assert_array_equal(info["P"][:, :3], camera.K)
    again = PinholeCamera.from_camera_info(info, "cam_3", camera.position, camera.pose_quaternion())
    assert again.isclose(camera, atol=1e-12)
    # The name defaults to the frame id without its suffix; flattened K/R/P are accepted.
    flat = dict(info, K=info["K"].ravel(), R=info["R"].ravel(), P=info["P"].ravel())
    assert PinholeCamera.from_camera_info(flat, position=camera.position,
                                          quaternion=camera.pose_quaternion()).isclose(camera, atol=1e-12)


def test_scaled_camera_matches_resized_image():
    camera = corner_rig()[0]
    small = camera.scaled(0.25)
    assert small.size == (160, 120)
    rng = np.random.default_rng(6)
    points = room_points(rng, 50)
    big_px, _ = camera.project(points)
    small_px, _ = small.project(points)
    # cv2.resize maps pixel centres as u' = s (u + 0.5) - 0.5.
    np.testing.assert_allclose(small_px, 0.25 * (big_px + 0.5) - 0.5, atol=1e-9)
    np.testing.assert_array_equal(small.D, camera.D)
    np.testing.assert_allclose(small.projection[:, :3], small.K)
    # A lit pixel survives an area resize at the predicted place.
    image = np.zeros((480, 640), np.float32)
    image[200:204, 300:304] = 1.0  # centre (301.5, 201.5)
    resized = cv2.resize(image, small.size, interpolation=cv2.INTER_AREA)
    row, col = np.unravel_index(np.argmax(resized), resized.shape)
    np.testing.assert_allclose((col, row), 0.25 * (np.array([301.5, 201.5]) + 0.5) - 0.5, atol=0.01)
    with pytest.raises(ValueError):
        camera.scaled(0.0)


def test_validation_errors():
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    with pytest.raises(ValueError, match="distortion_model"):
        PinholeCamera("cam", 640, 480, K, distortion_model="equidistant")
    with pytest.raises(ValueError, match="at most 5"):
        PinholeCamera("cam", 640, 480, K, D=np.zeros(8))
    with pytest.raises(ValueError, match="K must"):
        PinholeCamera("cam", 640, 480, K[:2])
    with pytest.raises(ValueError, match="rotation"):
        PinholeCamera("cam", 640, 480, K, R=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="width"):
        PinholeCamera("cam", 0, 480, K)
    camera = PinholeCamera("cam", 640, 480, K, D=(0.1, 0.01))
    assert camera.D.shape == (5,) and camera.D[1] == 0.01  # padded to the model's length
    assert not camera.K.flags.writeable
    with pytest.raises(dataclasses.FrozenInstanceError):
        camera.name = "other"  # frozen
