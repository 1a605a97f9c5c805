"""``hmocap train gestures``: train a gesture forest (thesis sec. 3.2.3) from annotated depth bags.

Reads ``/depth/image_raw``, ``/depth/camera_info`` and ``/ground_truth/gestures`` of each bag
(the layout of ``hmocap sim gestures``; :func:`hmocap_ros.eval.gesture_eval.read_gesture_bags`)
into one compact uint16 millimetre stack, scales the pixel sizes of the defaults (given for
f = 525 px at 640x480) by ``fx / 525`` of the bags' camera, trains a forest with boosted (or
plain bagged) learning and hard negative mining, and saves it. Frames whose gesture reference
point is hidden (``position_valid`` false) are left out: they are neither a gesture sample nor
background. A near-miss frame (``/ground_truth/near_misses``, a hand that is almost a gesture)
is background labelled with the missed gesture's reference pixel, ``(0, u, v)``: patch
collection draws negatives on that hand and mining looks there first
(:mod:`hmocap_ros.gestures.patches`). All bags must share one image size and focal length.

The forest records the focal length it was trained at (``meta["training"]["focal_px"]``), so
that the detector can rescale its test offsets to another camera.

``--online`` grows an online random forest instead (thesis sec. 3.3.1, alg. 6;
:mod:`hmocap_ros.gestures.online_forest`): ``--passes`` times over the frames in random order,
one update per frame, background frames giving hard negatives found by on-the-fly detection
(sec. 3.3.2) or as many random ones (``--negatives``); one line of progress per pass.
``--resume FOREST`` keeps growing a saved online forest on more bags (sec. 3.4.2): its open
leaves' candidate tests and statistics are in the file, and without ``--seed`` the random
stream continues where the forest stopped, so training in two sessions gives the forest that
one session over the same frames gives.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from hmocap_ros.eval.gesture_eval import GestureBag, GestureBagError
from hmocap_ros.eval.gesture_training_bags import read_training_bags
from hmocap_ros.gestures.forest import train_forest_on_frames
from hmocap_ros.gestures.forest_file import ForestFileError, load_forest, save_forest
from hmocap_ros.gestures.online_forest import OnlineForest, PassReport, train_online_on_frames
from hmocap_ros.gestures.params import (
    NEGATIVE_MODES,
    REFERENCE_FOCAL_PX,
    FeatureParams,
    OnlineParams,
    OnlineTrainParams,
    train_params_for_focal,
)

__all__ = ["REFERENCE_FOCAL_PX", "add_arguments", "main_from_args", "print_data_summary"]


#: ``--kappa none``: plain tests (eq. 3.3).
PLAIN = "none"


def _kappa(text: str) -> float | str:
    if text.lower() in ("none", "plain", "off"):
        return PLAIN
    value = float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError("kappa must be > 0 (metres) or 'none'")
    return value


def _kappa_m(ns) -> float | None:
    """``--kappa`` as ``train_params_for_focal`` takes it: None = plain tests, default 0.15 m."""
    return None if ns.kappa == PLAIN else _or(ns.kappa, 0.15)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bags", nargs="+", metavar="BAG", help="annotated depth bags (hmocap sim gestures layout)")
    parser.add_argument("--out", required=True, help="forest file to write (.npz)")
    parser.add_argument("--trees", type=int, default=None, help="trees M (default 15)")
    parser.add_argument("--depth", type=int, default=None, help="maximum tree depth D (default 20)")
    parser.add_argument("--kappa", type=_kappa, default=None,
                        help="clipping kappa in metres (eq. 3.6), or 'none' for plain tests (default 0.15)")
    parser.add_argument("--no-boost", action="store_true", help="independent balanced bags instead of boosting")
    parser.add_argument("--samples-per-class", type=int, default=None,
                        help="balanced bag samples per class and tree (default 10000)")
    parser.add_argument("--mining-rounds", type=int, default=None,
                        help="rounds of hard negative mining on the training frames (default 1; 0 = none)")
    parser.add_argument("--located-share", type=float, default=None,
                        help="located near-miss negatives per tree bag, as a share of --samples-per-class "
                             "(default 1; 0 = drawn as any background sample)")
    online = parser.add_argument_group("online forests (thesis sec. 3.3; --online or --resume)")
    online.add_argument("--online", action="store_true", help="grow an online random forest (alg. 6)")
    online.add_argument("--resume", metavar="FOREST", help="keep growing this online forest (its trees, depth, "
                                                           "tests and, unless given, alpha/beta/lambda/negatives)")
    online.add_argument("--passes", type=int, default=None, help="passes over the bags' frames (default 5)")
    online.add_argument("--negatives", choices=NEGATIVE_MODES, default=None,
                        help="negatives of background frames: hard (on-the-fly detection, sec. 3.3.2) or "
                             "random, as many (default hard)")
    online.add_argument("--alpha", type=float, default=None,
                        help=f"samples a leaf must have seen to split (default {OnlineParams().alpha:g})")
    online.add_argument("--beta", type=float, default=None,
                        help=f"information gain (nats) a split must exceed (default {OnlineParams().beta:g})")
    online.add_argument("--lambda", dest="poisson_lambda", metavar="LAMBDA", type=float, default=None,
                        help=f"Poisson rate of online bagging (default {OnlineParams().poisson_lambda:g})")
    online.add_argument("--tests", type=int, default=None,
                        help=f"random offset pairs per leaf (default {OnlineParams().n_tests})")
    online.add_argument("--thresholds", type=int, default=None,
                        help=f"random thresholds per offset pair (default {OnlineParams().n_thresholds}; "
                             f"candidate tests per leaf = tests x thresholds)")
    parser.add_argument("--seed", type=int, default=None,
                        help="random seed (default 0; --resume: the stream the forest stopped at)")
    parser.add_argument("--force", action="store_true", help="overwrite --out")
    parser.add_argument("--quiet", action="store_true", help="no progress bar (online: no line per pass)")


def main_from_args(ns) -> int:
    out = Path(ns.out)
    online = ns.online or ns.resume is not None
    same_file = ns.resume is not None and out.resolve() == Path(ns.resume).resolve()
    if out.exists() and not ns.force and not same_file:
        print(f"error: {out} exists (use --force to overwrite)", file=sys.stderr)
        return 2
    wrong = [name for name, value in (_offline_options if online else _online_options)(ns) if value]
    if wrong:
        print(f"error: {', '.join(wrong)} {'do' if len(wrong) > 1 else 'does'} not apply to "
              f"{'online' if online else 'offline'} training", file=sys.stderr)
        return 2
    if online:
        return main_online(ns, out)
    try:
        data, n_hidden = read_training_bags(ns.bags)
        params = train_params_for_focal(data.focal_px, n_trees=_or(ns.trees, 15), max_depth=_or(ns.depth, 20),
                                        kappa_m=_kappa_m(ns), boosted=not ns.no_boost,
                                        samples_per_class=_or(ns.samples_per_class, 10000),
                                        mining_rounds=_or(ns.mining_rounds, 1),
                                        located_share=_or(ns.located_share, 1.0))
    except (GestureBagError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print_data_summary(data, n_hidden)
    rng = np.random.default_rng(_or(ns.seed, 0))
    try:
        forest = train_forest_on_frames(data.depth, data.labels, params, rng, class_names=data.class_names,
                                        progress=not ns.quiet)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    forest.meta["training"].update({"focal_px": data.focal_px, "bags": [Path(b).name for b in ns.bags],
                                    "seed": _or(ns.seed, 0)})
    save_forest(forest, out)
    tr = forest.meta["training"]
    last = tr["trees"][-1]
    print(f"{out}: {len(forest.trees)} trees, {forest.n_nodes} nodes, classes {', '.join(forest.class_names[1:])}; "
          f"{forest.features.feature_type}"
          + (f" kappa {forest.features.kappa_m:.2f} m" if forest.features.clipped else "")
          + f", {tr['method']}; out-of-bag balanced error {last['forest_oob_error']:.3f}; "
          f"{tr['seconds']:.1f} s; {out.stat().st_size / 1e6:.2f} MB")
    return 0


def _or(value, default):
    return default if value is None else value


def _offline_options(ns):
    return [("--no-boost", ns.no_boost), ("--samples-per-class", ns.samples_per_class is not None),
            ("--mining-rounds", ns.mining_rounds is not None), ("--located-share", ns.located_share is not None)]


def _online_options(ns):
    return [(f"--{name.replace('_', '-')}", getattr(ns, name) is not None)
            for name in ("passes", "negatives", "alpha", "beta", "tests", "thresholds")] + [
        ("--lambda", ns.poisson_lambda is not None)]


def print_data_summary(data: GestureBag, n_hidden: int) -> None:
    n_pos = sum(lab is not None and lab[0] > 0 for lab in data.labels)
    n_near = sum(m is not None for m in data.near_misses or ())
    print(f"{len(data.labels)} frames {data.width}x{data.height}, fx {data.focal_px:.1f} px "
          f"(pixel sizes x{data.focal_px / REFERENCE_FOCAL_PX:.3f}); {n_pos} with a gesture, {n_near} near misses, "
          f"{n_hidden} with a hidden reference point left out")


def _online_setup(ns, data: GestureBag):
    """(online forest, patch parameters, Generator) for ``--online`` or ``--resume``."""
    base = OnlineTrainParams().for_focal(data.focal_px)
    given = {k: v for k, v in (("alpha", ns.alpha), ("beta", ns.beta), ("poisson_lambda", ns.poisson_lambda),
                               ("negatives", ns.negatives)) if v is not None}
    if ns.resume is None:
        kappa = _kappa_m(ns)
        features = FeatureParams(feature_type="plain" if kappa is None else "clipped",
                                 kappa_m=FeatureParams().kappa_m if kappa is None else kappa)
        online = OnlineParams(n_trees=_or(ns.trees, 15), max_depth=_or(ns.depth, 20),
                              n_tests=_or(ns.tests, OnlineParams().n_tests),
                              n_thresholds=_or(ns.thresholds, OnlineParams().n_thresholds), **given)
        params = OnlineTrainParams(features=features, online=online).for_focal(data.focal_px)
        rng = np.random.default_rng(_or(ns.seed, 0))
        forest = OnlineForest(data.class_names, params.features, params.online, rng,
                              {"training": {"method": "online", "focal_px": data.focal_px,
                                            "image_size": [data.width, data.height]}})
        return forest, params.patches, rng
    stored = load_forest(ns.resume)
    forest = OnlineForest.from_forest(stored)
    p = forest.params
    for option, value, have in (("--trees", ns.trees, p.n_trees), ("--depth", ns.depth, p.max_depth),
                                ("--tests", ns.tests, p.n_tests), ("--thresholds", ns.thresholds, p.n_thresholds)):
        if value is not None and value != have:
            raise ValueError(f"{ns.resume}: a resumed forest keeps its {option} {have}")
    if ns.kappa is not None:
        raise ValueError(f"{ns.resume}: a resumed forest keeps its tests (--kappa does not apply)")
    if stored.class_names != data.class_names:
        raise ValueError(f"{ns.resume}: classes {stored.class_names[1:]} differ from the bags' {data.class_names[1:]}")
    if stored.training_focal_px and abs(stored.training_focal_px - data.focal_px) > 1e-6 * data.focal_px:
        raise ValueError(f"{ns.resume}: grown at fx {stored.training_focal_px:g} px, the bags have {data.focal_px:g}")
    forest.params = replace(p, **given)
    rng = np.random.default_rng(_or(ns.seed, 0))
    if ns.seed is None and "rng_state" in stored.meta["online"]:
        rng.bit_generator.state = stored.meta["online"]["rng_state"]
    return forest, base.patches, rng


def main_online(ns, out: Path) -> int:
    """``--online`` / ``--resume``: grow an online forest (thesis sec. 3.3) on the bags and save it."""
    passes = _or(ns.passes, 5)
    if passes < 1:
        print("error: --passes must be >= 1", file=sys.stderr)
        return 2
    try:
        data, n_hidden = read_training_bags(ns.bags)
        forest, patches, rng = _online_setup(ns, data)
    except (GestureBagError, ForestFileError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print_data_summary(data, n_hidden)
    p = forest.params
    print(f"online forest: {p.n_trees} trees, depth <= {p.max_depth}, {p.n_candidates} candidate tests per leaf, "
          f"alpha {p.alpha:g}, beta {p.beta:g}, lambda {p.poisson_lambda:g}, {p.negatives} negatives"
          + (f"; resuming {ns.resume} ({forest.n_nodes} nodes)" if ns.resume else ""))

    def progress(r: PassReport) -> None:
        if not ns.quiet:
            print(f"  pass {r.index + 1}/{r.n_passes}: {r.samples} samples ({r.frame_negatives} from background "
                  f"frames), {r.splits} splits, {r.n_nodes} nodes, {r.open_leaves} open leaves, "
                  f"{r.memory_bytes / 1e6:.1f} MB, {r.seconds:.0f} s", flush=True)

    try:
        train_online_on_frames(data.depth, data.labels, patches, forest, rng, passes, progress)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    state = forest.meta["online"]
    seconds = sum(r["seconds"] for r in state["passes"][-passes:])
    state.setdefault("sessions", []).append({"bags": [Path(b).name for b in ns.bags], "passes": passes,
                                             "negatives": p.negatives, "seed": ns.seed, "seconds": seconds})
    state["rng_state"] = rng.bit_generator.state
    training = forest.meta.setdefault("training", {})
    training["bags"] = training.get("bags", []) + [Path(b).name for b in ns.bags]
    training["seconds_total"] = training.get("seconds_total", 0.0) + seconds
    saved = forest.to_forest()
    save_forest(saved, out)
    print(f"{out}: online, {len(saved.trees)} trees, {saved.n_nodes} nodes ({forest.n_open_leaves} open leaves), "
          f"classes {', '.join(saved.class_names[1:])}; {seconds:.1f} s; {out.stat().st_size / 1e6:.2f} MB")
    return 0
