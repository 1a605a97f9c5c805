#!/usr/bin/env python3
"""Is a tracking failure the cost's or the search's? Split it on a simulated bag.

Replays a bag through the tracker (the same code as ``hmocap eval mocap``) and, at every frame
with ground truth, weighs with the whole-body silhouette cost (eq. 2.8) the tracker's
estimate, the ground-truth pose (``/ground_truth/joint_states``), and the estimate with one
group of its DoFs replaced by the truth's (torso = root 6 DoF, spine and neck; arms; legs;
torso and legs; torso and arms). All poses are weighed with the body shape the tracker
estimated, as the filter does.

Reading it:

- truth cheaper than the estimate: the cost knows better and the filter did not find it (a
  *search* failure: more particles, better proposals or kernels can help);
- estimate as cheap as the truth or cheaper: the silhouettes do not tell the two apart at this
  shape (a *cost* failure: no search fixes it, another cue is needed);
- a group whose substitution alone brings the cost down to the truth's is the one that is off;
  when only a pair does (e.g. torso and legs), the error is a coupled one that a layer
  searching one group at a time cannot leave;
- ``yaw_off``: the estimate's pelvis heading (root yaw) minus the truth's, in degrees;
- ``views``: the cameras that see the whole true skeleton (every joint inside the image, 3 %
  margin, as the simulator places its subjects); the summary splits the error by it, to tell
  a failure of the search from a subject leaving the views.

::

    .venv/bin/python tools/failure_split.py BAG.mcap --method hpf-apo --seed 0
    .venv/bin/python tools/failure_split.py BAG.mcap --silhouettes gt --param dd_reacquire=false

Prints one line per frame (mean joint error, costs) and a summary.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hmocap_ros.body import load_body_model  # noqa: E402
from hmocap_ros.eval.metrics import joint_errors, match_joints  # noqa: E402
from hmocap_ros.eval.mocap_eval import DETECTOR_METHODS, load_frames, tracker_overrides  # noqa: E402
from hmocap_ros.io import topics  # noqa: E402
from hmocap_ros.io.bag_reader import BagReader  # noqa: E402
from hmocap_ros.io.conversions import joint_state_to_dict  # noqa: E402
from hmocap_ros.io.msg_factory import stamp_to_ns  # noqa: E402
from hmocap_ros.sim.mocap_dataset import views_seeing  # noqa: E402
from hmocap_ros.tracking.body_tracker import BodyTracker, TrackerParams  # noqa: E402

#: substitutions weighed besides the estimate and the truth: name -> DoF groups from the truth
GROUPS = {"torso": ("torso",), "arms": ("l_shoulder", "r_shoulder", "l_elbow", "r_elbow"),
          "legs": ("l_leg", "r_leg"), "torso+legs": ("torso", "l_leg", "r_leg"),
          "torso+arms": ("torso", "l_shoulder", "r_shoulder", "l_elbow", "r_elbow")}


def true_params(bag: str) -> dict:
    """Ground-truth pose parameters by stamp (ns)."""
    out = {}
    with BagReader(bag) as reader:
        if topics.GT_JOINT_STATES not in reader.topics():
            raise SystemExit(f"{bag}: no {topics.GT_JOINT_STATES}: not a simulator bag")
        for item in reader.messages([topics.GT_JOINT_STATES]):
            out[stamp_to_ns(item.msg.header.stamp)] = np.asarray(
                joint_state_to_dict(item.msg)["position"], dtype=np.float64)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bag")
    ap.add_argument("--method", default="hpf-apo")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--silhouettes", choices=("fg", "gt"), default="fg")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                    help="TrackerParams override, as for hmocap eval mocap")
    ns = ap.parse_args()

    truth = true_params(ns.bag)
    frames = load_frames(ns.bag, ns.silhouettes, detector_maps=ns.method in DETECTOR_METHODS)
    model = load_body_model("tracking")
    skel = model.skeleton
    params = TrackerParams(method=ns.method, **tracker_overrides(ns.param))
    tracker = BodyTracker(model, frames.rig, params, np.random.default_rng(ns.seed))
    est_idx, true_idx = match_joints(model.joint_names, frames.joint_names)
    dofs = {name: np.concatenate([skel.group_dofs(g) for g in groups])
            for name, groups in GROUPS.items()}
    names = ["estimate", *GROUPS, "truth"]
    yaw = skel.dof_index("root_yaw")
    print("frame  views  error_mm  yaw_off  " + "  ".join(f"{n:>10s}" for n in names))
    rows = []
    for k, stamp in enumerate(frames.stamps):
        masks = frames.mask_list(k)
        maps = frames.maps[k] if frames.maps is not None else None
        result = tracker.update(masks, int(stamp), maps)
        if not result.has_pose or tracker.state != "tracking" or int(stamp) not in truth:
            continue
        est, gt = result.params, truth[int(stamp)]
        poses = [est]
        for d in dofs.values():
            p = est.copy()
            p[d] = gt[d]
            poses.append(p)
        poses.append(gt)
        obs = tracker.fitness.observe(masks, int(stamp))
        cost = tracker.fitness.costs(np.stack(poses), obs, tracker.fitness.rest(tracker.shape))
        err = float(joint_errors(result.joints[est_idx][None],
                                 frames.truth[k][true_idx][None]).mean())
        views = int(views_seeing(frames.rig, frames.truth[k][None], 0.03)[0].sum())
        yaw_off = float(np.rad2deg((est[yaw] - gt[yaw] + np.pi) % (2.0 * np.pi) - np.pi))
        rows.append((err, cost, views, yaw_off))
        print(f"{k:5d}  {views:5d}  {err:8.1f}  {yaw_off:7.1f}  "
              + "  ".join(f"{c:10.3f}" for c in cost))
    if not rows:
        print("no tracked frame with ground truth")
        return 1
    err = np.array([r[0] for r in rows])
    cost = np.array([r[1] for r in rows])
    search = cost[:, -1] < cost[:, 0]
    print(f"\n{len(rows)} tracked frames, mean error {err.mean():.1f} mm; mean cost: "
          + ", ".join(f"{n} {c:.3f}" for n, c in zip(names, cost.mean(axis=0))))
    yaw_abs = np.abs([r[3] for r in rows])
    print(f"pelvis heading off by {yaw_abs.mean():.1f} degrees on average, {yaw_abs.max():.1f} "
          "at most")
    print(f"truth cheaper than the estimate (search failure) in {search.sum()}/{len(rows)} "
          f"frames; as cheap or dearer (cost failure) in {(~search).sum()}")
    views = np.array([r[2] for r in rows])
    print("error by the views seeing the whole true skeleton: " + ", ".join(
        f"{v} views {err[views == v].mean():.1f} mm ({(views == v).sum()} frames)"
        for v in sorted(set(views.tolist()), reverse=True)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
