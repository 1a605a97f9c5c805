"""Layered particle filtering (thesis sec. 2.2, alg. 1-5): building blocks, synthetic comparison.

Fast (about a second): small particle sets, synthetic objectives with a known optimum.
"""
from __future__ import annotations

import numpy as np
import pytest
from fixtures.synthetic_chain import BLOCK_DIMS, N_DIMS, make_chain_problem

from hmocap_ros.lpf import (
    Layer,
    LayeredFilter,
    annealed_filter,
    annealed_weights,
    annealing_stds,
    beta_for_survival_rate,
    clip_to_bounds,
    effective_sample_size,
    gaussian_kernel,
    gpf_run,
    hierarchical_filter,
    identity_kernel,
    layer_diffusion_stds,
    layered_resample,
    lpf_run,
    survival_rate,
    systematic_resample_indices,
)


def quadratic_cost(target: np.ndarray, scale: float = 0.1):
    def weight_fn(particles: np.ndarray, layer_index: int) -> np.ndarray:
        return np.sum((particles - target) ** 2, axis=1) / scale**2
    return weight_fn


# ----------------------------------------------------------------------------- weights, beta


def test_annealed_weights_follow_eq_2_8_and_2_9():
    costs = np.array([0.0, 1.0, 2.0, np.inf, np.nan])
    w = annealed_weights(costs, 1.0)
    expected = np.exp(-costs[:3]) / np.exp(-costs[:3]).sum()
    np.testing.assert_allclose(w[:3], expected)
    assert w[3] == 0.0 and w[4] == 0.0
    # w^beta: beta -> 0 flattens, large beta concentrates on the best particle
    assert survival_rate(annealed_weights(costs[:3], 1e-9)) == pytest.approx(1.0)
    assert annealed_weights(costs[:3], 1e3)[0] == pytest.approx(1.0)
    # huge costs do not underflow to 0/0
    assert np.isfinite(annealed_weights(np.array([1e6, 1e6 + 1.0]), 1.0)).all()
    with pytest.raises(ValueError, match="no finite cost"):
        annealed_weights(np.array([np.inf, np.nan]), 1.0)


def test_effective_sample_size():
    assert effective_sample_size(np.full(8, 1 / 8)) == pytest.approx(8.0)
    assert effective_sample_size(np.eye(1, 8)[0]) == pytest.approx(1.0)


@pytest.mark.parametrize("target", [0.1, 0.3, 0.5, 0.9])
def test_beta_bisection_hits_the_survival_rate(target):
    costs = np.random.default_rng(3).gamma(2.0, 5.0, 500)
    beta = beta_for_survival_rate(costs, target)
    assert beta > 0.0
    assert survival_rate(annealed_weights(costs, beta)) == pytest.approx(target, rel=2e-3)


def test_beta_bisection_edge_cases():
    costs = np.random.default_rng(4).gamma(2.0, 5.0, 200)
    free = beta_for_survival_rate(costs, 0.5)
    assert beta_for_survival_rate(costs, 0.5, beta_max=free / 10) == pytest.approx(free / 10)
    assert beta_for_survival_rate(np.full(10, 3.0), 0.5) == 1.0  # weights do not depend on beta
    # only 2 finite costs of 10: even beta=0 keeps 20% < 50%
    few = np.array([1.0, 2.0] + [np.inf] * 8)
    assert beta_for_survival_rate(few, 0.5) == 0.0
    with pytest.raises(ValueError):
        beta_for_survival_rate(np.full(4, np.nan), 0.5)


# ----------------------------------------------------------------------------- diffusion


def test_annealing_stds_eq_2_10():
    sigma0 = np.array([1.0, 2.0])
    stds = annealing_stds(sigma0, [0.5, 0.25, 0.8], 4)
    expected_var_scale = [1.0, 0.5, 0.125, 0.1]
    np.testing.assert_allclose(stds**2, np.outer(expected_var_scale, sigma0**2))
    with pytest.raises(ValueError):
        annealing_stds(sigma0, [0.5], 4)
    with pytest.raises(ValueError):
        annealing_stds(sigma0, 1.5, 3)


