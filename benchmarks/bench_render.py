"""Benchmark of the renderers: the tracker's silhouette masks and fused XOR counts
(hmocap_ros.render), the simulator's RGB and depth frames (hmocap_sim.render).

Usage: PYTHONPATH=. .venv/bin/python benchmarks/bench_render.py [--save DIR]

Uses the package's 2,400-triangle tracking body (``load_body_model("tracking")``, rest pose; or
any mesh with ``--mesh FILE.npz``) seen by four cameras in the upper corners of a 6 x 5 x 2.6 m
room, like the smart-room rig.
Figures are wall-clock medians after a warm-up (numba compiled and cached first).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from functools import partial

import numba
import numpy as np

from hmocap_ros.geometry.pinhole_camera import look_at_pose
from hmocap_ros.geometry.projection import project_batch
from hmocap_ros.render import render_silhouettes, xor_counts
from hmocap_sim.render import (
    DirectionalLight,
    Lighting,
    Material,
    PointLight,
    concatenate_meshes,
    face_range_mask,
    grid_quad,
    kinect_depth,
    rasterize,
    render_shadow_map,
    shade,
    vertex_normals,
)
from hmocap_sim.render.sensor import add_sensor_noise, downsample

DEFAULT_MESH = "tracking"
ROOM = (6.0, 2.6, 5.0)  # x, y (height), z in metres; floor on y = 0, corner at the origin


def rig(width: int, height: int, n_views: int = 4):
    """Four cameras in the room's upper corners looking at its centre (~75 deg horizontal)."""
    sx, sy, sz = ROOM
    corners = [(0.3, sy - 0.3, 0.3), (sx - 0.3, sy - 0.3, 0.3), (sx - 0.3, sy - 0.3, sz - 0.3),
               (0.3, sy - 0.3, sz - 0.3)][:n_views]
    target = (sx / 2, 0.8, sz / 2)
    f = 0.65 * width
    K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])
    Rs, ts = zip(*(look_at_pose(c, target) for c in corners))
    dist = np.tile([-0.12, 0.03, 0.0, 0.0, 0.0], (n_views, 1))
    return np.stack([K] * n_views), np.stack(Rs), np.stack(ts), dist


def load_body(path: str):
    """``tracking`` (the shipped tracking body) or any .npz with ``vertices (V, 3)`` (metres,
    +Y up, feet on y = 0) and ``faces (F, 3)``; ``joint_names`` and ``weights`` (skinning) only
    colour the clothes."""
    if path == "tracking":
        from hmocap_ros.body import load_body_model

        model = load_body_model("tracking")
        d = {"vertices": np.asarray(model.vertices, np.float64), "faces": np.asarray(model.faces),
             "weights": np.asarray(model.weights), "joint_names": np.asarray(model.joint_names)}
        return d["vertices"], d["faces"].astype(np.int32), d
    if not os.path.exists(path):
        raise SystemExit(f"body mesh {path} not found: pass --mesh FILE.npz")
    d = dict(np.load(path))
    return d["vertices"].astype(np.float64), d["faces"].astype(np.int32), d


def random_poses(vertices, n: int, rng):
    """n copies of the body, each turned about the vertical axis and moved on the floor (a
    stand-in for LBS-posed particles: the renderer only sees vertices)."""
    yaw = rng.uniform(-np.pi, np.pi, n)
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.zeros((n, 3, 3))
    R[:, 0, 0] = c
    R[:, 0, 2] = s
    R[:, 1, 1] = 1
    R[:, 2, 0] = -s
    R[:, 2, 2] = c
    shift = np.stack([ROOM[0] / 2 + rng.normal(0, 0.3, n), np.zeros(n),
                      ROOM[2] / 2 + rng.normal(0, 0.3, n)], 1)
    return np.einsum("nij,vj->nvi", R, vertices) + shift[:, None, :]


def timed(fn, repeat: int = 5):
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def body_colours(d) -> np.ndarray:
    """sRGB vertex colours: skin on head, neck and hands, blue shirt, dark jeans, black shoes."""
    if "weights" not in d or "joint_names" not in d:
        return np.tile([0.12, 0.32, 0.62], (len(d["vertices"]), 1))
    names = list(d["joint_names"])
    dominant = np.array(names)[np.argmax(d["weights"], axis=1)]
    y = d["vertices"][:, 1]
    colours = np.tile([0.12, 0.32, 0.62], (len(y), 1))  # shirt
    legs = np.isin(dominant, [n for n in names if any(k in n for k in ("hip", "knee", "ankle",
                                                                       "pelvis"))])
    colours[legs] = (0.11, 0.13, 0.2)
    skin = np.isin(dominant, [n for n in names if any(k in n for k in ("head", "neck",
                                                                       "wrist"))])
    colours[skin] = (0.85, 0.62, 0.5)
    colours[y < 0.09] = (0.05, 0.05, 0.05)
    return colours


