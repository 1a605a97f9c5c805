"""Robust DLT triangulation (geometry.triangulation.triangulate_robust) on the example rig: exact on
noise-free projections (with distortion), a wrong view is dropped by the reprojection test, too
few views give NaN."""
from pathlib import Path

import numpy as np

from hmocap_ros.geometry import reprojection_errors, triangulate, triangulate_robust
from hmocap_ros.geometry.rig import load_rig

ROOT = Path(__file__).resolve().parents[1]


def _setup(n=50, seed=0):
    rig = load_rig(ROOT / "config" / "rig_example.yaml")
    cams = list(rig)
    rng = np.random.default_rng(seed)
    points = rng.uniform([-1.0, -1.0, 0.1], [1.0, 1.0, 1.9], size=(n, 3))
    pixels = np.stack([cam.project(points)[0] for cam in cams])
    return cams, points, pixels


def test_noise_free_projections_triangulate_exactly():
    cams, points, pixels = _setup()
    assert any(np.abs(np.asarray(c.D)).max() > 0 for c in cams)  # distortion is exercised
    est, used = triangulate_robust(cams, pixels)
    np.testing.assert_allclose(est, points, atol=1e-6)
    assert used.all()
    assert np.nanmax(reprojection_errors(cams, est, pixels)) < 1e-4


def test_a_wrong_view_is_dropped_and_too_few_views_give_nan():
    cams, points, pixels = _setup()
    rng = np.random.default_rng(1)
    pixels = pixels + rng.normal(0, 0.5, pixels.shape)  # detector noise
    bad = pixels.copy()
    bad[2, :10] += 80.0  # view 2 saw something else for the first ten points
    plain = triangulate(cams, bad)
    robust, used = triangulate_robust(cams, bad, max_reprojection_px=15.0)
    err_plain = np.linalg.norm(plain[:10] - points[:10], axis=1)
    err_robust = np.linalg.norm(robust[:10] - points[:10], axis=1)
    assert err_plain.min() > 0.02 and err_robust.max() < 0.01
    assert not used[2, :10].any() and used[:, 10:].all()
    valid = np.zeros(pixels.shape[:2], bool)
    valid[0] = True  # one view only
    one, _ = triangulate_robust(cams, pixels, valid=valid)
    assert np.isnan(one).all()