def test_alg_3_reduces_to_eq_2_10_for_annealing_layers():
    sigma0 = np.array([0.3, 0.1, 0.2])
    nu = 0.7
    all_dims = [np.arange(3)] * 5
    np.testing.assert_allclose(layer_diffusion_stds(all_dims, sigma0, nu),
                               annealing_stds(sigma0, nu**2, 5))


def test_alg_3_hierarchical_table():
    # Psi_0 = {0, 1}, Psi_1 = {2}, Psi_2 = {3}, Psi_3 = {0..3}; dim 4 is never sampled.
    dims = [np.array([0, 1]), np.array([2]), np.array([3]), np.arange(4)]
    stds = layer_diffusion_stds(dims, np.ones(5), 0.5)
    expected = np.array([[1.0, 1.0, 0.0, 0.0, 0.0],
                         [0.5, 0.5, 1.0, 0.0, 0.0],       # earlier dims re-diffused with nu
                         [0.25, 0.25, 0.5, 1.0, 0.0],
                         [1.0, 1.0, 1.0, 0.5, 0.0]])      # 0-2 re-enter (not in Psi_2): sigma
    np.testing.assert_allclose(stds, expected)


def test_gaussian_kernel_touches_only_diffused_dims():
    rng = np.random.default_rng(0)
    x = np.zeros((20000, 4))
    std = np.array([0.0, 0.5, 0.0, 2.0])
    out = gaussian_kernel(x.copy(), std, rng)
    assert np.all(out[:, [0, 2]] == 0.0)
    np.testing.assert_allclose(out.std(axis=0)[[1, 3]], [0.5, 2.0], rtol=0.03)
    assert identity_kernel(x, std, rng) is x
    clipped = clip_to_bounds(out, np.full(4, -1.0), np.full(4, 1.0))
    assert clipped.min() >= -1.0 and clipped.max() <= 1.0


# ----------------------------------------------------------------------------- resampling


def test_systematic_resampling_counts_are_floor_or_ceil():
    rng = np.random.default_rng(1)
    w = rng.random(50) ** 4
    w /= w.sum()
    for n_out in (50, 37, 200):
        counts = np.bincount(systematic_resample_indices(w, n_out, rng), minlength=50)
        assert counts.sum() == n_out
        assert np.all(counts >= np.floor(n_out * w) - 1e-9)
        assert np.all(counts <= np.ceil(n_out * w) + 1e-9)


def test_layered_resampling_copies_only_filtered_dims():
    rng = np.random.default_rng(2)
    x = rng.standard_normal((40, 6))
    w = rng.random(40) ** 3
    w /= w.sum()
    filtered = np.array([True, True, False, True, False, False])
    out = layered_resample(x, w, filtered, np.random.default_rng(5))
    # unfiltered dims keep their own values (alg. 4 line 10-11 only assigns filtered ones)
    np.testing.assert_array_equal(out[:, ~filtered], x[:, ~filtered])
    # filtered dims of each output come together from one source particle, the same one
    # that plain resampling with the same random draw picks
    idx = systematic_resample_indices(w, 40, np.random.default_rng(5))
    np.testing.assert_array_equal(out[:, filtered], x[idx][:, filtered])
    plain = layered_resample(x, w, np.ones(6, dtype=bool), np.random.default_rng(5))
    np.testing.assert_array_equal(plain, x[idx])
    # a different output count cycles the unfiltered values
    more = layered_resample(x, w, filtered, rng, n_out=60)
    np.testing.assert_array_equal(more[:, ~filtered], x[np.arange(60) % 40][:, ~filtered])


# ----------------------------------------------------------------------------- runs


def test_gpf_run_alg_1():
    rng = np.random.default_rng(6)
    target = np.array([1.0, -1.0])
    x = rng.normal(0.0, 1.0, (500, 2))
    out, w, diag = gpf_run(x, quadratic_cost(target, 1.0), np.array([0.05, 0.05]), rng,
                           layer=Layer(beta=1.0), layer_index=3)
    assert out.shape == x.shape and w.shape == (500,)
    assert diag.layer == 3 and diag.beta == 1.0 and diag.n_evaluations == 500
    assert diag.ess == pytest.approx(effective_sample_size(w))
    np.testing.assert_allclose(diag.estimate, w @ x)
    # N(0, 1) prior times exp(-|x - t|^2) (a N(t, 1/2) likelihood): posterior mean 2t/3
    np.testing.assert_allclose(out.mean(axis=0), target * 2 / 3, atol=0.1)