def demo_scene(body_vertices, body_faces, d):
    """A furnished-room stand-in: wooden floor, plaster walls, a cupboard and the person;
    returns the concatenated scene, per-face materials and the person's face range."""
    sx, sy, sz = ROOM
    n = 0.25  # tessellation (m): no near clipping in the rasteriser, and lens distortion
    parts = [
        (grid_quad((0, 0, 0), (0, 0, sz), (sx, 0, 0), int(sz / n), int(sx / n)), 0),  # floor
        (grid_quad((0, 0, 0), (sx, 0, 0), (0, sy, 0), int(sx / n), int(sy / n)), 1),  # walls
        (grid_quad((0, 0, sz), (0, sy, 0), (sx, 0, 0), int(sy / n), int(sx / n)), 2),
        (grid_quad((0, 0, 0), (0, sy, 0), (0, 0, sz), int(sy / n), int(sz / n)), 1),
        (grid_quad((sx, 0, 0), (0, 0, sz), (0, sy, 0), int(sz / n), int(sy / n)), 2),
        (grid_quad((0, sy, 0), (sx, 0, 0), (0, 0, sz), int(sx / n), int(sz / n)), 3),  # ceiling
    ]
    # A cupboard against the far wall: front, top and both sides of a box.
    x0, x1, y1, z0, z1 = 4.2, 5.2, 1.8, sz - 0.45, sz - 0.02
    box = [((x0, 0, z0), (x1 - x0, 0, 0), (0, y1, 0)),
           ((x0, y1, z0), (x1 - x0, 0, 0), (0, 0, z1 - z0)),
           ((x0, 0, z1), (0, 0, z0 - z1), (0, y1, 0)),
           ((x1, 0, z0), (0, 0, z1 - z0), (0, y1, 0))]
    parts += [(grid_quad(o, a, b, 4, 6), 4) for o, a, b in box]
    body = (body_vertices, body_faces)
    meshes = [p for p, _ in parts] + [body]
    vertices, faces, face_offsets, vertex_offsets = concatenate_meshes(meshes)
    mats = np.concatenate([np.full(len(p[1]), m) for p, m in parts]
                          + [np.full(len(body_faces), 5)]).astype(np.int32)
    materials = [
        Material("wood", (0.7, 0.44, 0.26), (0.4, 0.21, 0.1), scale=0.14, seed=1),
        Material("plaster", (0.86, 0.84, 0.79), (0.77, 0.76, 0.71), scale=0.4, noise=0.04, seed=2),
        Material("plaster", (0.8, 0.85, 0.82), (0.72, 0.77, 0.74), scale=0.4, noise=0.04, seed=3),
        Material("plain", (0.9, 0.9, 0.9)),
        Material("wood", (0.45, 0.27, 0.14), (0.3, 0.16, 0.07), scale=0.3, angle=np.pi / 2, seed=4),
        Material("fabric", (1, 1, 1), scale=0.08, noise=0.15, vertex_colour=True, smooth=True,
                 specular=0.05, seed=5),
    ]
    colours = np.ones((len(vertices), 3), np.float32)
    colours[vertex_offsets[-2]:] = body_colours(d)
    normals = np.zeros((len(vertices), 3), np.float32)
    normals[vertex_offsets[-2]:] = vertex_normals(body_vertices, body_faces)
    person = (int(face_offsets[-2]), int(face_offsets[-1]))
    return vertices, faces, mats, materials, colours, normals, person


