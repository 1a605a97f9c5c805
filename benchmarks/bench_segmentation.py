"""Benchmark of the foreground segmentation: ms per frame and fps per camera, on one core.

Target (thesis set-up, 4 cameras x 25 fps on one core): <= 10 ms per 640x480 frame, clean-up
included. Run: ``python benchmarks/bench_segmentation.py [--width 640 --height 480 --frames 200]``.
A synthetic textured room with a moving blob and a cast shadow; numba and OpenCV limited to one
thread. Prints the split between the fused per-pixel kernel and the morphological clean-up.
"""

from __future__ import annotations

import argparse
import time

import cv2
import numba
import numpy as np

from hmocap_ros.segmentation import BackgroundModel, ForegroundParams, mask_scores
from hmocap_ros.segmentation.mask_cleanup import clean_mask


def textured_background(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    coarse = rng.uniform(50, 200, (h // 16 + 2, w // 16 + 2, 3)).astype(np.float32)
    bg = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
    fine = cv2.GaussianBlur(rng.normal(0, 15, (h, w, 3)).astype(np.float32), (0, 0), 1.0)
    return np.clip(bg + fine, 30, 225)


def make_frames(rng: np.random.Generator, h: int, w: int, n: int, noise: float = 3.0):
    """n pre-rendered frames (so rendering is not timed) and their true masks."""
    bg = textured_background(rng, h, w)
    frames, truths = [], []
    r = max(4, h // 8)
    for i in range(n):
        scene = bg.copy()
        cx = int(w * (0.2 + 0.6 * (0.5 + 0.5 * np.sin(i * 0.05))))
        cy = int(h * (0.5 + 0.2 * np.cos(i * 0.07)))
        shadow = np.zeros((h, w), np.uint8)
        cv2.ellipse(shadow, (cx + r, cy + r), (2 * r, r // 2), 0, 0, 360, 255, -1)
        scene[shadow > 0] *= 0.6
        truth = np.zeros((h, w), np.uint8)
        cv2.circle(truth, (cx, cy), r, 255, -1)
        scene[truth > 0] = (220, 40, 60)
        frames.append(np.clip(np.rint(scene + rng.normal(0, noise, scene.shape)), 0, 255).astype(np.uint8))
        truths.append(truth)
    learn = [np.clip(np.rint(bg + rng.normal(0, noise, bg.shape)), 0, 255).astype(np.uint8)
             for _ in range(8)]
    return learn, frames, truths


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--frames", type=int, default=100, help="frames per camera")
    ap.add_argument("--cameras", type=int, default=4, help="models run round robin, as one node would")
    ap.add_argument("--threads", type=int, default=1, help="numba and OpenCV threads (default 1)")
    args = ap.parse_args(argv)
    numba.set_num_threads(args.threads)
    cv2.setNumThreads(args.threads)
    rng = np.random.default_rng(0)
    learn, frames, truths = make_frames(rng, args.height, args.width, args.frames)
    params = ForegroundParams(learn_frames=len(learn))

    warm = BackgroundModel(params)  # numba compile or cache load, not timed
    for i, f in enumerate(learn + frames[:3]):
        warm.apply(f, i)

    models = [BackgroundModel(params) for _ in range(args.cameras)]
    for model in models:
        for i, f in enumerate(learn):
            model.apply(f, i)
    n = len(frames)
    masks = np.empty((args.cameras, n) + frames[0].shape[:2], np.uint8)
    times = np.empty((n, args.cameras))
    for i in range(n):
        for c, model in enumerate(models):
            k = (i + 17 * c) % n  # each camera at another point of the sequence
            t0 = time.perf_counter()
            masks[c, k] = model.apply(frames[k], len(learn) + i)
            times[i, c] = time.perf_counter() - t0

    model = models[0]
    clean_times = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        clean_mask(model.raw_mask, model._opening, model._closing, params.min_blob_area, params.max_hole_area)
        clean_times[i] = time.perf_counter() - t0

    f1 = mask_scores(masks, np.stack(truths)[None]).f1
    ms = 1e3 * times.ravel()
    median = float(np.median(ms))
    print(f"foreground segmentation {args.width}x{args.height}, {args.cameras} camera(s) x {n} frames, "
          f"{args.threads} thread(s), numba {numba.__version__}, OpenCV {cv2.__version__}")
    print(f"  per frame: median {median:.2f} ms, mean {ms.mean():.2f} ms, p95 {np.percentile(ms, 95):.2f} ms"
          f"  -> {1e3 / median:.0f} fps per camera, {1e3 / median / 25:.1f} cameras at 25 fps per core")
    print(f"  of which clean-up (opening, closing, blobs, holes): median {1e3 * np.median(clean_times):.2f} ms")
    print(f"  F1 vs truth (moving disc + cast shadow): mean {f1.mean():.4f}, min {f1.min():.4f}")
    target = 10.0
    print(f"  target <= {target:.0f} ms per frame (4 cameras x 25 fps on one core): "
          f"{'met' if median <= target else 'NOT met'}")


if __name__ == "__main__":
    main()