def test_lpf_run_is_deterministic_batched_and_reports_layers():
    target = np.linspace(-1.0, 1.0, 8)
    calls = []

    def weight_fn(particles, layer_index):
        calls.append((layer_index, particles.shape))
        return quadratic_cost(target)(particles, layer_index)

    lpf = hierarchical_filter([np.arange(4), np.arange(4, 8)], np.full(8, 0.3), 100,
                              layers_per_block=2)
    x0 = np.random.default_rng(7).normal(0.0, 0.5, (100, 8))
    a = lpf_run(x0, lpf, weight_fn, np.random.default_rng(11))
    assert calls == [(layer, (100, 8)) for layer in range(5)]  # one batch call per layer
    b = lpf_run(x0, lpf, weight_fn, np.random.default_rng(11))
    c = lpf_run(x0, lpf, weight_fn, np.random.default_rng(12))
    np.testing.assert_array_equal(a.particles, b.particles)
    np.testing.assert_array_equal(a.estimate, b.estimate)
    assert not np.array_equal(a.particles, c.particles)
    assert len(a.layers) == lpf.n_layers == 5 and a.n_evaluations == 500
    for d in a.layers:
        assert d.survival_rate == pytest.approx(0.5, rel=2e-3)
        assert d.beta > 0.0 and d.weight_time_s >= 0.0 and d.filter_time_s >= 0.0
    np.testing.assert_allclose(a.estimate, a.weights @ a.weighted_particles)
    np.testing.assert_array_equal(x0, np.random.default_rng(7).normal(0.0, 0.5, (100, 8)))


def test_lpf_keeps_unfiltered_dims_of_each_particle():
    seen = {}

    def weight_fn(particles, layer_index):
        seen[layer_index] = particles.copy()
        return np.sum(particles[:, :2] ** 2, axis=1)

    lpf = LayeredFilter(layers=(Layer(dims=[0, 1], beta=1.0), Layer(dims=[2, 3], beta=1.0)),
                        sigma0=np.full(5, 0.2))
    x0 = np.random.default_rng(8).normal(0.0, 1.0, (64, 5))
    lpf_run(x0, lpf, weight_fn, np.random.default_rng(9))
    # layer 1 weighs a set whose dims 2-4 are still the input's, particle by particle
    np.testing.assert_array_equal(seen[1][:, 2:], x0[:, 2:])
    # the final layer sees dims 2-3 resampled and diffused, dim 4 untouched since the start
    np.testing.assert_array_equal(seen[2][:, 4], x0[:, 4])
    assert not np.array_equal(seen[2][:, 2:4], x0[:, 2:4])


def test_lpf_particle_counts_bounds_and_estimate():
    shapes = []

    def weight_fn(particles, layer_index):
        shapes.append(particles.shape[0])
        assert particles.min() >= -0.5 or layer_index == 0
        return np.sum((particles - 0.4) ** 2, axis=1)

    lpf = LayeredFilter(layers=(Layer(n_particles=100), Layer(n_particles=30),
                                Layer(n_particles=80)),
                        sigma0=np.full(3, 0.5), final=Layer(n_particles=60),
                        lower=np.full(3, -0.5), upper=np.full(3, 0.5))
    x0 = np.random.default_rng(10).uniform(-1.0, 1.0, (100, 3))
    r = lpf_run(x0, lpf, weight_fn, np.random.default_rng(0))
    assert shapes == [100, 30, 80, 60]
    assert r.particles.shape == (100, 3)  # ready for the first layer of the next frame
    assert r.particles.min() >= -0.5 and r.particles.max() <= 0.5
    assert np.allclose(r.estimate, r.weights @ r.weighted_particles)
    with pytest.raises(ValueError, match="first layer weighs 100"):
        lpf_run(x0[:50], lpf, weight_fn, np.random.default_rng(0))


