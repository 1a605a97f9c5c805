"""Depth binary tests (thesis eq. 3.3, clipped eq. 3.6), depth conversion and patch collection,
on hand-made depth maps whose feature values are known."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from hmocap_ros.gestures import (
    DepthFormat,
    FeatureParams,
    PatchParams,
    collect_samples,
    depth_to_metres,
    evaluate_tests,
    random_offsets,
)
from hmocap_ros.gestures.depth_features import evaluate_tests_at_pixels

PLAIN = FeatureParams(feature_type="plain", background_depth_m=10.0)
CLIPPED = FeatureParams(feature_type="clipped", kappa_m=0.3, background_depth_m=10.0)


def reference_test(img, x, y, u, v, params: FeatureParams) -> float:
    """Eq. 3.3 / 3.6 written out in plain Python (probes rounded to the nearest pixel)."""
    d = float(img[y, x])

    def probe(o):
        px = math.floor(x + o[0] / d + 0.5)
        py = math.floor(y + o[1] / d + 0.5)
        if params.outside == "border":  # the nearest pixel of the image
            z = float(img[min(max(py, 0), img.shape[0] - 1), min(max(px, 0), img.shape[1] - 1)])
        elif not (0 <= px < img.shape[1] and 0 <= py < img.shape[0]):
            z = params.background_depth_m
        else:
            z = float(img[py, px])
        if params.clipped:
            z = max(min(z, d + params.kappa_m), d - params.kappa_m)
        return z

    return probe(u) - probe(v)


def test_depth_to_metres_units_and_invalid_values():
    fmt_mm = DepthFormat()  # REP 118: integers are millimetres, 0 invalid
    raw = np.array([[0, 1500, 20000], [250, 8000, 65535]], np.uint16)
    m = depth_to_metres(raw, fmt_mm, 10.0)
    assert m.dtype == np.float32
    np.testing.assert_allclose(m, [[10.0, 1.5, 10.0], [10.0, 8.0, 10.0]])  # 0.25 m < min, 20 m > max

    eighth = DepthFormat(unit_m=0.000125, invalid_value=0)
    m = depth_to_metres(np.array([[8000, 0]], np.uint16), eighth, 10.0)
    np.testing.assert_allclose(m, [[1.0, 10.0]])

    metres = np.array([[np.nan, 2.0, np.inf, -1.0]], np.float32)
    m = depth_to_metres(metres, DepthFormat(), 10.0)  # floats are metres
    np.testing.assert_allclose(m, [[10.0, 2.0, 10.0, 10.0]])

    odd = DepthFormat(unit_m=0.001, invalid_value=65535)
    m = depth_to_metres(np.array([[65535, 0, 3000]], np.uint16), odd, 10.0)
    np.testing.assert_allclose(m, [[10.0, 10.0, 3.0]])  # 0 is below min_depth anyway

    with pytest.raises(ValueError):
        depth_to_metres(np.zeros((2, 2, 3), np.uint16), fmt_mm, 10.0)
    with pytest.raises(ValueError):
        depth_to_metres(np.zeros((2, 2), np.uint16), DepthFormat(max_depth_m=12.0), 10.0)


def test_plain_test_values_on_a_step():
    img = np.full((20, 40), 2.0, np.float32)
    img[:, 25:] = 3.0  # a step 1 m further from column 25 on
    # At depth 2 m an offset of (20, 0) pixel*metres is 10 px.
    f = evaluate_tests_at_pixels(img, [10, 10], [5, 5],
                                 np.array([[20.0, 0.0, 0.0, 0.0], [-20.0, 0.0, 20.0, 0.0]], np.float32), PLAIN)
    np.testing.assert_allclose(f[0], [0.0, 0.0])  # column 20: still 2 m
    f = evaluate_tests_at_pixels(img, [20], [5], np.array([[20.0, 0.0, 0.0, 0.0]], np.float32), PLAIN)
    np.testing.assert_allclose(f, [[1.0]])  # column 30 is on the far side
    f = evaluate_tests_at_pixels(img, [20], [5], np.array([[0.0, 0.0, 20.0, 0.0]], np.float32), PLAIN)
    np.testing.assert_allclose(f, [[-1.0]])  # antisymmetric in u, v


def test_clipping_makes_background_beyond_kappa_look_the_same():
    """Eq. 3.6: the same hand in front of a wall at 3 m or at 5 m gives the same clipped tests."""
    tests = np.array([[30.0, 0.0, 0.0, 0.0],    # probe on the wall
                      [0.0, 0.0, 0.0, 0.0],     # no difference
                      [4.0, 0.0, -30.0, 0.0],   # on the 10 cm detail vs on the wall
                      [4.0, 0.0, 0.0, 0.0]],    # on the detail vs the reference pixel
                     np.float32)
    values = {}
    for wall in (3.0, 5.0):
        img = np.full((30, 60), wall, np.float32)
        img[:, 20:40] = 2.0  # the "hand": a band at 2 m; reference pixel (30, 15)
        img[:, 32:34] = 2.1  # a detail 10 cm behind it, within kappa
        values[wall] = (evaluate_tests_at_pixels(img, [30], [15], tests, CLIPPED)[0],
                        evaluate_tests_at_pixels(img, [30], [15], tests, PLAIN)[0])
    clipped3, plain3 = values[3.0]
    clipped5, plain5 = values[5.0]
    np.testing.assert_allclose(clipped3, clipped5)
    np.testing.assert_allclose(clipped3, [0.3, 0.0, 2.1 - 2.3, 0.1], atol=1e-6)  # wall -> d + kappa
    np.testing.assert_allclose(plain3, [1.0, 0.0, 2.1 - 3.0, 0.1], atol=1e-6)   # plain tests see the wall
    np.testing.assert_allclose(plain5, [3.0, 0.0, 2.1 - 5.0, 0.1], atol=1e-6)


def test_invalid_pixels_and_the_outside_read_as_far_background():
    raw = np.full((20, 40), 2000, np.uint16)
    raw[:, 30:] = 0  # no depth on the right
    img = depth_to_metres(raw, DepthFormat(), 10.0)
    tests = np.array([[30.0, 0.0, 0.0, 0.0],     # lands on an invalid pixel (column 25 + 15)
                      [200.0, 0.0, 0.0, 0.0],    # lands outside the image
                      [0.0, 0.0, 0.0, 0.0]], np.float32)
    far = dataclasses.replace(PLAIN, outside="background")
    plain = evaluate_tests_at_pixels(img, [25], [10], tests, far)[0]
    np.testing.assert_allclose(plain, [8.0, 8.0, 0.0])  # 10 m background - 2 m
    clipped = evaluate_tests_at_pixels(img, [25], [10], tests, dataclasses.replace(CLIPPED, outside="background"))[0]
    np.testing.assert_allclose(clipped, [0.3, 0.3, 0.0], atol=1e-6)  # "far": d + kappa


def test_outside_the_image_reads_the_nearest_border_pixel():
    """outside = 'border' (the default): the scene goes on beyond the frame, so a person cut by the
    image edge does not look like a small object in front of far background."""
    img = np.full((20, 40), 3.0, np.float32)
    img[:, 34:] = 2.0  # a body at 2 m entering from the right edge; reference pixel (36, 10)
    img[:, 38:] = 2.1  # the edge column differs, to tell it from the reference pixel
    img[0, 36] = 2.05  # the top edge above the reference pixel
    tests = np.array([[200.0, 0.0, 0.0, 0.0],     # beyond the right edge: column 39
                      [0.0, -200.0, 0.0, 0.0],    # beyond the top edge: row 0
                      [-40.0, 0.0, 200.0, 200.0]],  # on the wall vs beyond the bottom-right corner
                     np.float32)
    plain = evaluate_tests_at_pixels(img, [36], [10], tests, PLAIN)[0]
    np.testing.assert_allclose(plain, [0.1, 0.05, 3.0 - 2.1], atol=1e-6)
    clipped = evaluate_tests_at_pixels(img, [36], [10], tests, CLIPPED)[0]
    np.testing.assert_allclose(clipped, [0.1, 0.05, 2.3 - 2.1], atol=1e-6)


def render_square(depth: float, f: float = 200.0, shape=(120, 160)) -> np.ndarray:
    """A 20 cm square 30 cm in front of a wall, seen from ``depth`` (square) with focal ``f``."""
    h, w = shape
    img = np.full(shape, depth + 0.3, np.float32)
    half = 0.1 * f / depth
    ys, xs = np.mgrid[:h, :w]
    img[(np.abs(xs - w // 2) <= half) & (np.abs(ys - h // 2) <= half)] = depth
    return img


@pytest.mark.parametrize("params", [PLAIN, CLIPPED], ids=["plain", "clipped"])
def test_depth_normalised_offsets_see_the_same_object_at_twice_the_distance(params):
    f = 200.0
    # Probes at 7 cm (on the square) and 20 cm (on the wall) from the centre, in any direction.
    on, off = 0.07 * f, 0.2 * f
    tests = np.array([[on, 0, off, 0], [0, -on, 0, off], [off, off, -on, on], [-off, 0, on, on]], np.float32)
    near = render_square(1.0, f)
    far = render_square(2.0, f)
    f_near = evaluate_tests_at_pixels(near, [80], [60], tests, params)[0]
    f_far = evaluate_tests_at_pixels(far, [80], [60], tests, params)[0]
    np.testing.assert_allclose(f_near, f_far, atol=1e-6)
    assert np.any(np.abs(f_near) > 0.1)  # the tests do see the square's edge
    # Without the 1/d scaling (offsets fixed in pixels) the far view would probe elsewhere.
    f_far_unscaled = evaluate_tests_at_pixels(far, [80], [60], tests * 2.0, params)[0]
    assert not np.allclose(f_near, f_far_unscaled)


@pytest.mark.parametrize("params", [PLAIN, CLIPPED, dataclasses.replace(PLAIN, outside="background"),
                                    dataclasses.replace(CLIPPED, outside="background")],
                         ids=["plain", "clipped", "plain-far-outside", "clipped-far-outside"])
def test_kernel_matches_the_written_out_equation(params):
    rng = np.random.default_rng(3)
    frames = rng.uniform(0.8, 4.0, (3, 30, 50)).astype(np.float32)
    frames[rng.random(frames.shape) < 0.1] = params.background_depth_m  # invalid pixels
    s_frame = rng.integers(0, 3, 200)
    s_x, s_y = rng.integers(0, 50, 200), rng.integers(0, 30, 200)
    ok = frames[s_frame, s_y, s_x] < params.background_depth_m
    s_frame, s_x, s_y = s_frame[ok], s_x[ok], s_y[ok]
    offsets = random_offsets(rng, 12, FeatureParams(patch_half_size_px_m=40.0))
    got = evaluate_tests(frames, s_frame, s_x, s_y, offsets, params)
    assert got.shape == (s_frame.size, 12)
    want = np.array([[reference_test(frames[f], x, y, o[:2], o[2:], params) for o in offsets]
                     for f, x, y in zip(s_frame, s_x, s_y)])
    np.testing.assert_allclose(got, want, atol=1e-6)


def test_random_offsets_stay_in_the_patch_and_repeat_with_the_seed():
    p = FeatureParams(patch_half_size_px_m=50.0)
    a = random_offsets(np.random.default_rng(7), 1000, p)
    b = random_offsets(np.random.default_rng(7), 1000, p)
    assert a.shape == (1000, 4) and a.dtype == np.float32
    np.testing.assert_array_equal(a, b)
    assert np.abs(a).max() <= 50.0 and np.abs(a).max() > 45.0


def test_patch_collection_boxes_and_negative_frames():
    h, w = 60, 80
    wall = np.full((h, w), 4.0, np.float32)
    gesture = wall.copy()
    gesture[20:41, 30:51] = 2.0  # a 21 x 21 px "hand" at 2 m around (40, 30)
    frames = np.stack([gesture, wall])
    params = PatchParams(n_positive=30, n_negative=50, n_negative_near=0, box_half_size_px_m=12.0,
                         positive_depth_tolerance_m=0.1)
    s = collect_samples(frames, [(1, 40, 30), None], params, FeatureParams(), np.random.default_rng(0),
                        n_classes=3)
    assert s.n_classes == 3
    np.testing.assert_array_equal(s.class_counts(), [100, 30, 0])
    half = 12.0 / 2.0  # box half side in pixels at 2 m
    pos = s.label == 1
    assert np.all(s.frame[pos] == 0)
    assert np.all(np.abs(s.x[pos] - 40) <= half) and np.all(np.abs(s.y[pos] - 30) <= half)
    assert np.all(frames[0, s.y[pos], s.x[pos]] == 2.0)
    assert len(set(zip(s.x[pos], s.y[pos]))) == 30  # without replacement
    neg0 = (s.label == 0) & (s.frame == 0)
    assert neg0.sum() == 50
    assert np.all((np.abs(s.x[neg0] - 40) > half) | (np.abs(s.y[neg0] - 30) > half))
    assert ((s.label == 0) & (s.frame == 1)).sum() == 50

    # The wall seen through a box around an annotated point at the hand's edge is not positive.
    s = collect_samples(frames[:1], [(1, 30, 30)], params, FeatureParams(), np.random.default_rng(0))
    assert np.all(frames[0, s.y[s.label == 1], s.x[s.label == 1]] == 2.0)
    assert 0 < (s.label == 1).sum() <= 30

    # Near negatives: outside the box, inside the near square (30 px*m = 15 px at 2 m), nothing in
    # negative frames; the same uint16 millimetre frames give the same samples.
    near = dataclasses.replace(params, n_negative=0, n_negative_near=40, near_half_size_px_m=30.0)
    s = collect_samples(frames, [(1, 40, 30), None], near, FeatureParams(), np.random.default_rng(0))
    np.testing.assert_array_equal(s.class_counts(), [40, 30])
    neg = s.label == 0
    assert np.all(s.frame[neg] == 0)
    assert np.all((np.abs(s.x[neg] - 40) > half) | (np.abs(s.y[neg] - 30) > half))
    assert np.all((np.abs(s.x[neg] - 40) <= 15) & (np.abs(s.y[neg] - 30) <= 15))
    mm = np.rint(frames * 1000).astype(np.uint16)
    s_mm = collect_samples(mm, [(1, 40, 30), None], near, FeatureParams(), np.random.default_rng(0))
    for name in ("frame", "x", "y", "label"):
        np.testing.assert_array_equal(getattr(s_mm, name), getattr(s, name))
