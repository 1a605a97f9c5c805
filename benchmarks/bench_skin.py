#!/usr/bin/env python3
"""Skin probability map speed (the skin extremity detector of thesis sec. 2.5.1).

``extremity_detection`` with ``detector:=skin`` computes it per image inside the foreground;
this measures that cost at 640x480 (CPU time of the thread, median over 200 images of
sensor-like noise: the cost does not depend on the content).

    .venv/bin/python benchmarks/bench_skin.py
"""
from __future__ import annotations

import time

import numpy as np

from hmocap_ros.detection.skin import skin_probability


def main() -> None:
    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, (8, 480, 640, 3), dtype=np.uint8)
    mask = np.zeros((480, 640), np.uint8)
    mask[100:400, 250:400] = 255
    skin_probability(images[0], mask=mask)  # warm-up
    cpu = []
    for k in range(200):
        c0 = time.thread_time()
        skin_probability(images[k % len(images)], mask=mask)
        cpu.append(time.thread_time() - c0)
    ms = 1e3 * float(np.median(cpu))
    print(f"skin probability at 640x480 (map 320x240): median {ms:.2f} ms CPU per image "
          f"-> {1e3 / ms:.0f} images/s per core")


if __name__ == "__main__":
    main()
