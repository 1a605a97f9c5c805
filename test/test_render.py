"""Tests of hmocap_ros.render and hmocap_sim.render against an exact reference and known synthetic scenes."""

from __future__ import annotations

import cv2
import numba
import numpy as np
import pytest

from hmocap_ros.geometry.pinhole_camera import look_at_pose as look_at
from hmocap_ros.geometry.projection import project_batch
from hmocap_ros.render import observed_counts, render_silhouettes, xor_counts
from hmocap_sim.render import (
    DirectionalLight,
    KinectNoise,
    Lighting,
    Material,
    PointLight,
    concatenate_meshes,
    depth_to_millimetres,
    face_range_mask,
    grid_quad,
    interpolate,
    kinect_depth,
    rasterize,
    render_shadow_map,
    shade,
)
from hmocap_sim.render.depth import projector_shadow
from hmocap_sim.render.reference import coverage_pairs, silhouette_reference, zbuffer_reference
from hmocap_sim.render.sensor import add_sensor_noise, random_illumination


def project_points(points, K, R, t, dist=None, *, near: float = 1e-3, scale: float = 1.0):
    """``project_batch`` of one point set into one camera: ``uv (N, 2)``, ``z (N,)``."""
    uv, z = project_batch(np.asarray(points, dtype=np.float64)[None], np.asarray(K)[None],
                          np.asarray(R)[None], np.asarray(t)[None],
                          None if dist is None else np.asarray(dist)[None], near=near, scale=scale)
    return uv[0, 0], z[0, 0]


@pytest.fixture(scope="module")
def body():
    # The shipped 2,400-triangle tracking body (in the repository, so CI renders the same mesh).
    from hmocap_ros.body import load_body_model

    model = load_body_model("tracking")
    return np.asarray(model.vertices, np.float64), np.asarray(model.faces, np.int32)


def _cameras(width, height, n=4, dist=True):
    f = 0.7 * width
    K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])
    eyes = [(2.5, 2.2, 2.0), (-2.5, 2.0, 2.5), (-2.0, 2.3, -2.5), (2.6, 1.5, -2.0)][:n]
    Rs, ts = zip(*(look_at(e, (0, 0.9, 0)) for e in eyes))
    d = np.tile([-0.15, 0.04, 0.001, -0.001, 0.0], (n, 1)) if dist else None
    return np.stack([K] * n), np.stack(Rs), np.stack(ts), d


def _poses(vertices, n, rng):
    out = []
    for _ in range(n):
        a = rng.uniform(-np.pi, np.pi)
        R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        out.append(vertices @ R.T + [rng.normal(0, 0.2), 0, rng.normal(0, 0.2)])
    return np.stack(out)


def _iou(a, b):
    a, b = a != 0, b != 0
    return (a & b).sum() / max((a | b).sum(), 1)


def test_silhouettes_match_exact_reference(body):
    verts, faces = body
    rng = np.random.default_rng(0)
    uv, _ = project_batch(_poses(verts, 3, rng), *_cameras(160, 120))
    masks = render_silhouettes(uv, faces, 120, 160)
    masks_front = render_silhouettes(uv, faces, 120, 160, front_only=True)
    assert masks.shape == (3, 4, 120, 160) and masks.dtype == np.uint8
    for b in range(3):
        for m in range(4):
            ref = silhouette_reference(uv[b, m], faces, 120, 160)
            assert ref.sum() > 100
            assert _iou(masks[b, m], ref) > 0.99
            assert _iou(masks_front[b, m], ref) > 0.99
            # Same coverage rule: in practice identical, pixel for pixel.
            assert np.count_nonzero(masks[b, m] != ref) <= 2


def test_random_triangle_soup_matches_reference():
    rng = np.random.default_rng(1)
    proj = rng.uniform(-30, 90, (300, 2)).astype(np.float32)
    proj[:5] = np.nan  # invalid vertices: their triangles are skipped by both
    faces = rng.integers(0, len(proj), (200, 3)).astype(np.int32)
    faces[:3, 2] = faces[:3, 1]  # degenerate triangles
    fast = render_silhouettes(proj, faces, 48, 64)
    ref = silhouette_reference(proj, faces, 48, 64)
    assert np.count_nonzero(fast != ref) <= 2


def test_top_left_rule_tiles_without_gaps_or_overlaps():
    # A 4 x 3 grid of unit squares with integer corners: every pixel centre lies on edges, so
    # only a consistent tie rule covers each of the 12 covered pixels exactly once.
    v, f = grid_quad((2.0, 1.0, 0.0), (4.0, 0, 0), (0, 3.0, 0), 4, 3)
    proj = v[:, :2]
    pairs = list(coverage_pairs(proj, f, 10, 10))
    covered = np.concatenate([y * 10 + x for _, y, x in pairs])
    assert len(covered) == 12 and len(np.unique(covered)) == 12
    mask = render_silhouettes(proj, f, 10, 10)
    assert mask.sum() == 12 and mask[1:4, 2:6].all()
    zbuf, face_id, _ = rasterize(proj, np.ones(len(v)), f, 10, 10)
    assert ((face_id >= 0) == (mask == 1)).all()


