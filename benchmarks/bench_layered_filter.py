#!/usr/bin/env python3
"""Overhead of the layered particle filter itself, weight evaluation excluded (N=500, D=30).

The weighting function returns precomputed costs, so every microsecond measured is the
filter's: annealing (beta bisection of the survival rate, eq. 2.9 weights), layered
systematic resampling (alg. 4), the Gaussian kernel with the alg. 3 std, limits, estimate.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_layered_filter.py [--particles 500] \
        [--dims 30] [--repeats 200]
"""
from __future__ import annotations

import argparse
import platform
import time

import numpy as np

from hmocap_ros.lpf import (
    Layer,
    annealed_filter,
    annealed_weights,
    beta_for_survival_rate,
    gaussian_kernel,
    gpf_run,
    hierarchical_filter,
    layered_resample,
    lpf_run,
    systematic_resample_indices,
)


def best_time(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, default=500)
    ap.add_argument("--dims", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=200)
    args = ap.parse_args()
    n, d, reps = args.particles, args.dims, args.repeats
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 1.0, (n, d))
    costs = rng.gamma(2.0, 5.0, n)
    sigma0 = np.full(d, 0.1)
    weights = annealed_weights(costs, 0.05)
    half = np.zeros(d, dtype=bool)
    half[: d // 2] = True
    std_all, std_block = sigma0.copy(), np.where(np.arange(d) < 5, 0.1, 0.0)

    def precomputed(particles: np.ndarray, layer_index: int) -> np.ndarray:
        return costs[: particles.shape[0]]

    print(f"N={n} particles, D={d} dims, best of {reps}; numpy {np.__version__}, "
          f"{platform.processor() or platform.machine()}")
    stages = [
        ("beta bisection (survival rate 0.5)", lambda: beta_for_survival_rate(costs, 0.5)),
        ("weights exp(-beta cost), eq. 2.8/2.9", lambda: annealed_weights(costs, 0.05)),
        ("systematic resampling indices", lambda: systematic_resample_indices(weights, n, rng)),
        ("layered resampling, all dims (alg. 4)",
         lambda: layered_resample(x, weights, np.ones(d, bool), rng)),
        ("layered resampling, half the dims", lambda: layered_resample(x, weights, half, rng)),
        ("Gaussian kernel, all dims", lambda: gaussian_kernel(x.copy(), std_all, rng)),
        ("Gaussian kernel, 5 dims", lambda: gaussian_kernel(x.copy(), std_block, rng)),
        ("one layer, fixed beta (alg. 1)",
         lambda: gpf_run(x, precomputed, std_all, rng, Layer(beta=0.05))),
        ("one layer, survival-rate beta",
         lambda: gpf_run(x, precomputed, std_all, rng, Layer())),
        ("one layer, survival-rate beta, limits, half dims",
         lambda: gpf_run(x, precomputed, std_all, rng, Layer(), filtered=half,
                         lower=np.full(d, -3.0), upper=np.full(d, 3.0))),
    ]
    for name, fn in stages:
        print(f"  {name:50s} {best_time(fn, reps) * 1e6:8.1f} us")

    blocks = np.array_split(np.arange(d), 10)
    for label, lpf in (("APF, 10 layers + final", annealed_filter(sigma0, 11, n)),
                       ("HPF, 10 blocks + final", hierarchical_filter(blocks, sigma0, n))):
        times = []
        for _ in range(max(reps // 10, 3)):
            r = lpf_run(x, lpf, precomputed, rng)
            times.append(sum(dg.filter_time_s for dg in r.layers) / len(r.layers))
        print(f"  lpf_run {label:42s} {min(times) * 1e6:8.1f} us per layer (filter only)")


if __name__ == "__main__":
    main()
