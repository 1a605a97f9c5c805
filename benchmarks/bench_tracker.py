#!/usr/bin/env python3
"""Body tracker speed at the thesis' budget: seconds per frame and weight evaluations per second.

The scene: the shipped CMU clip 13_26 retargeted onto the tracking body, exact silhouettes
rendered at 640x480 in the 4 cameras of ``config/rig_example.yaml`` (no segmentation: this
measures the tracker). The tracker is started on the first frame (the start-up is not timed),
then every method of :data:`hmocap_ros.tracking.methods.METHODS` runs ``--frames`` frames of
tracking at its default budget of about 3,500 weight evaluations per frame (APF 14 layers x
250 particles; in the default two sweeps over the kinematic tree, ``filter.sweeps``, HPF
14 x 250 and HPF+APO and DD-HPF+ 15 x 234), with 1 and 2 numba threads. DD-HPF+ gets ideal
keypoint detections (the true limb joints and hands, labelled, score 1; the keypoint
detector's own cost is the extremity node's, ``bench_keypoints.py``).

Printed per method: seconds per frame (median), evaluations per second, and where the time
goes (skinning = eq. 2.11/2.12, projection (fused into the XOR pass by default), XOR = eq.
2.8/2.15, proposals (their own search; the re-ranking of proposals counts as skinning and
XOR), detection (DD-HPF+: 3D extremities and IK solutions), the rest = resampling, kernels,
boxes); then the time of one fresh search (``research.every``, once every 25 tracked frames
by default), which the frames above leave out; and what a second tracker slot costs while
nobody else is in the room (``max_people`` 2: it carves the coarse visual hull of each frame
to look for a new person).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_tracker.py [--frames 10] [--threads 1 2]
        [--methods hpf dd-hpf] [--mesh tracking_coarse] [--param filter.sweeps=1]

The scene is always rendered with the 2,400-triangle ``tracking`` body; ``--mesh`` picks what
the tracker renders its particles with (``weighting.mesh``).
"""
from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numba
import numpy as np

from hmocap_ros.body import load_body_model, local_rotations_to_pose
from hmocap_ros.body.anthropometry import BodyShape
from hmocap_ros.detection.detections import MODEL_JOINT, Detections
from hmocap_ros.eval.mocap_eval import tracker_overrides
from hmocap_ros.geometry.projection import project_batch
from hmocap_ros.geometry.rig import load_rig
from hmocap_ros.params import from_flat
from hmocap_ros.render import render_silhouettes
from hmocap_ros.tracking.body_tracker import BodyTracker, working_scale
from hmocap_ros.tracking.methods import METHODS, method_names
from hmocap_ros.tracking.params import TRACKER_MESHES, TrackerParams
from hmocap_ros.tracking.people_tracker import PeopleTracker
from hmocap_sim.retarget import load_motion, place_in_room

ROOT = Path(__file__).resolve().parents[1]