def _jittered_scene(body, seed: int, n_poses: int):
    """(uv, faces, rendered masks (B, 4, 120, 160), observed (4, 120, 160) 0/1, the generator
    for more draws): ``n_poses`` random poses in 4 views at 160x120, observed = the first
    pose shifted by ~2 px per view."""
    verts, faces = body
    rng = np.random.default_rng(seed)
    uv, _ = project_batch(_poses(verts, n_poses, rng), *_cameras(160, 120))
    rendered = render_silhouettes(uv, faces, 120, 160)
    observed = render_silhouettes(uv[0] + rng.normal(0, 2, (4, 1, 2)).astype(np.float32),
                                  faces, 120, 160)
    return uv, faces, rendered, observed, rng


def test_xor_counts_equal_numpy_xor(body):
    uv, faces, rendered, observed, rng = _jittered_scene(body, 2, 6)
    observed = observed * 255
    observed[:, 100:110, 10:30] = 255  # spurious foreground, as from a bad segmentation
    observed[rng.random(observed.shape) < 0.01] = 255
    expected = (rendered != (observed[None] != 0)).sum(axis=(2, 3))
    assert (xor_counts(uv, faces, observed) == expected).all()
    assert (xor_counts(uv, faces, observed, front_only=True) == expected).all()


def test_xor_counts_only_inside_box(body):
    verts, faces = body
    rng = np.random.default_rng(3)
    uv, _ = project_batch(_poses(verts, 4, rng), *_cameras(160, 120))
    rendered = render_silhouettes(uv, faces, 120, 160)
    observed = (rng.random((4, 120, 160)) < 0.3).astype(np.uint8)
    boxes = np.array([[40, 10, 120, 60], [-20, -5, 60, 200], [70, 50, 70, 90],
                      [150, 100, 400, 300]])  # normal, beyond the image, empty, corner
    diff = rendered != observed[None]
    expected = np.zeros((4, 4), np.int64)
    for m, (x0, y0, x1, y1) in enumerate(boxes):
        x0, x1 = np.clip([x0, x1], 0, 160)
        y0, y1 = np.clip([y0, y1], 0, 120)
        expected[:, m] = diff[:, m, y0:y1, x0:x1].sum(axis=(1, 2))
    got = xor_counts(uv, faces, observed, boxes)
    assert (got == expected).all()
    assert (got[:, 2] == 0).all()
    # Differences outside the box do not count.
    observed2 = observed.copy()
    observed2[0, :, :40] ^= 1
    assert (xor_counts(uv, faces, observed2, boxes)[:, 0] == got[:, 0]).all()
    assert observed_counts(observed, boxes)[2] == 0
    assert observed_counts(observed)[0] == observed[0].sum()


def test_zbuffer_keeps_the_nearer_triangle():
    proj = np.array([[10, 10], [50, 12], [20, 40], [5, 5], [45, 30], [30, 45]], np.float32)
    faces = np.array([[0, 1, 2], [3, 4, 5]], np.int32)
    for near_face, depth in ((0, [2, 2, 2, 3, 3, 3]), (1, [3, 3, 3, 2, 2, 2])):
        zbuf, face_id, bary = rasterize(proj, np.array(depth, np.float32), faces, 48, 64)
        both = (face_id >= 0) & (silhouette_reference(proj, faces[:1], 48, 64) == 1) \
            & (silhouette_reference(proj, faces[1:], 48, 64) == 1)
        assert both.sum() > 100
        assert (face_id[both] == near_face).all()
        assert np.allclose(zbuf[both], 2.0)
        assert np.allclose(bary[face_id >= 0].sum(axis=1), 1.0, atol=1e-5)
        assert np.isinf(zbuf[face_id < 0]).all()


def test_zbuffer_matches_reference_on_body(body):
    verts, faces = body
    K, R, t, dist = _cameras(160, 120, n=1)
    uv, z = project_points(verts, K[0], R[0], t[0], dist[0])
    zbuf, face_id, _ = rasterize(uv, z, faces, 120, 160)
    zr, fr = zbuffer_reference(uv, z, faces, 120, 160)
    assert np.count_nonzero(face_id != fr) <= 2
    hit = (face_id >= 0) & (face_id == fr)
    assert np.allclose(zbuf[hit], zr[hit], atol=1e-5)
    assert (render_silhouettes(uv, faces, 120, 160) == (face_id >= 0)).all()


