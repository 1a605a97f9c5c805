"""Benchmark of the online random forest update (thesis sec. 3.3.1, alg. 6): samples/s on one core.

Run: ``python benchmarks/bench_online_forest.py [--samples 300000 --trees 15 --depth 20 --alpha 300]``
(about a minute). Target: >= 20,000 samples/s with 15 trees of depth <= 20. ``--bag BAG``
streams a simulated bag's frames instead (``hmocap sim gestures``; one update per frame, its
patches as the offline trainer collects them, random order, ``--samples`` of them).

The stream: toy depth scenes at 640x480 (``test/fixtures/toy_depth.py``: clutter, a person,
palm / tee hand shapes, Kinect-like noise and holes); each frame's patches (sec. 3.2.3, the
offline trainer's patch collection) are pooled and dealt out in class-balanced batches of
``--batch`` samples, one :meth:`OnlineForest.update` per batch (as one frame's patches; the
toy pool is mostly background, and balanced batches keep every class splitting, the trees
growing). Every tree takes every sample ``Poisson(1)`` times (alg. 6), so the samples/s count
samples that reach about 63 % of the trees each. numba is compiled (one update on a
throwaway forest) before timing, and numba and OpenCV are limited to one thread. Printed:
the samples/s by CPU time of the thread (robust to other processes) and wall-clock, the
sample-tree updates/s, the growth (nodes, open leaves, depth) and the memory of the forest
(the nodes, the open leaves' candidate tests and statistics, and the compressed forest file).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numba
import numpy as np

from hmocap_ros.gestures.forest_file import save_forest
from hmocap_ros.gestures.online_forest import OnlineForest
from hmocap_ros.gestures.params import OnlineParams, OnlineTrainParams, TrainParams
from hmocap_ros.gestures.patches import collect_samples

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))  # test fixtures
from fixtures.toy_depth import TOY_CLASSES, toy_sequence


def balanced_batches(samples, batch: int, n_total: int, rng: np.random.Generator):
    """Index arrays of class-balanced batches (equal counts per class, with replacement)."""
    by_class = [np.flatnonzero(samples.label == c) for c in range(samples.n_classes)]
    per = batch // len(by_class)
    out = []
    for _ in range(n_total // (per * len(by_class))):
        idx = np.concatenate([pool[rng.integers(0, pool.size, per)] for pool in by_class])
        out.append(np.sort(idx))
    return out


def toy_stream(ns, rng):
    """(samples, batches as index arrays, class names, tests, description) of toy scenes."""
    train = TrainParams()
    frames, labels = toy_sequence(rng, ns.frames, (480, 640))
    samples = collect_samples(np.stack(frames), labels, train.patches, train.features, rng, len(TOY_CLASSES))
    batches = balanced_batches(samples, ns.batch, ns.samples, rng)
    return samples, batches, TOY_CLASSES, train.features, (
        f"{len(batches)} balanced batches of {batches[0].size} samples from {ns.frames} toy frames 640x480 "
        f"({len(samples)} patches)")


def bag_stream(ns, rng):
    """The same from an annotated bag: one batch per frame (its patches as the offline trainer
    collects them), frames in random order, as many passes as ``--samples`` takes."""
    from hmocap_ros.eval.gesture_training_bags import read_training_bags

    data, _ = read_training_bags([ns.bag])
    params = OnlineTrainParams().for_focal(data.focal_px)
    samples = collect_samples(data.depth, data.labels, params.patches, params.features, rng, len(data.class_names))
    starts = np.searchsorted(samples.frame, np.arange(len(data.labels) + 1))
    batches, n = [], 0
    while n < ns.samples:
        for f in rng.permutation(len(data.labels)):
            if n >= ns.samples:
                break
            batches.append(np.arange(starts[f], starts[f + 1]))
            n += batches[-1].size
    return samples, batches, data.class_names, params.features, (
        f"{len(batches)} frame batches of {n / len(batches):.0f} samples on average from {ns.bag} "
        f"({len(data.labels)} frames {data.width}x{data.height})")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=300_000, help="samples streamed through the forest")
    ap.add_argument("--batch", type=int, default=600, help="samples per update (one frame's patches)")
    ap.add_argument("--frames", type=int, default=120, help="toy frames the samples come from")
    ap.add_argument("--bag", help="stream the patches of this annotated bag's frames instead of toy scenes")
    ap.add_argument("--trees", type=int, default=15)
    ap.add_argument("--depth", type=int, default=20)
    ap.add_argument("--alpha", type=float, default=OnlineParams().alpha)
    ap.add_argument("--tests", type=int, default=OnlineParams().n_tests, help="offset pairs per leaf")
    ap.add_argument("--thresholds", type=int, default=OnlineParams().n_thresholds, help="thresholds per pair")
    ns = ap.parse_args(argv)
    numba.set_num_threads(1)
    cv2.setNumThreads(1)
    params = OnlineParams(n_trees=ns.trees, max_depth=ns.depth, alpha=ns.alpha, n_tests=ns.tests,
                          n_thresholds=ns.thresholds)
    rng = np.random.default_rng(0)
    samples, batches, classes, features, description = (bag_stream if ns.bag else toy_stream)(ns, rng)
    print(f"stream: {description}; {params.n_trees} trees, depth <= {params.max_depth}, "
          f"{params.n_candidates} candidate tests per leaf ({params.n_tests} offset pairs x "
          f"{params.n_thresholds} thresholds), alpha {params.alpha:g}, beta {params.beta:g}, "
          f"lambda {params.poisson_lambda:g}")

    def update(forest, idx):
        return forest.update(samples.frames, samples.frame[idx], samples.x[idx], samples.y[idx],
                             samples.label[idx], rng)

    t0 = time.perf_counter()
    update(OnlineForest(classes, features, params, np.random.default_rng(1)), batches[0])
    print(f"numba compiled (or loaded from its cache) in {time.perf_counter() - t0:.1f} s, not timed")
    forest = OnlineForest(classes, features, params, np.random.default_rng(2))
    n_done = 0
    wall0, cpu0 = time.perf_counter(), time.thread_time()
    for k, idx in enumerate(batches):
        update(forest, idx)
        n_done += idx.size
        if (k + 1) % max(1, len(batches) // 5) == 0:
            cpu = time.thread_time() - cpu0
            print(f"  {n_done:8d} samples: {n_done / cpu:8.0f} samples/s of CPU so far, {forest.n_nodes:6d} nodes, "
                  f"{forest.n_open_leaves:5d} open leaves, max depth {int(forest.depth[:forest.n_nodes].max())}",
                  flush=True)
    wall, cpu = time.perf_counter() - wall0, time.thread_time() - cpu0
    report(forest, params, n_done, cpu, wall)
    return 0


def report(forest: OnlineForest, params: OnlineParams, n_done: int, cpu: float, wall: float) -> None:
    mem = forest.memory_bytes()
    with tempfile.TemporaryDirectory() as tmp:
        size = save_forest(forest.to_forest(), Path(tmp) / "online.npz").stat().st_size
    print(f"online update: {n_done} samples in {cpu:.1f} s CPU ({wall:.1f} s wall): "
          f"{n_done / cpu:.0f} samples/s of CPU ({n_done / wall:.0f} wall), "
          f"{n_done * params.n_trees * params.poisson_lambda / cpu:.0f} sample-tree updates/s; "
          f"{'meets' if n_done / cpu >= 20_000 else 'BELOW'} the 20,000 samples/s target")
    print(f"forest: {forest.n_nodes} nodes ({forest.n_nodes / params.n_trees:.0f} per tree), "
          f"{forest.n_open_leaves} open leaves; memory {mem['total'] / 1e6:.1f} MB "
          f"(nodes {mem['nodes'] / 1e6:.2f} MB, open leaves' tests and statistics "
          f"{mem['open_leaves'] / 1e6:.1f} MB = {mem['open_leaves'] / max(forest.n_open_leaves, 1) / 1e3:.1f} kB "
          f"each); forest file {size / 1e6:.1f} MB")


if __name__ == "__main__":
    sys.exit(main())