def scene(model, rig, n_frames: int, start: int = 250):
    shape = BodyShape.neutral()
    motion = load_motion(ROOT / "hmocap_ros" / "data" / "bvh" / "13_26.bvh", model.joints_rest,
                         model.parents, model.joint_names, model.end_sites_rest,
                         model.end_site_parents, model.end_site_names, fps=25)
    motion = place_in_room(motion, (0.2, -0.1), 0.6)
    sl = slice(start, start + n_frames)
    params = local_rotations_to_pose(model.skeleton, motion.local_rotations[sl],
                                     motion.root_translation[sl])
    verts, _ = model.pose(params, shape)
    K, R, t, D = rig.arrays()
    uv, _ = project_batch(verts, K, R, t, D)
    masks = render_silhouettes(uv, model.faces, rig[0].height, rig[0].width) * np.uint8(255)
    joints = np.asarray(model.pose(params, shape)[1])
    names = list(model.joint_names)
    labels = tuple(MODEL_JOINT)
    index = [names.index(MODEL_JOINT[label]) for label in labels]
    detections = [Detections("keypoints", labels, j[index], np.ones(len(labels))) for j in joints]
    return shape, masks, detections


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--threads", type=int, nargs="*", default=[1, 2])
    ap.add_argument("--methods", nargs="*", default=list(method_names()), choices=method_names())
    ap.add_argument("--working-width", type=int, default=TrackerParams().weighting.working_width,
                    help="weighting.working_width (default %(default)s)")
    ap.add_argument("--mesh", default=TrackerParams().weighting.mesh, choices=TRACKER_MESHES,
                    help="mesh the tracker renders its particles with, weighting.mesh "
                         "(default %(default)s)")
    ap.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                    help="other tracker setting by its dotted name, e.g. filter.sweeps=1 "
                         "(repeatable; as hmocap eval mocap --param)")
    args = ap.parse_args()
    try:
        # --param wins over --working-width and --mesh
        settings = {"weighting.working_width": args.working_width, "weighting.mesh": args.mesh,
                    **tracker_overrides(args.param)}
        base = from_flat(TrackerParams, settings)
    except ValueError as err:
        ap.error(str(err))
    mesh = base.weighting.mesh
    model = load_body_model("tracking")
    rig = load_rig(ROOT / "config" / "rig_example.yaml")
    scale = working_scale(list(rig), base.weighting.working_width)
    shape, masks, maps = scene(model, rig, args.frames + 1)
    print(f"python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}, "
          f"{platform.machine()}, cpus {numba.config.NUMBA_NUM_THREADS}")
    print(f"4 views {rig[0].width}x{rig[0].height}, working scale {scale} "
          f"({int(rig[0].width * scale)}x{int(rig[0].height * scale)}), "
          f"scene mesh {model.n_vertices} vertices / {len(model.faces)} triangles, tracker mesh "
          f"{mesh} ({len(model.with_mesh(mesh).faces)} triangles), {args.frames} frames"
          + "".join(f", {k}={v}" for k, v in settings.items() if not k.startswith("weighting.")))
    every = TrackerParams().research.every
    for threads in args.threads:
        numba.set_num_threads(threads)
        for method in args.methods:
            label = METHODS[method].label
            # the fresh search (research.every) runs on the frame after the timed ones
            # (the start-up and warm-up frames do not count, so it is tracked frame n + 2)
            params = from_flat(TrackerParams, {**settings, "method": method,
                                               "research.every": args.frames + 2})
            tracker = BodyTracker(model, rig, params, np.random.default_rng(0), shape=shape)
            tracker.update(list(masks[0]), 0)  # start-up (hull, Powell): not timed
            tracker.update(list(masks[1 % len(masks)]), 1, maps[1 % len(masks)])  # warm-up
            totals, stages = [], {}
            for f in range(1, args.frames + 1):
                t0 = time.perf_counter()
                res = tracker.update(list(masks[f]), f, maps[f])
                totals.append(time.perf_counter() - t0)
                for k, v in res.timings.items():
                    stages[k] = stages.get(k, 0.0) + v
            spf = float(np.median(totals))
            n = args.frames
            evals = stages["evaluations"] / n
            # projection is fused into the XOR pass (fused_xor.py) at the default settings
            known = ("skinning", "projection", "xor", "proposals", "detection")
            rest = stages["total"] / n - sum(stages.get(k, 0.0) / n for k in known)
            print(f"threads={threads} {label:8s} {spf:6.3f} s/frame  {evals:6.0f} evaluations/frame  "
                  f"{evals / spf:8.0f} evaluations/s  | " + "  ".join(
                      f"{k} {stages.get(k, 0.0) / n:.3f}" for k in known) + f"  other {rest:.3f}",
                  flush=True)
            res = tracker.update(list(masks[n]), n + 1, maps[n])
            search = res.timings.get("research", float("nan"))
            print(f"{'':18s}fresh search (research.every): {search:.2f} s on its frame, "
                  f"{search / every:.3f} s/frame at the default of one every {every} frames",
                  flush=True)
        people = PeopleTracker(model, rig, from_flat(TrackerParams, {**settings,
                                                                     "method": "hpf-apo"}),
                               np.random.default_rng(0), shape=shape, max_people=2)
        people.update(list(masks[0]), 0)
        idle = [people.update(list(masks[f]), f)[1].timings["total"]
                for f in range(1, args.frames + 1)]
        print(f"threads={threads} a second slot (max_people 2) looking for somebody else: "
              f"{1000 * float(np.median(idle)):.0f} ms/frame", flush=True)


if __name__ == "__main__":
    main()
