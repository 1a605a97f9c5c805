#!/usr/bin/env python3
"""MediaPipe Pose on every view of a frame stack; runs in the peer venv (see peer_mediapipe.py).

    PEER_PYTHON tools/peer_mediapipe_worker.py IMAGES.npy OUT.npy

IMAGES.npy: (F, V, H, W, 3) uint8 RGB. OUT.npy: (F, V, 33, 3) float64 pixel x, pixel y and
visibility of MediaPipe's 33 landmarks (NaN where no person was found). One video-mode
tracker per view (``static_image_mode=False``, model_complexity 1, the full model shipped in
the wheel), as FreeMoCap runs it. Prints the milliseconds per image.
"""
import sys
import time

import mediapipe as mp
import numpy as np


def main() -> int:
    images = np.load(sys.argv[1], mmap_mode="r")
    n_frames, n_views, height, width = images.shape[:4]
    out = np.full((n_frames, n_views, 33, 3), np.nan)
    seconds = 0.0
    for v in range(n_views):
        with mp.solutions.pose.Pose(static_image_mode=False, model_complexity=1,
                                    smooth_landmarks=True, enable_segmentation=False) as pose:
            for f in range(n_frames):
                image = np.ascontiguousarray(images[f, v])
                t0 = time.perf_counter()
                res = pose.process(image)
                seconds += time.perf_counter() - t0
                if res.pose_landmarks is not None:
                    out[f, v] = [(lm.x * width, lm.y * height, lm.visibility)
                                 for lm in res.pose_landmarks.landmark]
    np.save(sys.argv[2], out)
    print(f"{1000 * seconds / (n_frames * n_views):.1f} ms per image", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