def test_perspective_correct_barycentrics():
    # A slanted plane: interpolated world points must lie on it and reproject to the pixel.
    v, f = grid_quad((-1.0, -0.8, 1.5), (2.0, 0, 1.5), (0, 1.6, 0), 3, 2)
    K = np.array([[300.0, 0, 79.5], [0, 300.0, 59.5], [0, 0, 1]])
    uv, z = project_points(v, K, np.eye(3), np.zeros(3))
    zbuf, face_id, bary = rasterize(uv, z, f, 120, 160)
    world = interpolate(v, f, face_id, bary)
    hit = face_id >= 0
    assert hit.sum() > 5000
    p = world[hit].astype(np.float64)
    u = K[0, 0] * p[:, 0] / p[:, 2] + K[0, 2]
    vv = K[1, 1] * p[:, 1] / p[:, 2] + K[1, 2]
    ys, xs = np.nonzero(hit)
    assert np.abs(u - xs).max() < 1e-3 and np.abs(vv - ys).max() < 1e-3
    assert np.allclose(p[:, 2], zbuf[hit], rtol=1e-5)


def test_projection_matches_opencv():
    rng = np.random.default_rng(4)
    pts = rng.uniform([-1, -1, 2], [1, 1, 4], (100, 3))
    K = np.array([[500.0, 0.0, 320], [0, 510.0, 240], [0, 0, 1]])  # cv2 ignores skew
    R, t = look_at((0.2, -0.1, -0.3), (0, 0, 3))
    dist = np.array([-0.2, 0.05, 0.001, -0.002, 0.01])
    uv, z = project_points(pts, K, R, t, dist)
    ref, _ = cv2.projectPoints(pts, cv2.Rodrigues(R)[0], t, K, dist)
    assert np.abs(uv - ref[:, 0]).max() < 1e-3
    behind, _ = project_points(np.array([[0, 0, -1.0]]), K, np.eye(3), np.zeros(3))
    assert np.isnan(behind).all()
    # Scaling keeps pixel centres on integer coordinates: (u + 0.5) s - 0.5.
    uv4, _ = project_points(pts, K, R, t, dist, scale=0.25)
    assert np.allclose(uv4, (uv + 0.5) * 0.25 - 0.5, atol=1e-4)


def _plane_zbuf(distance=2.0, width=640, height=480, fx=580.0):
    v, f = grid_quad((-4.0, -3.0, distance), (8.0, 0, 0), (0, 6.0, 0), 8, 6)
    K = np.array([[fx, 0, (width - 1) / 2], [0, fx, (height - 1) / 2], [0, 0, 1]])
    uv, z = project_points(v, K, np.eye(3), np.zeros(3))
    return rasterize(uv, z, f, height, width, with_barycentrics=False)[0]


def test_depth_of_fronto_parallel_plane():
    zbuf = _plane_zbuf(2.0)
    assert np.allclose(zbuf, 2.0)
    assert (depth_to_millimetres(zbuf) == 2000).all()
    mm = kinect_depth(zbuf, np.random.default_rng(5), fx=580.0)
    assert mm.dtype == np.uint16
    valid = mm > 0
    assert 0.99 < valid.mean() < 0.999  # random dropouts only
    d = mm[valid].astype(np.float64)
    sigma = 0.0015 * 2.0**2 * 1000  # 6 mm at 2 m
    step = 0.125 / (580.0 * 0.075) * 2.0**2 * 1000  # disparity quantum at 2 m, ~11.5 mm
    assert abs(d.mean() - 2000) < 1.0
    assert 0.7 * sigma < d.std() < np.hypot(sigma, step)
    assert np.abs(d - 2000).max() < 6 * sigma + step
    # Farther is noisier (sigma ~ z^2).
    far = kinect_depth(_plane_zbuf(3.5), np.random.default_rng(5), fx=580.0)
    assert far[far > 0].std() > 2.5 * d.std()
    # Out of range reads 0.
    assert (kinect_depth(_plane_zbuf(5.0), np.random.default_rng(5), fx=580.0) == 0).all()


def test_depth_holes_at_discontinuities_and_projector_shadow():
    zbuf = np.full((60, 80), 3.0, np.float32)
    zbuf[20:40, 30:50] = 1.5  # a box in front of a wall
    shadow = projector_shadow(zbuf, fx=580.0, baseline_m=0.075)
    width = 580.0 * 0.075 * (1 / 1.5 - 1 / 3.0)  # ~14.5 px
    assert shadow[20:40, 30 - int(width) + 1:30].all()
    assert not shadow[20:40, 30 - int(width) - 2].any()
    assert not shadow[:, 30:].any() and not shadow[:20].any()
    params = KinectNoise(dropout=0.0, edge_dropout=1.0)
    mm = kinect_depth(zbuf, np.random.default_rng(6), fx=580.0, params=params)
    assert (mm[20:40, 50] == 0).all()  # right edge of the box: a discontinuity hole
    assert (mm[25:35, 35:45] > 0).all() and (mm[5:15, 60:75] > 0).all()


