#!/usr/bin/env python3
"""Measure the corrections of keypoint anthropometry (``hmocap_ros/data/keypoint_sizes.json``).

For every measure of :mod:`hmocap_ros.tracking.keypoint_anthropometry` (a distance between
two 3D keypoints), the ratio of its median over a bag's frames, as the keypoint detector
measures it, to the same distance between the body model's points of the bag's true subject
(its ground-truth body shape, rest pose). The corrections are the geometric means of the
bags' ratios. Run on simulated bags that no evaluation uses::

    .venv/bin/python tools/learn_keypoint_sizes.py BAG [BAG ...] [--out FILE]

The shipped file was made from 3 s of CMU 13_29 (jumping jacks, twists; seed 31) and of CMU
01_01 (jumps, turns; seed 32), 4 cameras at 640x480: ``hmocap sim mocap --bvh CLIP --start S
--seconds 3 --seed N --out BAG``.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hmocap_ros.body import ENTITY_NAMES, load_body_model  # noqa: E402
from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams  # noqa: E402
from hmocap_ros.eval.mocap_frames import load_frames  # noqa: E402
from hmocap_ros.tracking.keypoint_anthropometry import (  # noqa: E402
    CORRECTIONS_FILE, MEASURES, KeypointShape, model_log_measures)
from hmocap_ros.tracking.keypoint_fit import KeypointFit  # noqa: E402


def bag_ratios(bag: Path, model) -> np.ndarray:
    """(M,) median keypoint measure over the true subject's model measure, of one bag."""
    frames = load_frames(bag, "fg", detector=ExtremityDetectionParams(detector="keypoints"))
    if frames.body_shape is None:
        raise SystemExit(f"{bag}: no ground-truth body shape (/ground_truth/body_shape)")
    measured = KeypointShape(model, np.ones(len(MEASURES)))
    for det in frames.detections:
        if det is not None and len(det):
            measured.add(det)
    truth = frames.body_shape
    n = len(ENTITY_NAMES)
    log_factors = np.concatenate([np.log(truth.bone_scale), [np.log(truth.global_scale)]])
    model_measures = np.exp(model_log_measures(model, KeypointFit(model), log_factors[:n + 1]))
    return measured.measures() / model_measures


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("bags", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, default=CORRECTIONS_FILE)
    ns = parser.parse_args(argv)
    model = load_body_model("tracking")
    ratios = np.array([bag_ratios(bag, model) for bag in ns.bags])
    for bag, r in zip(ns.bags, ratios):
        print(bag.name, " ".join(f"{m} {v:.3f}" for m, v in zip(MEASURES, r)))
    corrections = np.exp(np.nanmean(np.log(ratios), axis=0))
    data = json.loads(ns.out.read_text()) if ns.out.exists() else {}
    data["corrections"] = {m: round(float(c), 4) for m, c in zip(MEASURES, corrections)
                           if np.isfinite(c)}
    data["bags"] = [bag.name for bag in ns.bags]
    ns.out.write_text(json.dumps(data, indent=1) + "\n")
    print(f"wrote {ns.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
