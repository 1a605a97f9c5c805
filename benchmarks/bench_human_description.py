#!/usr/bin/env python3
"""How far REP-155's kinematic model (human_description), posed from a tracked body, puts its joints.

Random poses of the tracking body (every angle within its limits and within +-0.8 rad; the
spine's and neck's three angles each within +-LIMIT), the URDF of
:func:`~hmocap_ros.body.human_description.human_urdf` at the body's lengths, posed with
:func:`~hmocap_ros.body.human_description.urdf_joint_positions` and placed at the body frame:
per joint, the mean and largest distance (mm) from the tracked joint. REP-155's torso is rigid
with one pitch joint, so a spine bent sideways or twisted moves the URDF's shoulders (and with
them the arms) and head.

    .venv/bin/python benchmarks/bench_human_description.py [--poses 40]
"""
from __future__ import annotations

import argparse

import numpy as np


def main(argv=None) -> int:
    from hmocap_ros.body.human_description import (
        dimensions_from_joints,
        human_urdf,
        urdf_joint_names,
        urdf_joint_positions,
        urdf_link_poses,
    )
    from hmocap_ros.body.model import load_body_model
    from hmocap_ros.tracking import body_frames as bf

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=40, help="random poses per spine limit (default 40)")
    ns = ap.parse_args(argv)
    model = load_body_model("tracking")
    skel = model.skeleton
    names = list(skel.joint_names)
    at = {n: k for k, n in enumerate(names)}
    angles_idx = np.setdiff1d(np.arange(skel.n_dofs), skel.translation_dofs)
    lo, hi = np.maximum(skel.lower[angles_idx], -0.8), np.minimum(skel.upper[angles_idx], 0.8)
    links = {"shoulder": "y_shoulder", "wrist": "wrist", "hip": "y_hip", "ankle": "ankle"}
    for limit in (0.0, 0.15, 0.3):
        errors: dict = {j: [] for j in (*links, "head")}
        for seed in range(ns.poses):
            rng = np.random.default_rng(seed)
            params = model.rest_pose().copy()
            params[angles_idx] = lo + (hi - lo) * rng.random(angles_idx.size)
            for k, dof in enumerate(skel.dof_names):
                if dof.startswith(("spine", "neck")):
                    params[k] = rng.uniform(-limit, limit)
            transforms = bf.joint_transforms(model, params, model.joints_rest)
            joints, rotations = transforms[:, :3, 3], transforms[:, :3, :3] @ bf.REP155_AXES
            dims = dimensions_from_joints(names, joints, 1.7)
            angles = dict(zip(urdf_joint_names("b0"),
                              urdf_joint_positions(names, joints, rotations[at["pelvis"]], rotations[at["head"]])))
            root = np.eye(4)
            root[:3, :3], root[:3, 3] = rotations[at["pelvis"]], joints[at["pelvis"]]
            poses = urdf_link_poses(human_urdf("b0", dims), angles, root)
            for joint, link in links.items():
                for side in "lr":
                    placed = poses[f"{side}_{link}_b0"][:3, 3]
                    errors[joint].append(np.linalg.norm(placed - joints[at[f"{side}_{joint}"]]))
            errors["head"].append(np.linalg.norm(poses["p_head_b0"][:3, 3] - joints[at["head"]]))
        print(f"spine and neck within +-{limit:.2f} rad: " + ", ".join(
            f"{j} {1e3 * np.mean(v):.0f} mm (max {1e3 * np.max(v):.0f})" for j, v in errors.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
