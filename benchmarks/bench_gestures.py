"""Benchmark of gesture localization (thesis sec. 3.2): training samples/s and detection fps, one core.

Targets: 15 trees of depth 20 trained on ~100k samples in a few minutes; detection at >= 30 fps
on 640x480 depth frames with such a forest. Run:
``python benchmarks/bench_gestures.py [--width 640 --height 480 --trees 15 --depth 20 --quick]``.

Three forests are timed:

- ``shipped``: the default forest ``hmocap_ros/data/gesture_forest.npz`` (15 trees, depth <= 20,
  trained on 640x480 simulated bags) on frames of a freshly simulated 640x480 bag
  (``hmocap sim gestures``: a person gesturing in a furnished room, Kinect-like noise): the
  case the node runs.
- ``trained``: boosted training (sec. 3.2.3) on toy depth scenes (``gestures.synthetic``:
  clutter, a person, palm / tee hand shapes, Kinect-like noise and holes), timed on toy scenes.
- ``deep``: the same samples with random labels, so that every tree grows to the maximum depth
  with uncertain leaves (about 15k nodes per tree, mean path 18 at depth 20): the worst case for
  detection (no pixel is decided early) and for training.

Training speed is the bag samples grown per second (tree growth, sec. 3.2.1, on the toy set;
``--samples-per-class`` per class and tree, no mining). numba and OpenCV are limited to one
thread. Detection is timed per frame over a stream (``GestureDetector.update``: depth
conversion, forest votes, Parzen density, smoothing, localization) for several grid strides
(stride 4 = the node's default at 640x480); the median CPU time of the thread per frame (robust
to other processes on a shared machine) and the median wall-clock time are printed. The shipped
forest is timed with the node's ``vote_reach`` (pixels whose background lead no remaining tree
could plausibly overturn stop early) and with the exact vote (``vote_reach`` 1); the toy forests
with the node's.
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

from hmocap_ros.eval.gesture_eval import DEFAULT_MODEL, read_gesture_bag
from hmocap_ros.gestures import DetectorParams, ForestParams, GestureDetector, collect_samples, load_forest
from hmocap_ros.gestures.forest import frames_to_metres, train_forest_on_samples
from hmocap_ros.gestures.params import FeatureParams, PatchParams, TrainParams

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))  # test fixtures
from fixtures.toy_depth import TOY_CLASSES, focal_scale, toy_sequence

from hmocap_sim.gesture_dataset import generate


def train(samples, params: TrainParams, rng, label: str):
    t0, c0 = time.perf_counter(), time.thread_time()
    forest = train_forest_on_samples(samples, params.forest, params.features, rng, TOY_CLASSES)
    seconds, cpu = time.perf_counter() - t0, time.thread_time() - c0
    meta = forest.meta["training"]
    nodes = [t.n_nodes for t in forest.trees]
    depths = [t.max_depth for t in forest.trees]
    print(f"  {label:8s} {len(forest.trees)} trees in {seconds:6.1f} s ({cpu:6.1f} s CPU): "
          f"{meta['bag_samples_total']} bag samples, {meta['bag_samples_total'] / cpu:8.0f} samples/s of CPU "
          f"({meta['bag_samples_per_s']:.0f} wall), nodes/tree {np.mean(nodes):7.0f}, "
          f"max depth {max(depths)}, OOB error {meta['trees'][-1]['forest_oob_error']:.3f}")
    return forest


def time_detection(forest, frames, stride: int, scale: float, focal_px: float | None = None,
                   vote_reach: float = DetectorParams().vote_reach):
    params = DetectorParams(stride=stride, parzen_sigma_px=6.0 * scale, volume_radius_px_m=20.0 * scale,
                            suppression_radius_px_m=60.0 * scale, reference_focal_px=0.0, vote_reach=vote_reach)
    det = GestureDetector(forest, params, focal_px=focal_px)
    det.update(frames[0], 0)  # compile / warm caches, not timed
    wall, cpu = [], []
    for i, frame in enumerate(frames):
        t0, c0 = time.perf_counter(), time.thread_time()
        det.update(frame, (i + 1) * 33_333_333)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.thread_time() - c0)
    return np.median(cpu) * 1e3, np.median(wall) * 1e3


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--trees", type=int, default=15)
    ap.add_argument("--depth", type=int, default=20)
    ap.add_argument("--train-frames", type=int, default=300)
    ap.add_argument("--samples-per-class", type=int, default=35000,
                    help="balanced bag per class and tree (3 classes: ~100k samples per tree)")
    ap.add_argument("--frames", type=int, default=40, help="detection frames per stride")
    ap.add_argument("--strides", type=int, nargs="+", default=[3, 4, 5])
    ap.add_argument("--threads", type=int, default=1, help="numba and OpenCV threads (default 1)")
    ap.add_argument("--quick", action="store_true", help="5 trees, 120 training frames (a smoke run)")
    args = ap.parse_args(argv)
    if args.quick:
        args.trees, args.train_frames, args.samples_per_class, args.frames = 5, 120, 10000, 15
    numba.set_num_threads(args.threads)
    cv2.setNumThreads(args.threads)
    shape = (args.height, args.width)
    scale = focal_scale(shape)
    rng = np.random.default_rng(0)

    print(f"toy depth scenes {args.width}x{args.height}, {args.trees} trees, max depth {args.depth}, "
          f"{args.threads} thread(s)")
    frames, labels = toy_sequence(rng, args.train_frames, shape)
    params = TrainParams(
        features=FeatureParams(patch_half_size_px_m=85.0 * scale),
        patches=PatchParams(n_positive=200, n_negative=300, box_half_size_px_m=20.0 * scale),
        forest=ForestParams(n_trees=args.trees, max_depth=args.depth, samples_per_class=args.samples_per_class,
                            mining_rounds=0))
    samples = collect_samples(frames_to_metres(frames, params), labels, params.patches, params.features, rng,
                              len(TOY_CLASSES))
    print(f"training: {len(samples)} samples from {args.train_frames} frames, "
          f"per class {samples.class_counts().tolist()}")
    trained = train(samples, params, rng, "trained")
    noise = samples.subset(np.arange(len(samples)))
    noise.label = rng.integers(0, len(TOY_CLASSES), len(samples)).astype(np.int32)
    deep = train(noise, params, rng, "deep")

    test_frames, _ = toy_sequence(np.random.default_rng(1), args.frames, shape)
    shipped = load_forest(DEFAULT_MODEL)
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "bench.mcap"
        generate(bag, seed=77, subjects=1, subject_offset=7700, frames=args.frames, width=args.width,
                 height=args.height, contact=False, progress=False)
        sim = read_gesture_bag(bag)
    print(f"shipped forest: {len(shipped.trees)} trees, {shipped.n_nodes} nodes, max depth "
          f"{max(t.max_depth for t in shipped.trees)}, trained at fx {shipped.training_focal_px:g} px; "
          f"simulated frames fx {sim.focal_px:g} px")
    print(f"detection, {args.frames} frames per run, median ms of CPU per frame (one thread), its fps, "
          f"and median wall-clock ms (load from other processes shows there):")
    for stride in args.strides:
        row = []
        cpu, wall = time_detection(shipped, list(sim.depth), stride, scale, sim.focal_px)
        row.append(f"shipped {cpu:5.1f} ms {1e3 / cpu:5.1f} fps (wall {wall:5.1f})")
        cpu, wall = time_detection(shipped, list(sim.depth), stride, scale, sim.focal_px, 1.0)
        row.append(f"shipped exact vote {cpu:5.1f} ms {1e3 / cpu:5.1f} fps (wall {wall:5.1f})")
        for name, forest in (("trained", trained), ("deep", deep)):
            cpu, wall = time_detection(forest, test_frames, stride, scale)
            row.append(f"{name} {cpu:5.1f} ms {1e3 / cpu:5.1f} fps (wall {wall:5.1f})")
        gh, gw = (args.height + stride - 1) // stride, (args.width + stride - 1) // stride
        print(f"  stride {stride} ({gw}x{gh} grid): " + "   ".join(row))


if __name__ == "__main__":
    main()
