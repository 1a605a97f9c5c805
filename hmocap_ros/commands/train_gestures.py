"""``hmocap train gestures``: train a gesture forest (thesis sec. 3.2.3) from annotated depth bags.

Reads ``/depth/image_raw``, ``/depth/camera_info`` and ``/ground_truth/gestures`` of each bag
(the layout of ``hmocap sim gestures``; :func:`hmocap_ros.eval.gesture_eval.read_gesture_bags`)
into one compact uint16 millimetre stack, scales the pixel sizes of the defaults (given for
f = 525 px at 640x480) by ``fx / 525`` of the bags' camera, trains a forest with boosted (or
plain bagged) learning and hard negative mining, and saves it. Frames whose gesture reference
point is hidden (``position_valid`` false) are left out: they are neither a gesture sample nor
background. All bags must share one image size and focal length.

The forest records the focal length it was trained at (``meta["training"]["focal_px"]``), so
that the detector can rescale its test offsets to another camera.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from hmocap_ros.eval.gesture_eval import GestureBag, GestureBagError, read_gesture_bags
from hmocap_ros.gestures.depth_features import depth_to_millimetres
from hmocap_ros.gestures.forest import train_forest_on_frames
from hmocap_ros.gestures.forest_file import save_forest
from hmocap_ros.gestures.params import REFERENCE_FOCAL_PX, FeatureParams, ForestParams, TrainParams

__all__ = ["REFERENCE_FOCAL_PX", "add_arguments", "main_from_args", "read_training_bags", "train_params_for_focal"]


def read_training_bags(paths, params: TrainParams | None = None) -> tuple[GestureBag, int]:
    """The trainable frames of annotated bags as compact uint16 millimetres, 0 = invalid
    (``params.depth``; :func:`~hmocap_ros.gestures.depth_features.depth_to_millimetres`):
    background frames and gesture frames whose reference point is visible, in bag order. Each
    frame is converted as it is read and the others are dropped in place, so memory holds one
    copy of the frames at 0.6 MB per 640x480 frame. Returns the frames and the number of frames
    left out."""
    params = params if params is not None else TrainParams()
    fmt, background = params.depth, params.features.background_depth_m
    data = read_gesture_bags(paths, frame_fn=lambda raw: depth_to_millimetres(raw, fmt, background))
    keep = np.flatnonzero(data.trainable)
    frames = data.depth
    for j, i in enumerate(keep):  # per frame, not per pixel: compaction without a second stack
        if i != j:
            frames[j] = frames[i]
    return GestureBag(frames[:keep.size], data.stamps_ns[keep], [data.labels[i] for i in keep],
                      data.visible[keep], data.focal_px, data.class_names, data.sources), len(data.labels) - keep.size


def train_params_for_focal(focal_px: float, *, n_trees: int = 15, max_depth: int = 20,
                           kappa_m: float | None = 0.15, boosted: bool = True,
                           samples_per_class: int = 10000, mining_rounds: int = 1) -> TrainParams:
    """The default training parameters with the pixel sizes scaled from f = 525 px to
    ``focal_px`` (:meth:`TrainParams.for_focal`); ``kappa_m`` None = plain tests (eq. 3.3), else
    clipped tests (eq. 3.6)."""
    features = FeatureParams(feature_type="plain" if kappa_m is None else "clipped",
                             kappa_m=FeatureParams().kappa_m if kappa_m is None else float(kappa_m))
    forest = ForestParams(n_trees=n_trees, max_depth=max_depth, boosted=boosted,
                          samples_per_class=samples_per_class, mining_rounds=mining_rounds)
    return TrainParams(features=features, forest=forest).for_focal(focal_px)


def _kappa(text: str) -> float | None:
    if text.lower() in ("none", "plain", "off"):
        return None
    value = float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError("kappa must be > 0 (metres) or 'none'")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bags", nargs="+", metavar="BAG", help="annotated depth bags (hmocap sim gestures layout)")
    parser.add_argument("--out", required=True, help="forest file to write (.npz)")
    parser.add_argument("--trees", type=int, default=15, help="trees M (default 15)")
    parser.add_argument("--depth", type=int, default=20, help="maximum tree depth D (default 20)")
    parser.add_argument("--kappa", type=_kappa, default=0.15,
                        help="clipping kappa in metres (eq. 3.6), or 'none' for plain tests (default 0.15)")
    parser.add_argument("--no-boost", action="store_true", help="independent balanced bags instead of boosting")
    parser.add_argument("--samples-per-class", type=int, default=10000,
                        help="balanced bag samples per class and tree (default 10000)")
    parser.add_argument("--mining-rounds", type=int, default=1,
                        help="rounds of hard negative mining on the training frames (default 1; 0 = none)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--force", action="store_true", help="overwrite --out")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def main_from_args(ns) -> int:
    out = Path(ns.out)
    if out.exists() and not ns.force:
        print(f"error: {out} exists (use --force to overwrite)", file=sys.stderr)
        return 2
    try:
        data, n_hidden = read_training_bags(ns.bags)
        params = train_params_for_focal(data.focal_px, n_trees=ns.trees, max_depth=ns.depth, kappa_m=ns.kappa,
                                        boosted=not ns.no_boost, samples_per_class=ns.samples_per_class,
                                        mining_rounds=ns.mining_rounds)
    except (GestureBagError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    n_pos = sum(lab is not None for lab in data.labels)
    print(f"{len(data.labels)} frames {data.width}x{data.height}, fx {data.focal_px:.1f} px "
          f"(pixel sizes x{data.focal_px / REFERENCE_FOCAL_PX:.3f}); {n_pos} with a gesture, "
          f"{n_hidden} with a hidden reference point left out")
    rng = np.random.default_rng(ns.seed)
    try:
        forest = train_forest_on_frames(data.depth, data.labels, params, rng, class_names=data.class_names,
                                        progress=not ns.quiet)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    forest.meta["training"].update({"focal_px": data.focal_px, "bags": [Path(b).name for b in ns.bags],
                                    "seed": ns.seed})
    save_forest(forest, out)
    tr = forest.meta["training"]
    last = tr["trees"][-1]
    print(f"{out}: {len(forest.trees)} trees, {forest.n_nodes} nodes, classes {', '.join(forest.class_names[1:])}; "
          f"{forest.features.feature_type}"
          + (f" kappa {forest.features.kappa_m:.2f} m" if forest.features.clipped else "")
          + f", {tr['method']}; out-of-bag balanced error {last['forest_oob_error']:.3f}; "
          f"{tr['seconds']:.1f} s; {out.stat().st_size / 1e6:.2f} MB")
    return 0

