#!/usr/bin/env python3
"""Layered (hierarchical) vs annealed particle filtering at equal numbers of evaluations.

The 24-dim multimodal kinematic-tree objective of ``fixtures.synthetic_chain``;
every filter starts from the same particle cloud around a wrong pose. Left: final marker error
against the evaluation budget (mean and standard deviation over the instances). Right: the error
of each layer's weighted-mean estimate against the evaluations spent so far, at one budget.

    PYTHONPATH=. .venv/bin/python tools/plot_layered_vs_annealed.py [--seeds 16] \
        [--out docs/figures/layered_vs_annealed.png]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import sys

import matplotlib.pyplot as plt
import numpy as np

from hmocap_ros.lpf import annealed_filter, hierarchical_filter, lpf_run

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))  # test fixtures
from fixtures.synthetic_chain import BLOCK_DIMS, make_chain_problem

LAYERS_PER_BLOCK = 2
N_LAYERS = len(BLOCK_DIMS) * LAYERS_PER_BLOCK + 1  # 15 weightings per run
BUDGETS = (750, 1500, 3000, 6000, 12000)
TRACE_BUDGET = 3000

# name -> (builder(problem, budget) -> (filter, weight_fn)), plot style
METHODS = {
    "APF, 15 layers, alpha 0.7 (eq. 2.10)": (
        lambda p, b: (annealed_filter(p.sigma, N_LAYERS, b // N_LAYERS, alpha=0.7,
                                      survival_rate=0.3), p.cost), dict(color="tab:blue")),
    "APF, 30 layers, alpha 0.8": (
        lambda p, b: (annealed_filter(p.sigma, 2 * N_LAYERS, b // (2 * N_LAYERS), alpha=0.8,
                                      survival_rate=0.3), p.cost),
        dict(color="tab:blue", linestyle="--")),
    "HPF, 7 blocks x 2 layers + final (alg. 3, nu 0.5)": (
        lambda p, b: (hierarchical_filter(BLOCK_DIMS, p.sigma, b // N_LAYERS,
                                          layers_per_block=LAYERS_PER_BLOCK, nu=0.5,
                                          survival_rate=0.3),
                      p.hierarchical_cost(LAYERS_PER_BLOCK)), dict(color="tab:red")),
}


def run(method: str, seed: int, budget: int):
    """One run on instance ``seed``: cumulative evaluations and per-layer estimate errors (m)."""
    problem = make_chain_problem(np.random.default_rng(1000 + seed))
    lpf, weight_fn = METHODS[method][0](problem, budget)
    x0 = problem.initial_particles(lpf.layers[0].n_particles, np.random.default_rng(seed))
    result = lpf_run(x0, lpf, weight_fn, np.random.default_rng(seed))
    evaluations = np.cumsum([d.n_evaluations for d in result.layers])
    layer_errors = problem.marker_error(np.array([d.estimate for d in result.layers]))
    return problem, evaluations, layer_errors


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=16)
    ap.add_argument("--out", type=Path, default=Path("docs/figures/layered_vs_annealed.png"))
    args = ap.parse_args()
    seeds = range(args.seeds)

    fig, (ax_budget, ax_trace) = plt.subplots(1, 2, figsize=(12, 4.6))
    problems = [make_chain_problem(np.random.default_rng(1000 + s)) for s in seeds]
    start = np.mean([p.marker_error(p.start)[0] for p in problems])
    print(f"start error (mean over {args.seeds} instances): {100 * start:.2f} cm")
    print("final marker error (cm), mean +- std over instances:")
    print(f"{'method':52s}" + "".join(f"{b:>14d}" for b in BUDGETS))
    for name, (_, style) in METHODS.items():
        runs = {b: [run(name, s, b) for s in seeds] for b in BUDGETS}
        finals = np.array([[r[2][-1] for r in runs[b]] for b in BUDGETS]) * 100
        evals = [runs[b][0][1][-1] for b in BUDGETS]
        mean, std = finals.mean(axis=1), finals.std(axis=1)
        print(f"{name:52s}" + "".join(f"{m:8.2f} +-{s:4.2f}" for m, s in zip(mean, std)))
        ax_budget.plot(evals, mean, marker="o", label=name, **style)
        ax_budget.fill_between(evals, mean - std, mean + std, alpha=0.15, color=style["color"])
        traces = runs[TRACE_BUDGET]
        ev = traces[0][1]
        errors = np.array([t[2] for t in traces]) * 100
        ax_trace.plot(np.concatenate([[0], ev]), np.concatenate([[100 * start], errors.mean(0)]),
                      marker=".", label=name, **style)
    ax_budget.set(xscale="log", xlabel="weight evaluations per run",
                  ylabel="mean marker error of the estimate (cm)",
                  title=f"final error vs budget ({args.seeds} instances, mean +- std)")
    ax_budget.set_xticks(BUDGETS, [str(b) for b in BUDGETS])
    ax_budget.set_ylim(bottom=0)
    ax_budget.grid(alpha=0.3)
    ax_budget.legend(fontsize=8)
    ax_trace.set(xlabel="weight evaluations so far", ylabel="error of the layer's estimate (cm)",
                 title=f"per-layer estimate, budget {TRACE_BUDGET} (mean over instances)")
    ax_trace.set_ylim(bottom=0)
    ax_trace.grid(alpha=0.3)
    fig.suptitle("Layered (hierarchical) vs annealed particle filtering, 24-dim multimodal "
                 "kinematic tree")
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
