#!/usr/bin/env python3
"""Rendering speed of the multi-view simulator: seconds per 4-view frame.

The scene of ``hmocap sim mocap``: the furnished room (about 9,500 static triangles), the
12,000-triangle subject posed from the 13_26 clip, four cameras; per frame the shadow map,
projection, z-buffer, shading, ground-truth silhouettes and the sensor model
(:meth:`hmocap_sim.mocap_render.MocapRenderer.render`). Timed at 640x480 and 320x240,
with the default anti-aliasing (2x supersampling up to 320 pixels wide) and without it, on
one numba thread and on all of them, plus the whole frame as ``hmocap sim mocap`` writes it
(posing, rendering, messages into an MCAP bag). Figures are medians over several frames
after a warm-up (numba compiled and cached first); with one thread the process CPU time is
also given, which other load on a shared machine does not inflate.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_sim.py [--frames 8] [--distractors]
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from hmocap_ros.body import load_body_model, sample_shape
from hmocap_sim import mocap_dataset as md
from hmocap_sim import mocap_subject as ms
from hmocap_sim.appearance import dress, sample_appearance
from hmocap_sim.mocap_render import FrameState, MocapRenderer, RenderOptions
from hmocap_sim.room import build_room


def subject_frames(n: int, rig, room, rng):
    """``n`` posed subject meshes (room frame) from the 13_26 clip, and the body's faces."""
    tracking = load_body_model("tracking")
    full = load_body_model("hands", "full")
    shape = sample_shape(rng)
    look = dress(full, sample_appearance(rng))
    motion = ms.motion_window(ms.retargeted_motion(md.DEFAULT_BVH, tracking, shape, 25.0), 3.0,
                               n / 25.0, 25.0)
    motion = ms.place_subject(motion, rig, room, rng, ms.shaped_skeleton(tracking, shape))
    perf = ms.make_performer(motion, tracking, full, shape, look)
    verts = full.forward(perf.full_params, shape).vertices
    return [look.with_hair(v, full.faces) for v in verts], full.faces, look


def time_render(width, height, supersample, threads, frames: int, shadows=True):
    numba.set_num_threads(threads)
    rng = np.random.default_rng(0)
    rig = md.make_rig(4, width, height)
    room = build_room(rng)
    verts, faces, look = subject_frames(frames, rig, room, rng)
    renderer = MocapRenderer(rig, room, [(faces, look)],
                             RenderOptions(supersample=supersample, shadows=shadows))
    rngs = [np.random.default_rng(k) for k in range(4)]
    renderer.render(FrameState(people=(verts[0],)), rngs)  # warm-up
    times, cpu, stages = [], [], {}
    for v in verts:
        t0, c0 = time.perf_counter(), time.process_time()
        renderer.render(FrameState(people=(v,)), rngs)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        for key, val in renderer.last_timings.items():
            stages.setdefault(key, []).append(val)
    return (float(np.median(times)), float(np.median(cpu)),
            {k: float(np.median(v)) for k, v in stages.items()})


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=8, help="frames timed per configuration")
    ap.add_argument("--distractors", action="store_true",
                    help="also time a whole recording with distractors")
    args = ap.parse_args(argv)
    all_threads = numba.config.NUMBA_NUM_THREADS
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, "
          f"numba {numba.__version__} ({all_threads} threads max), numpy {np.__version__}")
    print("seconds per 4-view frame (render: shadow map, projection, z-buffer, shading, "
          "silhouettes, sensor):")
    for width, height in ((640, 480), (320, 240)):
        for ss in sorted({RenderOptions().supersample_for(width), 1}, reverse=True):
            for threads in sorted({1, all_threads}):
                dt, cpu, st = time_render(width, height, ss, threads, args.frames)
                detail = ", ".join(f"{k} {v:.3f}" for k, v in st.items())
                print(f"  {width}x{height} supersample {ss} threads {threads}: {dt:.3f} s wall, "
                      f"{cpu:.3f} s CPU ({detail})")
    dt, cpu, _ = time_render(640, 480, 1, 1, args.frames, shadows=False)
    print(f"  640x480 supersample 1 threads 1 --no-shadow: {dt:.3f} s wall, {cpu:.3f} s CPU")

    numba.set_num_threads(1)
    print("whole recording (hmocap sim mocap: posing, rendering, bag writing), 1 thread:")
    with tempfile.TemporaryDirectory() as tmp:
        for width, height, dist in ((640, 480, False), (320, 240, False),
                                    *(((640, 480, True),) if args.distractors else ())):
            cfg = md.MocapSimConfig(out=Path(tmp) / f"b{width}{dist}.mcap", width=width,
                                    height=height, seconds=args.frames / 25.0,
                                    background_seconds=0.0, progress=False, contact_frames=0,
                                    distractors=dist)
            t0 = time.perf_counter()
            result = md.generate(cfg)
            total = time.perf_counter() - t0
            print(f"  {width}x{height}{' distractors' if dist else ''}: "
                  f"{total / result.n_frames:.3f} s per frame incl. set-up "
                  f"(render {result.render_seconds_per_frame:.3f}), "
                  f"{result.bag_bytes / result.n_frames / 1e6:.2f} MB per frame in the bag")


if __name__ == "__main__":
    main()