def _small_scene():
    floor = grid_quad((-2.0, 0, -2.0), (0, 0, 4.0), (4.0, 0, 0), 8, 8)
    wall = grid_quad((-2.0, 0, -2.0), (4.0, 0, 0), (0, 2.5, 0), 8, 5)
    blocker = grid_quad((-0.3, 1.0, -0.3), (0.6, 0, 0), (0, 0, 0.6), 2, 2)
    vertices, faces, face_off, _ = concatenate_meshes([floor, wall, blocker])
    mats = np.repeat([0, 1, 2], np.diff(face_off)).astype(np.int32)
    materials = [Material("plain", (0.6, 0.35, 0.2)),
                 Material("plaster", (0.8, 0.8, 0.75), (0.7, 0.7, 0.65), scale=0.4, noise=0.05),
                 Material("fabric", (0.2, 0.3, 0.7), scale=0.1, noise=0.2)]
    return vertices, faces, mats, materials, face_off, blocker


def _render_small_scene(seed_noise=None):
    vertices, faces, mats, materials, face_off, blocker = _small_scene()
    K = np.array([[200.0, 0, 79.5], [0, 200.0, 59.5], [0, 0, 1]])
    R, t = look_at((0.0, 2.2, 3.5), (0, 0.5, 0))
    uv, z = project_points(vertices, K, R, t)
    raster = rasterize(uv, z, faces, 120, 160)
    lamp = (0.0, 2.4, 0.0)
    smap = render_shadow_map(*blocker, light_position=lamp, size=128)
    lighting = Lighting(lights=(PointLight(lamp, (3.0, 3.0, 3.0), smap),
                                DirectionalLight((0, -1, -0.3), (0.1, 0.1, 0.1))))
    rgb = shade(raster, vertices, faces, mats, materials, -R.T @ t, lighting)
    if seed_noise is not None:
        rgb = add_sensor_noise(rgb, np.random.default_rng(seed_noise))
    return rgb, raster, (vertices, faces, K, R, t, face_off)


def test_shading_casts_a_shadow_and_marks_the_object():
    rgb, raster, (vertices, faces, K, R, t, face_off) = _render_small_scene()
    assert rgb.shape == (120, 160, 3) and rgb.dtype == np.uint8
    floor_below, _ = project_points(np.array([[0.0, 0.0, 0.1], [1.2, 0.0, 0.1]]), K, R, t)
    (u0, v0), (u1, v1) = np.rint(floor_below).astype(int)
    face_id = raster[1]
    assert face_id[v0, u0] < face_off[1] and face_id[v1, u1] < face_off[1]  # both floor
    # The floor under the blocker (shadowed from the lamp overhead) is darker than beside it
    # (compared in linear light: only the ambient term is left in the shadow).
    linear = (rgb.astype(np.float64) / 255.0) ** 2.2
    assert linear[v0, u0].sum() < 0.6 * linear[v1, u1].sum()
    mask = face_range_mask(face_id, face_off[2], face_off[3])
    uvb, _ = project_points(vertices[np.unique(faces[face_off[2]:])], K, R, t)
    assert mask.sum() > 50 and mask[tuple(np.rint(uvb.mean(0)).astype(int)[::-1])] == 1


def test_same_seed_same_bytes():
    a, *_ = _render_small_scene(seed_noise=7)
    b, *_ = _render_small_scene(seed_noise=7)
    c, *_ = _render_small_scene(seed_noise=8)
    assert a.tobytes() == b.tobytes() and a.tobytes() != c.tobytes()
    zbuf = _plane_zbuf(2.5, 160, 120, 145.0)
    d1 = kinect_depth(zbuf, np.random.default_rng(9), fx=145.0)
    d2 = kinect_depth(zbuf, np.random.default_rng(9), fx=145.0)
    assert d1.tobytes() == d2.tobytes()
    # The z-buffer does not depend on the thread count (row bands, faces in index order).
    vertices, faces, *_ = _small_scene()
    uv, z = project_points(vertices, np.array([[200.0, 0, 79.5], [0, 200.0, 59.5], [0, 0, 1]]),
                           *look_at((0.0, 2.2, 3.5), (0, 0.5, 0)))
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = rasterize(uv, z, faces, 120, 160)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        many = rasterize(uv, z, faces, 120, 160)
    finally:
        numba.set_num_threads(threads)
    assert all(x.tobytes() == y.tobytes() for x, y in zip(one, many))
    i1 = random_illumination(a, np.random.default_rng(3))
    i2 = random_illumination(a, np.random.default_rng(3))
    assert i1.tobytes() == i2.tobytes()
