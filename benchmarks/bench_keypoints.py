#!/usr/bin/env python3
"""Keypoint detector speed: the landmark network per inference and whole frame sets of 4 views.

The scene: a simulated room rendered here (``hmocap_sim``, 4 cameras at 640x480, a subject
with one arm raised sideways), the exact silhouettes as foreground masks. Measured:

- **runtimes**: the landmark model (``pose_landmark_full.tflite``) per 256x256 inference on
  LiteRT (XNNPACK, the package's runtime) and on OpenCV dnn's classic engine (where this
  OpenCV reads TFLite), one inference of each in turn in one run, on 1 and 2 threads: median
  wall-clock and CPU milliseconds (1 thread: the calling thread's CPU time; 2 threads: the
  process's);
- **the pose detector**: :meth:`PoseDetector.detect` on a whole 640x480 view (the first crop
  of a track), median wall and CPU ms;
- **frame sets**: :meth:`KeypointDetector.detect` on the 4 views (crops from the views'
  tracks, networks, robust triangulation) on 2 and 1 LiteRT threads,
  median wall clock and CPU time of the process (all its threads), the median of each stage;
  and the first frame set of a track (every view through the pose detector first).

The networks' time does not depend on the image content, so one frame set is repeated. On a
machine shared with other processes the wall-clock figures grow with the load average,
printed first; the CPU figures much less.

    .venv/bin/python benchmarks/bench_keypoints.py [--repeats 12]
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import cv2
import numpy as np

from hmocap_ros.detection import (
    KeypointDetector,
    KeypointParams,
    PoseDetector,
    PoseLandmarkNetwork,
    box_roi,
    foreground_box,
)
from hmocap_ros.detection.keypoint_network import DEFAULT_MODEL, INPUT_SIZE
from hmocap_ros.detection.keypoint_roi import crop_transform

SETTINGS = (2, 1)  # LiteRT threads of the detector's networks


def render_scene():
    """(rig, 4 RGB images, 4 silhouettes) of a simulated room with one subject."""
    from hmocap_ros.body import load_body_model
    from hmocap_sim.appearance import dress, sample_appearance
    from hmocap_sim.mocap_dataset import make_rig
    from hmocap_sim.mocap_render import FrameState, MocapRenderer, RenderOptions
    from hmocap_sim.room import build_room

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


def _opencv_dnn(threads: int):
    """OpenCV dnn's classic engine on the same model file (the comparison of the runtimes), or
    None when this OpenCV has no TFLite reader."""
    reader = getattr(cv2.dnn, "readNetFromTFLite", None)
    if reader is None:
        return None
    cv2.setNumThreads(threads)
    engine = getattr(cv2.dnn, "ENGINE_CLASSIC", None)
    net = reader(str(DEFAULT_MODEL)) if engine is None else reader(str(DEFAULT_MODEL), engine=engine)
    outputs = ["Identity", "Identity_1", "Identity_3"]

    def infer(crop):
        net.setInput(cv2.dnn.blobFromImage(crop, scalefactor=1.0 / 255.0))
        return net.forward(outputs)
    return infer


def bench_runtimes(crops: list, repeats: int) -> dict:
    """LiteRT and OpenCV dnn per 256x256 inference, alternating one inference each in one run,
    on 1 and 2 threads: median wall and CPU ms (1 thread: the calling thread's CPU time; 2
    threads: the process's, nothing else running in it)."""
    out = {}
    for threads in (1, 2):
        runtimes = {"litert": PoseLandmarkNetwork(threads=threads).infer}
        opencv = _opencv_dnn(threads)
        if opencv is not None:
            runtimes["opencv_dnn"] = opencv
        for infer in runtimes.values():
            infer(crops[0])  # warm-up
        clock = time.thread_time if threads == 1 else time.process_time
        wall = {k: [] for k in runtimes}
        cpu = {k: [] for k in runtimes}
        for _ in range(repeats):
            for crop in crops:
                for name, infer in runtimes.items():
                    w0, c0 = time.perf_counter(), clock()
                    infer(crop)
                    cpu[name].append(clock() - c0)
                    wall[name].append(time.perf_counter() - w0)
        for name in runtimes:
            out[f"{name}/{threads}"] = (1e3 * np.median(wall[name]), 1e3 * np.median(cpu[name]))
            print(f"{name:10s} {threads} thread{'s' if threads > 1 else ' '}: median "
                  f"{out[f'{name}/{threads}'][0]:5.1f} ms wall, {out[f'{name}/{threads}'][1]:5.1f} ms "
                  f"CPU per 256x256 inference ({len(cpu[name])} runs, alternating)", flush=True)
    return out


def view_crops(rig, images, masks) -> list:
    """The 256x256 network inputs of the views' foreground crops."""
    crops = []
    for camera, image, mask in zip(rig, images, masks):
        roi = box_roi(foreground_box(camera, mask, KeypointParams()), KeypointParams().box_margin)
        crops.append(cv2.warpAffine(image, crop_transform(roi, INPUT_SIZE), (INPUT_SIZE, INPUT_SIZE),
                                    flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE))
    return crops


def bench_pose_detector(images, repeats: int) -> None:
    detector = PoseDetector()
    detector.detect(images[0])  # warm-up
    wall, cpu = [], []
    for _ in range(repeats):
        for image in images:
            w0, c0 = time.perf_counter(), time.thread_time()
            detector.detect(image)
            cpu.append(time.thread_time() - c0)
            wall.append(time.perf_counter() - w0)
    print(f"pose detector per 640x480 view, 1 thread: median {1e3 * np.median(wall):.1f} ms wall, "
          f"{1e3 * np.median(cpu):.1f} ms CPU ({len(wall)} runs)", flush=True)


def bench_detector(rig, images, masks, repeats: int) -> None:
    for threads in SETTINGS:
        detector = KeypointDetector(rig, KeypointParams(threads=threads))
        try:
            first_cpu, first_wall = [], []
            for _ in range(max(2, repeats // 4)):
                detector.reset()
                w0, c0 = time.perf_counter(), time.process_time()
                detector.detect(images, masks)  # every view: the pose detector, then the landmarks
                first_cpu.append(time.process_time() - c0)
                first_wall.append(time.perf_counter() - w0)
            result = detector.detect(images, masks)  # crops from the tracks from here on
            stages: dict[str, list] = {}
            cpu = []
            for _ in range(repeats):
                c0 = time.process_time()
                detector.detect(images, masks)
                cpu.append(time.process_time() - c0)
                for key, value in detector.last_timings.items():
                    stages.setdefault(key.split("/")[0] + ("/view" if "/" in key else ""),
                                      []).append(value)
            sources = detector.last_sources
        finally:
            detector.close()
        total = float(np.median(stages["total"]))
        parts = ", ".join(f"{k} {1e3 * np.median(v):.1f}"
                          for k, v in stages.items() if k != "total")
        print(f"detect(), 4 views, {threads} LiteRT thread{'s' if threads > 1 else ''}: "
              f"{1e3 * total:.0f} ms per frame set = "
              f"{1.0 / total:.1f} frame sets/s, {1e3 * np.median(cpu):.0f} ms CPU of the process "
              f"(median ms: {parts}; crops from {sorted(set(sources))}; {len(result.labels)} "
              f"keypoints); first set of a track {1e3 * np.median(first_wall):.0f} ms, "
              f"{1e3 * np.median(first_cpu):.0f} ms CPU", flush=True)


def _litert_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ai-edge-litert")
    except PackageNotFoundError:
        return "?"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=12, help="frame sets per measurement")
    ns = p.parse_args(argv)
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}, OpenCV {cv2.__version__}, "
          f"LiteRT {_litert_version()}", flush=True)
    t0 = time.perf_counter()
    rig, images, masks = render_scene()
    print(f"scene rendered in {time.perf_counter() - t0:.1f} s (4 views, 640x480)", flush=True)
    bench_runtimes(view_crops(rig, images, masks), ns.repeats)
    bench_pose_detector(images, ns.repeats)
    bench_detector(rig, images, masks, ns.repeats)
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
