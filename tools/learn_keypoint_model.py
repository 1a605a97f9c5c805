#!/usr/bin/env python3
"""Measure how the keypoint detector's 3D keypoints sit on the body model
(``hmocap_ros/data/keypoint_model.json``): the landmark offsets of the keypoint fit and the
size corrections of keypoint anthropometry.

On simulated bags with ground truth, the keypoint detector (the extremity node's code) runs
on every frame set; then

* **offsets** (:mod:`hmocap_ros.tracking.keypoint_fit`): per label, the median over all
  frames of the keypoint's residual from the body point of the true pose on the true body
  shape, turned into the frame of the joint the body point hangs on;
* **size corrections** (:mod:`hmocap_ros.tracking.keypoint_anthropometry`): per measure, the
  geometric mean over the bags of the ratio of its median over a bag's frames to the same
  distance between the body points (offsets included) of the bag's true subject.

Run it on bags that no evaluation uses::

    .venv/bin/python tools/learn_keypoint_model.py BAG [BAG ...] [--out FILE]

The shipped file was made from 3 s of CMU 13_29 (jumping jacks, twists; start 17 s, seed 31)
and of CMU 01_01 (jumps, turns; start 3 s, seed 32), 4 cameras at 640x480:
``hmocap sim mocap --bvh CLIP --start S --seconds 3 --seed N --out BAG``.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hmocap_ros.body import ENTITY_NAMES, load_body_model
from hmocap_ros.body.anthropometry import apply_shape
from hmocap_ros.body.kinematics import forward_kinematics
from hmocap_ros.body.skeleton import pose_to_local_rotations
from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams
from hmocap_ros.eval.mocap_frames import load_frames
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.tracking.keypoint_anthropometry import MEASURES, KeypointShape, model_log_measures
from hmocap_ros.tracking.keypoint_fit import KEYPOINT_MODEL_FILE, KeypointFit


def true_poses(bag: Path, model) -> dict:
    """stamp -> (D,) the true pose parameters (``/ground_truth/joint_states``)."""
    dofs = list(model.skeleton.dof_names)
    out = {}
    with BagReader(bag) as reader:
        for item in reader.messages([topics.GT_JOINT_STATES]):
            index = {str(n): i for i, n in enumerate(item.msg.name)}
            if all(d in index for d in dofs):
                out[stamp_to_ns(item.msg.header.stamp)] = np.array(
                    [item.msg.position[index[d]] for d in dofs])
    return out


def bag_samples(bag: Path, model, fit: KeypointFit):
    """Per label the residuals (N, 3) in the site joint's frame, the true shape, and the
    frames' detections."""
    frames = load_frames(bag, "fg", detector=ExtremityDetectionParams(detector="keypoints"))
    if frames.body_shape is None:
        raise SystemExit(f"{bag}: no ground-truth body shape ({topics.GT_BODY_SHAPE})")
    poses = true_poses(bag, model)
    rest = apply_shape(model, frames.body_shape)
    residuals = {label: [] for label in fit.labels}
    detections = []
    for stamp, det in zip(frames.stamps, frames.detections):
        if det is None or not len(det) or int(stamp) not in poses:
            continue
        detections.append(det)
        pose = poses[int(stamp)][None]
        points = fit.body_points(pose, rest)[0]
        rot, root = pose_to_local_rotations(model.skeleton, pose)
        transforms, _ = forward_kinematics(rot, root, rest.joints, model.parents)
        for k, label in enumerate(fit.labels):
            p = det.position(label)
            if p is not None:
                frame = transforms[0, fit.site_joints[k], :3, :3]
                residuals[label].append(frame.T @ (p - points[k]))
    return residuals, frames.body_shape, detections


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bags", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, default=KEYPOINT_MODEL_FILE)
    ns = parser.parse_args(argv)
    model = load_body_model("tracking")
    plain = KeypointFit(model)
    samples = [bag_samples(bag, model, plain) for bag in ns.bags]
    offsets = {}
    for label in plain.labels:
        pooled = [r for residuals, _, _ in samples for r in residuals[label]]
        if pooled:
            offsets[label] = np.median(np.array(pooled), axis=0)
            print(f"{label:16s} offset {np.round(1000 * offsets[label]).astype(int)} mm "
                  f"({len(pooled)} frames)")
    fit = KeypointFit(model, offsets=offsets)
    ratios = []
    n = len(ENTITY_NAMES)
    for bag, (_, shape, detections) in zip(ns.bags, samples):
        measured = KeypointShape(model, np.ones(len(MEASURES)), fit)
        for det in detections:
            measured.add(det)
        log_factors = np.concatenate([np.log(shape.bone_scale), [np.log(shape.global_scale)]])
        ratio = measured.measures() / np.exp(model_log_measures(model, fit, log_factors[:n + 1]))
        ratios.append(ratio)
        print(bag.name, " ".join(f"{m} {v:.3f}" for m, v in zip(MEASURES, ratio)))
    corrections = np.exp(np.nanmean(np.log(np.array(ratios)), axis=0))
    data = json.loads(ns.out.read_text()) if ns.out.exists() else {}
    data["offsets"] = {k: [round(float(x), 4) for x in v] for k, v in offsets.items()}
    data["size_corrections"] = {m: round(float(c), 4) for m, c in zip(MEASURES, corrections)
                                if np.isfinite(c)}
    data["bags"] = [bag.name for bag in ns.bags]
    ns.out.write_text(json.dumps(data, indent=1) + "\n")
    print(f"wrote {ns.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
