#!/usr/bin/env python3
"""Keypoint detector speed: the landmark network per view and whole frame sets of 4 views.

The scene: a simulated room rendered here (``hmocap_ros.sim``, 4 cameras at 640x480, a subject
with one arm raised sideways), the exact silhouettes as foreground masks. Measured:

- **network per view**: :meth:`PoseLandmarkNetwork.run` (crop, BlazePose "Pose landmark
  full" on OpenCV dnn, heatmap refinement, back to image pixels) on each view's crop, with
  1 and 2 OpenCV threads: median wall-clock and thread CPU milliseconds per view;
- **frame sets per second**: :meth:`KeypointDetector.detect` on the 4 views (crops, networks,
  robust triangulation) for the worker / OpenCV-thread settings below, median wall clock,
  with the CPU time of the process (all its threads) and the median time of each stage.

The network's time does not depend on the image content, so one frame set is repeated. On a
machine shared with other processes the wall-clock figures grow with the load average,
printed first; the CPU figures do not.

    .venv/bin/python benchmarks/bench_keypoints.py [--repeats 12]
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import cv2
import numpy as np

from hmocap_ros.detection import KeypointDetector, KeypointParams, PoseLandmarkNetwork, roi_box

SETTINGS = ((1, 2), (1, 1), (2, 1))  # (workers, OpenCV threads) of the detector


def render_scene():
    """(rig, 4 RGB images, 4 silhouettes) of a simulated room with one subject."""
    from hmocap_ros.body import load_body_model
    from hmocap_ros.sim.appearance import dress, sample_appearance
    from hmocap_ros.sim.mocap_dataset import make_rig
    from hmocap_ros.sim.mocap_render import FrameState, MocapRenderer, RenderOptions
    from hmocap_ros.sim.room import build_room

    rng = np.random.default_rng(3)
    rig = make_rig(4, 640, 480)
    full = load_body_model("hands", "full")
    look = dress(full, sample_appearance(rng))
    renderer = MocapRenderer(rig, build_room(rng), [(full.faces, look)], RenderOptions(noise=False))
    params = full.rest_pose()[None]
    params[:, full.skeleton.dof_index("l_shoulder_abd")] = 0.6
    params[:, full.skeleton.dof_index("r_elbow_flex")] = 1.0
    vertices = full.forward(params).vertices[0]
    frame = renderer.render(FrameState(people=(look.with_hair(vertices, full.faces),)))
    return rig, list(frame.images), list(frame.silhouettes)


def bench_network(rig, images, masks, repeats: int) -> None:
    network = PoseLandmarkNetwork()
    boxes = [roi_box(c, m, None, KeypointParams()) for c, m in zip(rig, masks)]
    for threads in (1, 2):
        cv2.setNumThreads(threads)
        network.run(images[0], boxes[0])  # warm-up
        wall, cpu = [], []
        for _ in range(repeats):
            for image, box in zip(images, boxes):
                w0, c0 = time.perf_counter(), time.thread_time()
                network.run(image, box)
                wall.append(time.perf_counter() - w0)
                cpu.append(time.thread_time() - c0)
        print(f"network per view, {threads} OpenCV thread{'s' if threads > 1 else ''}: "
              f"median {1e3 * np.median(wall):.1f} ms wall, {1e3 * np.median(cpu):.1f} ms CPU of "
              f"the calling thread ({len(wall)} runs)", flush=True)


def bench_detector(rig, images, masks, repeats: int) -> None:
    for workers, threads in SETTINGS:
        detector = KeypointDetector(rig, KeypointParams(workers=workers, opencv_threads=threads))
        try:
            result = detector.detect(images, masks)  # warm-up
            stages: dict[str, list] = {}
            cpu = []
            for _ in range(repeats):
                c0 = time.process_time()
                detector.detect(images, masks)
                cpu.append(time.process_time() - c0)
                for key, value in detector.last_timings.items():
                    stages.setdefault(key.split("/")[0] + ("/view" if "/" in key else ""),
                                      []).append(value)
        finally:
            detector.close()
        total = float(np.median(stages["total"]))
        parts = ", ".join(f"{k} {1e3 * np.median(v):.1f}"
                          for k, v in stages.items() if k != "total")
        print(f"detect(), 4 views, {workers} worker{'s' if workers > 1 else ''} x {threads} "
              f"OpenCV thread{'s' if threads > 1 else ''}: {1e3 * total:.0f} ms per frame set = "
              f"{1.0 / total:.1f} frame sets/s, {1e3 * np.median(cpu):.0f} ms CPU of the process "
              f"(median ms: {parts}; {len(result.labels)} keypoints)", flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=12, help="frame sets per measurement")
    ns = p.parse_args(argv)
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}, OpenCV {cv2.__version__}", flush=True)
    t0 = time.perf_counter()
    rig, images, masks = render_scene()
    print(f"scene rendered in {time.perf_counter() - t0:.1f} s (4 views, 640x480)", flush=True)
    bench_network(rig, images, masks, ns.repeats)
    bench_detector(rig, images, masks, ns.repeats)
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