def test_lpf_rejects_bad_input():
    lpf = annealed_filter(np.full(3, 0.1), 3, alpha=0.5)
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="shape"):
        lpf_run(np.zeros((10, 4)), lpf, quadratic_cost(np.zeros(3)), rng)
    with pytest.raises(ValueError, match="weight_fn returned shape"):
        lpf_run(np.zeros((10, 3)), lpf, lambda x, layer: np.zeros(5), rng)
    with pytest.raises(ValueError, match="no finite cost"):
        lpf_run(np.zeros((10, 3)), lpf, lambda x, layer: np.full(10, np.nan), rng)
    with pytest.raises(ValueError, match="dims out of range"):
        LayeredFilter(layers=(Layer(dims=[5]),), sigma0=np.ones(3))


def test_custom_kernel_hook_and_fixed_betas():
    seen_std = []

    def kernel(particles, std, rng):
        seen_std.append(std.copy())
        return gaussian_kernel(particles, std, rng)

    lpf = LayeredFilter(layers=(Layer(beta=0.1, kernel=kernel), Layer(beta=0.5, kernel=kernel)),
                        sigma0=np.full(2, 0.4), nu=0.5, final=Layer(beta=1.0, std=np.zeros(2)))
    x0 = np.random.default_rng(1).normal(0.0, 1.0, (50, 2))
    r = lpf_run(x0, lpf, quadratic_cost(np.zeros(2), 1.0), np.random.default_rng(2))
    np.testing.assert_allclose(seen_std, [[0.4, 0.4], [0.2, 0.2]])  # alg. 3 with nu = 0.5
    assert [d.beta for d in r.layers] == [0.1, 0.5, 1.0]
    # zero final std: the next-frame set is the resampled final set, undiffused
    assert all(any(np.array_equal(p, q) for q in r.weighted_particles) for p in r.particles)


def test_annealed_filter_converges_on_a_quadratic_and_tracks_over_frames():
    rng = np.random.default_rng(3)
    d = 10
    target = rng.normal(0.0, 1.0, d)
    lpf = annealed_filter(np.full(d, 0.3), 8, 300, alpha=0.6, final_std=np.full(d, 0.05))
    x = target + rng.normal(0.0, 0.5, (300, d))
    for frame in range(5):
        target = target + 0.03  # slow motion: the final kernel K_t carries the set along
        r = lpf_run(x, lpf, quadratic_cost(target), rng)
        x = r.particles
        assert np.linalg.norm(r.estimate - target) < 0.15 + 0.3 * (frame == 0)


# ----------------------------------------------------------------------------- comparison

N_PARTICLES, LAYERS_PER_BLOCK = 200, 2
N_LAYERS = len(BLOCK_DIMS) * LAYERS_PER_BLOCK + 1   # 15 weightings for both filters


def chain_errors(seed: int) -> tuple[float, float, float]:
    """Start error and final marker error (m) of APF and HPF on one synthetic instance."""
    problem = make_chain_problem(np.random.default_rng(1000 + seed))
    x0 = problem.initial_particles(N_PARTICLES, np.random.default_rng(seed))
    apf = annealed_filter(problem.sigma, N_LAYERS, N_PARTICLES, alpha=0.7, survival_rate=0.3)
    hpf = hierarchical_filter(BLOCK_DIMS, problem.sigma, N_PARTICLES,
                              layers_per_block=LAYERS_PER_BLOCK, nu=0.5, survival_rate=0.3)
    ra = lpf_run(x0, apf, problem.cost, np.random.default_rng(seed))
    rh = lpf_run(x0, hpf, problem.hierarchical_cost(LAYERS_PER_BLOCK), np.random.default_rng(seed))
    assert ra.n_evaluations == rh.n_evaluations == N_LAYERS * N_PARTICLES
    return (problem.marker_error(problem.start)[0], problem.marker_error(ra.estimate)[0],
            problem.marker_error(rh.estimate)[0])


def test_layered_beats_annealed_at_equal_evaluations():
    """24-dim multimodal kinematic tree, 15 layers x 200 particles each, 8 instances."""
    assert N_DIMS == 24
    start, apf, hpf = np.array([chain_errors(seed) for seed in range(8)]).T
    assert np.all(apf < 0.5 * start)           # the annealed filter works...
    assert hpf.mean() < 0.7 * apf.mean()       # ...the hierarchical one works clearly better
    assert np.sum(hpf < apf) >= 7
