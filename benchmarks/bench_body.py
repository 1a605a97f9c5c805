#!/usr/bin/env python3
"""Posing throughput of the body model: poses skinned per second (batch of 1,000 poses).

Measures each stage for the tracking mesh (and the hands mesh for comparison):
parameters -> local rotations (eq. 2.11 factors), forward kinematics, skinning matrices,
LBS (eq. 2.12; numba and numpy backends), the whole ``BodyModel.pose`` call, and posing
with a different anthropometric shape per pose (sec. 2.3.2, particles of a shape layer).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_body.py [--batch 1000] [--repeats 5]
"""
from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from hmocap_ros.body import (
    forward_kinematics,
    load_body_model,
    pose_to_local_rotations,
    sample_pose,
    sample_shape,
    skin_vertices,
    skinning_matrices,
)


def best_time(fn, repeats: int) -> float:
    fn()  # warm-up (numba compilation, caches)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def one_thread(fn):
    import numba

    saved = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        return fn()
    finally:
        numba.set_num_threads(saved)


def bench_model(name: str, batch: int, repeats: int, rng: np.random.Generator) -> None:
    model = load_body_model(name)
    skel = model.skeleton
    params = sample_pose(skel, rng, batch)
    rot, root_t = pose_to_local_rotations(skel, params)
    transforms, _ = forward_kinematics(rot, root_t, model.joints_rest, model.parents)
    mats = skinning_matrices(transforms, model.joints_rest)
    shapes = sample_shape(rng, batch)
    shaped_params = model.rest_pose(shapes)
    shaped_params[:, 6:] = params[:, 6:]
    print(f"\n[{name}] {model.n_vertices} vertices, {len(model.faces)} triangles, "
          f"{model.n_joints} joints, {skel.n_dofs} DoF, "
          f"{model.sparse_weights.index.shape[1]} weights/vertex max, batch {batch}")
    stages = [
        ("params -> local rotations", lambda: pose_to_local_rotations(skel, params)),
        ("forward kinematics", lambda: forward_kinematics(rot, root_t, model.joints_rest, model.parents)),
        ("skinning matrices", lambda: skinning_matrices(transforms, model.joints_rest)),
        ("LBS numba (auto: parallel)", lambda: skin_vertices(mats, model.vertices, model.sparse_weights, "numba")),
        ("LBS numba, one thread", lambda: one_thread(
            lambda: skin_vertices(mats, model.vertices, model.sparse_weights, "numba"))),
        ("LBS numpy", lambda: skin_vertices(mats, model.vertices, model.weights, "numpy")),
        ("BodyModel.pose (numba)", lambda: model.pose(params)),
        ("BodyModel.pose + per-pose shape", lambda: model.pose(shaped_params, shapes)),
    ]
    for label, fn in stages:
        t = best_time(fn, repeats)
        print(f"  {label:36s} {t * 1e3:9.2f} ms/batch  {batch / t:12,.0f} poses/s")
    single = params[:1]
    t = best_time(lambda: model.pose(single), max(repeats, 20))
    print(f"  {'BodyModel.pose, one pose':36s} {t * 1e3:9.3f} ms")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--batch", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--hands", action=argparse.BooleanOptionalAction, default=True,
                    help="also benchmark the hands mesh")
    args = ap.parse_args(argv)
    import numba

    print(f"python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}, "
          f"cpus {os.cpu_count()}, numba threads {numba.get_num_threads()}, {platform.machine()}")
    rng = np.random.default_rng(0)
    bench_model("tracking", args.batch, args.repeats, rng)
    if args.hands:
        bench_model("hands", args.batch, args.repeats, rng)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