def render_frame(scene, cams, width, height, body_vertices, body_faces, supersample=1):
    vertices, faces, mats, materials, colours, normals, person = scene
    K, R, t, dist = cams
    sx, sy, sz = ROOM
    lamp = (sx / 2 - 1.0, sy - 0.1, sz / 2 - 1.2)
    shadow = render_shadow_map(body_vertices, body_faces, light_position=lamp, size=512)
    lighting = Lighting(lights=(PointLight(lamp, (5.5, 5.3, 5.0), shadow, radius=1.0),
                                DirectionalLight((0.3, -1.0, 0.2), (0.08, 0.08, 0.08))),
                        ambient_sky=(0.16, 0.16, 0.17), ambient_ground=(0.1, 0.09, 0.08),
                        shadow_softness_px=8.0)
    uv, z = project_batch(vertices[None], K, R, t, dist, scale=supersample)
    frames, masks, depths = [], [], []
    for m in range(len(K)):
        raster = rasterize(uv[0, m], z[0, m], faces, height * supersample, width * supersample)
        rgb = shade(raster, vertices, faces, mats, materials, -R[m].T @ t[m], lighting,
                    vertex_colours=colours, vertex_normals=normals)
        if supersample > 1:
            rgb = downsample(rgb, supersample)
        frames.append(rgb)
        masks.append(face_range_mask(raster[1], *person))
        depths.append(raster[0])
    return frames, masks, depths


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default=DEFAULT_MESH)
    ap.add_argument("--save", default=None, help="directory for a preview PNG of the RGB frame")
    ap.add_argument("--particles", type=int, default=500)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    body_v, body_f, d = load_body(args.mesh)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cpus, "
          f"numba {numba.__version__}, threading layer {numba.config.THREADING_LAYER}, "
          f"numpy {np.__version__}")
    print(f"mesh: {len(body_v)} vertices, {len(body_f)} triangles; 4 corner cameras")

    n_masks = 400
    for width, height in ((160, 120), (640, 480)):
        cams = rig(width, height)
        uv, _ = project_batch(random_poses(body_v, n_masks // 4, rng), *cams)
        area = render_silhouettes(uv[:8], body_f, height, width).mean() * 100
        buffer = np.empty(uv.shape[:2] + (height, width), np.uint8)
        print(f"render_silhouettes {width}x{height}, {n_masks} masks per call, body covers "
              f"{area:.1f}% of the image:")
        for threads in (1, 2):
            numba.set_num_threads(threads)
            for front in (False, True):
                fresh = timed(partial(render_silhouettes, uv, body_f, height, width, front_only=front))
                reused = timed(partial(render_silhouettes, uv, body_f, height, width, front_only=front,
                                       out=buffer))
                print(f"  threads={threads} front_only={front!s:5}: {n_masks / reused:8.0f} "
                      f"masks/s into a reused buffer, {n_masks / fresh:8.0f} allocating")

    width, height = 160, 120
    B, cams = args.particles, rig(width, height)
    posed = random_poses(body_v, B, rng)
    uv, _ = project_batch(posed, *cams)
    observed = render_silhouettes(uv[0], body_f, height, width)
    ys, xs = np.nonzero(observed[0])
    boxes = np.array([[xs.min(), ys.min(), xs.max() + 1, (ys.min() + ys.max()) // 2]] * 4)
    for threads in (1, 2):
        numba.set_num_threads(threads)
        for front in (False, True):
            for name, bx in (("whole image", None), ("upper-body box", boxes)):
                dt = timed(partial(xor_counts, uv, body_f, observed, bx, front_only=front))
                print(f"xor_counts B={B} x M=4 at {width}x{height} threads={threads} "
                      f"front_only={front!s:5} {name:14}: {dt * 1e3:7.1f} ms "
                      f"= {B * 4 / dt:7.0f} masks/s")
        dt = timed(lambda: project_batch(posed, *cams))
        print(f"  (project_batch of the same {B} poses x 4 views x {len(body_v)} vertices, "
              f"with distortion, threads={threads}: {dt * 1e3:.1f} ms)")

    numba.set_num_threads(2)
    width, height = 640, 480
    cams = rig(width, height)
    posed = random_poses(body_v, 1, rng)[0]
    scene = demo_scene(posed, body_f, d)
    print(f"RGB scene: {len(scene[0])} vertices, {len(scene[1])} triangles (room + cupboard "
          f"+ person), 1 point light with a 512^2 shadow map + 1 directional light")
    for threads in (1, 2):
        numba.set_num_threads(threads)
        dt = timed(lambda: render_frame(scene, cams, width, height, posed, body_f), repeat=3)
        print(f"RGB 4 views x {width}x{height} threads={threads}: {dt * 1e3:.0f} ms per frame "
              f"(shadow map + 4 x rasterize + shade)")
    dt = timed(lambda: render_frame(scene, cams, width, height, posed, body_f, supersample=2),
               repeat=1)
    print(f"RGB 4 views x {width}x{height}, 2x2 supersampled, threads=2: {dt * 1e3:.0f} ms")
    _, _, depths = render_frame(scene, cams, width, height, posed, body_f)
    dt = timed(lambda: kinect_depth(depths[0], np.random.default_rng(1), fx=cams[0][0, 0, 0]))
    print(f"kinect_depth {width}x{height}: {dt * 1e3:.1f} ms")
    if args.save:
        import cv2
        os.makedirs(args.save, exist_ok=True)
        frames, _, _ = render_frame(scene, cams, width, height, posed, body_f, supersample=2)
        noisy = [add_sensor_noise(f, np.random.default_rng(k)) for k, f in enumerate(frames)]
        grid = np.vstack([np.hstack(noisy[:2]), np.hstack(noisy[2:])])
        cv2.imwrite(os.path.join(args.save, "bench_render_rgb.png"), grid[..., ::-1])
        mm = kinect_depth(depths[0], np.random.default_rng(1), fx=cams[0][0, 0, 0])
        vis = cv2.applyColorMap(cv2.convertScaleAbs(mm, alpha=255 / 6000), cv2.COLORMAP_JET)
        vis[mm == 0] = 0
        cv2.imwrite(os.path.join(args.save, "bench_render_depth.png"), vis)
        print(f"saved previews to {args.save}")


if __name__ == "__main__":
    main()
