#!/usr/bin/env python3
"""Thesis table 3.1 on simulated depth: AP per gesture for plain tests (eq. 3.3) vs depth
clipping kappa = 15/30/50 cm (eq. 3.6), boosted vs plain (bagged) learning (sec. 3.2.3).

One command (about 1.5 h on 2 busy cores; bags and forests are cached in ``--workdir``/SENSOR, so
an interrupted run resumes where it stopped)::

    .venv/bin/python tools/gesture_table.py

1. Generates (``hmocap sim gestures``) three training bags, a validation bag and two test bags,
   all 640x480 with disjoint subjects and seeds, hence disjoint people, rooms, clutter and
   bystanders (:data:`BAGS`). ``test_close`` puts the back wall 0.15-0.85 m behind the person
   (``--background close``), a background the training rooms (0.4-2.3 m) never show: the case
   depth clipping is for.
2. Trains the eight forests with the code of ``hmocap train gestures`` (15 trees, depth 20,
   one round of hard negative mining, seed 0; only the tests and the learning scheme differ)
   on the training frames, read once.
3. Scores each on the validation and test bags with the code of ``hmocap eval gestures``
   (correct class within 10 px at 640x480, all-point interpolated AP).
4. Writes ``docs/figures/gesture_table.md`` (the tables), ``docs/figures/gesture_table.json``
   (every number) and ``docs/figures/gesture_pr.png`` (precision-recall curves of the default
   forest, boosted kappa = 15 cm, on the test bag).

The shipped forest ``hmocap_ros/data/gesture_forest.npz`` is the default variant (boosted,
kappa 15 cm) trained with a fourth, near-miss bag: ``--near-forest`` trains and scores it,
``--ship`` writes it there without its per-gesture thresholds (see GESTURE_FOREST.md).
``--shipped`` scores the shipped forest as the node runs it (AP, the frames with a false
detection and the recall at the node's thresholds, the near-miss bags). Its near-miss frames are
located (``/ground_truth/near_misses``): patch collection draws background samples on the hand
that is almost a gesture and mining looks there first. Its per-gesture thresholds are chosen
on the validation bags ``val`` and ``val_near`` (:mod:`hmocap_ros.eval.gesture_thresholds`,
``--max-false-per-minute``, ``--min-recall``) and stored in the file; the held-out bags ``test``, ``test_close``
and ``test_near`` score it at those thresholds.
The defaults are chosen on the validation bag; the test bags are held out for this table.

Every bag is rendered with one depth sensor family, ``--sensor`` (default structured light,
:mod:`hmocap_sim.depth_sensor`), cached in ``--workdir``/SENSOR; the figures of another family
are written with its name appended (``gesture_shipped_ideal.md``). ``--bags`` scores only some
of the evaluation bags.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hmocap_ros.eval.gesture_eval import SWEEP_MIN_SCORE, evaluate_gestures, plot_pr, read_gesture_bag
from hmocap_ros.eval.gesture_thresholds import gesture_threshold_curves, set_gesture_thresholds
from hmocap_ros.eval.gesture_training_bags import read_training_bags
from hmocap_ros.gestures.forest import train_forest_on_frames
from hmocap_ros.gestures.forest_file import load_forest, save_forest
from hmocap_ros.gestures.params import DetectorParams, train_params_for_focal
from hmocap_sim import gesture_dataset as gd
from hmocap_sim.depth_sensor import DEFAULT_SENSOR, SENSOR_NAMES
from hmocap_sim.gesture_set import GESTURE_CLASSES

#: name -> ``hmocap sim gestures`` arguments (all 640x480). Short holds in the training bags give
#: more distinct poses per frame; the validation and test bags hold gestures 5-10 frames.
BAGS = {
    "train1": dict(seed=1000, subjects=8, subject_offset=1000, frames=1500),
    "train2": dict(seed=1001, subjects=16, subject_offset=1100, frames=3000, hold=(2, 4)),
    "train3": dict(seed=1002, subjects=16, subject_offset=1200, frames=3000, hold=(2, 3)),
    "val": dict(seed=3001, subjects=8, subject_offset=3100, frames=1200),
    "test": dict(seed=2000, subjects=8, subject_offset=2000, frames=1200),
    "test_close": dict(seed=2001, subjects=8, subject_offset=2100, frames=1200, background="close"),
    "train_near": dict(seed=1003, subjects=16, subject_offset=1300, frames=3000, hold=(2, 4), near_misses=6),
    "val_near": dict(seed=3002, subjects=8, subject_offset=3200, frames=600, gestures=(), negatives=0,
                     near_misses=6, near_of=GESTURE_CLASSES),
    "test_near": dict(seed=2002, subjects=8, subject_offset=2200, frames=1200, gestures=(), negatives=0,
                      near_misses=6, near_of=GESTURE_CLASSES),
}
TRAIN = ("train1", "train2", "train3")
#: The near-miss forest: the default variant trained on :data:`TRAIN` and the near-miss bag.
NEAR_TRAIN = TRAIN + ("train_near",)
SHIPPED = ROOT / "hmocap_ros" / "data" / "gesture_forest.npz"
#: The bags the shipped forest was trained on (hmocap_ros/data/GESTURE_FOREST.md).
SHIPPED_TRAIN = NEAR_TRAIN
EVAL = ("val", "test", "test_close")
#: Bags of near misses only (no gesture): scored by the false detections at the node's thresholds.
NEAR = ("val_near", "test_near")
#: The validation bags the near-miss forest's per-gesture thresholds are chosen on (never the test bags).
THRESHOLD_BAGS = ("val", "val_near")
#: The variants are scored with the exact vote (every tree walked for an undecided pixel): the
#: table compares forests, not the detector's speed setting (DetectorParams.vote_reach).
EXACT = DetectorParams(min_score=SWEEP_MIN_SCORE, min_volume=0.0, vote_reach=1.0)
KAPPAS = (None, 0.15, 0.30, 0.50)
DEFAULT = "boosted, kappa 15 cm"


def sim_command(name: str, sensor: str = DEFAULT_SENSOR) -> str:
    kw = BAGS[name]
    args = [f"--seed {kw['seed']}", f"--subjects {kw['subjects']}", f"--subject-offset {kw['subject_offset']}",
            f"--frames {kw['frames']}"]
    if "hold" in kw:
        args.append(f"--hold {kw['hold'][0]} {kw['hold'][1]}")
    if "background" in kw:
        args.append(f"--background {kw['background']}")
    if "gestures" in kw:
        args.append("--gestures " + " ".join(kw["gestures"]))
    if "negatives" in kw:
        args.append(f"--negatives {kw['negatives']}")
    if "near_misses" in kw:
        args.append(f"--near-misses {kw['near_misses']}")
    if "near_of" in kw:
        args.append("--near-misses-of " + " ".join(kw["near_of"]))
    if sensor != DEFAULT_SENSOR:
        args.append(f"--sensor {sensor}")
    return f"hmocap sim gestures {' '.join(args)} --out {name}.mcap"


def make_bag(work: Path, name: str, sensor: str = DEFAULT_SENSOR) -> Path:
    path = work / f"{name}.mcap"
    if not path.exists():
        t0 = time.perf_counter()
        gd.generate(path, contact=False, progress=False, sensor=sensor, **BAGS[name])
        print(f"generated {path} in {time.perf_counter() - t0:.0f} s", flush=True)
    return path


def variant_name(boosted: bool, kappa: float | None) -> str:
    return ("boosted" if boosted else "plain") + (", no clipping" if kappa is None else f", kappa {kappa * 100:.0f} cm")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--workdir", default="/tmp/hmocap_gesture_table",
                   help="bags, forests and results (cache), in a folder per sensor")
    p.add_argument("--sensor", choices=SENSOR_NAMES, default=DEFAULT_SENSOR,
                   help="the depth sensor family of every bag (hmocap sim gestures --sensor); the figures of "
                        "another than the default are written with the sensor's name appended")
    p.add_argument("--bags", nargs="+", choices=EVAL + NEAR, default=None,
                   help="with --shipped or --near-forest: score only these evaluation bags (default all)")
    p.add_argument("--trees", type=int, default=15)
    p.add_argument("--depth", type=int, default=20)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--only", nargs="*", help="train/score only these variants (names as in the table)")
    p.add_argument("--out-dir", default=str(ROOT / "docs" / "figures"))
    p.add_argument("--shipped", action="store_true",
                   help="score only the shipped forest (hmocap_ros/data/gesture_forest.npz) as the node runs it, "
                        "on the held-out and near-miss bags: docs/figures/gesture_shipped.md and .json")
    p.add_argument("--near-forest", action="store_true",
                   help="train and score the default variant on the training bags and the near-miss bag: "
                        "docs/figures/gesture_near_forest.md and .json")
    p.add_argument("--ship", action="store_true",
                   help="with --near-forest: write that forest, without its per-gesture thresholds, to "
                        "hmocap_ros/data/")
    p.add_argument("--max-false-per-minute", type=float, default=1.0,
                   help="with --near-forest: the node's false-event budget on the validation bags from which "
                        "each gesture's threshold is chosen (split evenly over the gestures)")
    p.add_argument("--min-recall", type=float, default=0.8,
                   help="with --near-forest: the share of a gesture's validation frames its threshold must find")
    return p


def train_variant(ns, bags: dict, boosted: bool, kappa: float | None, model: Path, training: dict,
                  names: tuple = TRAIN) -> None:
    """Train one variant on the training bags ``names`` and save it to ``model``; ``training``
    holds the training frames once read (shared by the variants)."""
    if training.get("names") != names:
        training.clear()
        training["data"], _ = read_training_bags([bags[b] for b in names])
        training["names"] = names
    train = training["data"]
    params = train_params_for_focal(train.focal_px, n_trees=ns.trees, max_depth=ns.depth, kappa_m=kappa,
                                    boosted=boosted)
    t0 = time.perf_counter()
    forest = train_forest_on_frames(train.depth, train.labels, params, np.random.default_rng(ns.seed),
                                    class_names=train.class_names)
    forest.meta["training"].update({"focal_px": train.focal_px, "bags": [f"{b}.mcap" for b in names],
                                    "seed": ns.seed})
    save_forest(forest, model)
    print(f"{variant_name(boosted, kappa)}: trained in {time.perf_counter() - t0:.0f} s ({forest.n_nodes} nodes)",
          flush=True)


def score_variant(name: str, model: Path, bags: dict) -> dict:
    """The forest's size and training figures, and its evaluation on each of :data:`EVAL`."""
    forest = load_forest(model)
    r = {"forest": str(model), "n_nodes": forest.n_nodes, "file_bytes": model.stat().st_size,
         "train_seconds": forest.meta["training"]["seconds_total"],
         "train_samples": forest.meta["training"]["n_samples"],
         "train_frames": forest.meta["training"]["n_frames"]}
    for bag in EVAL:
        data = read_gesture_bag(bags[bag])
        e = evaluate_gestures(data, forest, EXACT)
        r[bag] = e
        aps = " ".join(f"{g} {c['ap']:.2f}" for g, c in e["per_class"].items())
        print(f"{name} on {bag}: mean AP {e['mean_ap']:.3f} ({aps})", flush=True)
        del data
    return r


def score_shipped(model: Path, bags: dict, train: tuple, scored: tuple = EVAL + NEAR,
                  sensor: str = DEFAULT_SENSOR, train_sensor: str = DEFAULT_SENSOR) -> dict:
    """A forest as the node runs it (``DetectorParams`` defaults): AP and false detections on
    the bags ``scored`` (of :data:`EVAL` and the near-miss bags :data:`NEAR`), and its
    exact-vote APs; ``train``: the names of the bags it was trained on (with ``train_sensor``);
    ``sensor``: the scored bags' sensor."""
    forest = load_forest(model)
    shown = model.relative_to(ROOT) if model.is_relative_to(ROOT) else model
    r = {"forest": str(shown), "n_nodes": forest.n_nodes, "file_bytes": model.stat().st_size,
         "train_seconds": forest.meta["training"]["seconds_total"], "train_frames": forest.meta["training"]["n_frames"],
         "train_samples": forest.meta["training"]["n_samples"], "sensor": sensor,
         "bags": {b: sim_command(b, train_sensor) for b in train},
         "thresholds": dict(forest.meta.get("gesture_thresholds", {})),
         "threshold_rule": forest.meta.get("threshold_curves", {}).get("rule", "")}
    for bag in scored:
        data = read_gesture_bag(bags[bag])
        e = evaluate_gestures(data, forest)
        r[bag] = {"mean_ap": e["mean_ap"], "ap": {g: c["ap"] for g, c in e["per_class"].items()},
                  "found": {g: [c["found_at_node_thresholds"], c["positives"]] for g, c in e["per_class"].items()},
                  "false_detections": e["false_detections"], "fps": e["fps"], "command": sim_command(bag, sensor)}
        if bag in EVAL:
            r[bag]["exact_mean_ap"] = evaluate_gestures(data, forest, EXACT)["mean_ap"]
        fd = e["false_detections"]
        print(f"{model.name} on {bag}: mean AP {e['mean_ap']:.3f}, false detections in {100 * fd['per_frame']:.1f} % "
              f"of the frames", flush=True)
        del data
    return r


def shipped_lines(r: dict, option: str) -> list[str]:
    """A forest's tables (docs/figures/gesture_shipped.md, gesture_near_forest.md)."""
    present = [b for b in EVAL + NEAR if b in r]
    gestures = list(next((r[b]["ap"] for b in present if b in EVAL), GESTURE_CLASSES))
    sensor = r.get("sensor", DEFAULT_SENSOR)
    lines = [f"<!-- written by tools/gesture_table.py {option}; do not edit -->", "", f"Forest: `{r['forest']}`.", "",
             f"Evaluation bags rendered with the `{sensor}` depth sensor (`hmocap sim gestures --sensor`).", "",
             "Training: " + ", ".join(f"`{c}`" for c in r["bags"].values())
             + f" ({r['train_frames']} frames, {r['train_samples']} samples after mining); {r['n_nodes']} nodes, "
               f"{r['file_bytes'] / 1e6:.2f} MB, {r['train_seconds']:.0f} s of training.", "",
             "| bag | " + " | ".join(gestures) + " | mean AP | mean AP, exact vote | frames with a false detection |",
             "|---|" + "---:|" * (len(gestures) + 3)]
    for bag in present:
        e = r[bag]
        cells = ([f"{e['ap'][g]:.2f}" for g in gestures] + [f"**{e['mean_ap']:.3f}**", f"{e['exact_mean_ap']:.3f}"]
                 if bag in EVAL else ["-"] * len(gestures) + ["-", "-"])
        fd = e["false_detections"]
        lines.append(f"| {bag} | " + " | ".join(cells) + f" | {100 * fd['per_frame']:.1f} % ({fd['frames']}/"
                     f"{fd['scored_frames']}) |")
    th = r.get("thresholds") or {}
    lines += ["", "At the node's thresholds (" + (", ".join(f"{g} {th[g]:.3f}" for g in gestures if g in th)
                                                + f": {r.get('threshold_rule', '')}" if th else
                                                "min_score 0.4, min_volume 0.3 for every gesture") + "): "
              "frames of each gesture found / its frames, false events per minute.", "",
              "| bag | " + " | ".join(gestures) + " | recall (all) | false events / min |",
              "|---|" + "---:|" * (len(gestures) + 2)]
    for bag in (b for b in present if b in EVAL):
        e = r[bag]
        found = [e["found"][g] for g in gestures]
        total = sum(f for f, _ in found) / max(sum(n for _, n in found), 1)
        lines.append(f"| {bag} | " + " | ".join(f"{f}/{n}" for f, n in found)
                     + f" | {total:.3f} | {e['false_detections']['events_per_minute']:.2f} |")
    for bag in (b for b in present if b in NEAR):
        e = r[bag]
        lines.append(f"| {bag} | " + " | ".join("-" for _ in gestures)
                     + f" | - | {e['false_detections']['events_per_minute']:.2f} |")
    lines += ["", "Bags: " + "; ".join(f"{b}: `{r[b]['command']}`" for b in present)]
    return lines


def table_lines(results: dict, names: list, ns) -> list[str]:
    """The Markdown tables: AP per gesture and bag, then size and training time per forest."""
    default = results[DEFAULT]
    gestures = list(default["test"]["per_class"])
    lines = ["<!-- written by tools/gesture_table.py; do not edit -->", ""]
    for bag in EVAL:
        first = default[bag]
        lines += [f"**{bag}** (`{sim_command(bag, ns.sensor)}`: {first['scored_frames']} scored frames, "
                  f"{sum(c['positives'] for c in first['per_class'].values())} gestures)", "",
                  "| forest | " + " | ".join(gestures) + " | mean |", "|---|" + "---:|" * (len(gestures) + 1)]
        for n in names:
            e = results[n][bag]
            cells = [f"{e['per_class'][g]['ap']:.2f}" for g in gestures] + [f"**{e['mean_ap']:.3f}**"]
            lines.append(f"| {n}{' (default)' if n == DEFAULT else ''} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["Training: " + ", ".join(f"`{sim_command(b, ns.sensor)}`" for b in TRAIN)
              + f" ({default['train_frames']} frames used, {default['train_samples']} samples after mining); "
              f"{ns.trees} trees, depth <= {ns.depth}, seed {ns.seed}.", "",
              "| forest | nodes | file (MB) | training (s) |", "|---|---:|---:|---:|"]
    for n in names:
        r = results[n]
        lines.append(f"| {n} | {r['n_nodes']} | {r['file_bytes'] / 1e6:.2f} | {r['train_seconds']:.0f} |")
    return lines


def summary(results: dict, sensor: str) -> dict:
    """Every number of the tables (and fps) per variant, and the bags' commands."""
    out = {n: {"n_nodes": r["n_nodes"], "train_seconds": r["train_seconds"],
               **{bag: {"mean_ap": r[bag]["mean_ap"], "ap": {g: c["ap"] for g, c in r[bag]["per_class"].items()},
                        "positives": {g: c["positives"] for g, c in r[bag]["per_class"].items()},
                        "fps": r[bag]["fps"]} for bag in EVAL}}
           for n, r in results.items()}
    out["_bags"] = {b: sim_command(b, sensor) for b in BAGS}
    return out


def main(argv=None) -> int:
    ns = _parser().parse_args(argv)
    work = Path(ns.workdir) / ns.sensor
    work.mkdir(parents=True, exist_ok=True)
    if ns.shipped or ns.near_forest:
        return shipped(ns, work)
    bags = {name: make_bag(work, name, ns.sensor) for name in TRAIN + EVAL}
    variants = [(b, k) for b in (True, False) for k in KAPPAS]
    names = [variant_name(b, k) for b, k in variants]
    todo = [(b, k) for b, k in variants if not ns.only or variant_name(b, k) in ns.only]
    todo.sort(key=lambda v: variant_name(*v) != DEFAULT)  # the default forest first

    training = {}
    results = {}
    for boosted, kappa in todo:
        name = variant_name(boosted, kappa)
        stem = name.replace(", ", "_").replace(" ", "")
        model, scores = work / f"forest_{stem}.npz", work / f"scores_{stem}.json"
        if scores.exists():
            results[name] = json.loads(scores.read_text())
            print(f"{name}: cached", flush=True)
            continue
        if not model.exists():
            train_variant(ns, bags, boosted, kappa, model, training)
        results[name] = score_variant(name, model, bags)
        scores.write_text(json.dumps(results[name]))

    missing = [n for n in names if n not in results]
    if missing:
        print(f"not all variants scored yet ({', '.join(missing)}): no table written")
        return 0
    out = Path(ns.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    default = results[DEFAULT]
    tail = "" if ns.sensor == DEFAULT_SENSOR else f"_{ns.sensor}"
    table, numbers = out / f"gesture_table{tail}.md", out / f"gesture_table{tail}.json"
    pr = out / f"gesture_pr{tail}.png"
    plot_pr(default["test"], pr,
            f"{DEFAULT}, test bag: mean AP {default['test']['mean_ap']:.3f}\n"
            f"correct: class right, within {default['test']['tolerance_px']:g} px at 640x480")
    table.write_text("\n".join(table_lines(results, names, ns)) + "\n")
    numbers.write_text(json.dumps(summary(results, ns.sensor), indent=1) + "\n")
    print(f"wrote {table}, {numbers}, {pr}")
    return 0


def shipped(ns, work: Path) -> int:
    """``--shipped``: score the shipped forest; ``--near-forest``: train (cached) and score the
    near-miss forest, ``--ship`` copies it to the shipped one."""
    if ns.shipped:
        name, option, train, model = "gesture_shipped", "--shipped", SHIPPED_TRAIN, SHIPPED
        scores = work / "scores_in_data.json"
    else:
        name, option, train, model = "gesture_near_forest", "--near-forest", NEAR_TRAIN, work / "forest_near.npz"
        scores = work / "scores_near.json"
    scored = tuple(b for b in EVAL + NEAR if ns.bags is None or b in ns.bags)
    needed = (() if ns.shipped else NEAR_TRAIN + THRESHOLD_BAGS) + scored
    bags = {b: make_bag(work, b, ns.sensor) for b in dict.fromkeys(needed)}
    if ns.bags is not None:
        scores = scores.with_name(scores.stem + "_" + "_".join(scored) + ".json")
    if ns.sensor != DEFAULT_SENSOR:
        name += f"_{ns.sensor}"
    if not model.exists():
        trained = work / "forest_near_untuned.npz"
        if not trained.exists():
            train_variant(ns, bags, True, 0.15, trained, {}, NEAR_TRAIN)
        forest = load_forest(trained)
        curves = gesture_threshold_curves([read_gesture_bag(bags[b]) for b in THRESHOLD_BAGS], forest)
        sources = [f"{b}.mcap: {sim_command(b, ns.sensor)}" for b in THRESHOLD_BAGS]
        chosen = set_gesture_thresholds(forest, curves, ns.max_false_per_minute, sources, ns.min_recall)
        print("thresholds from " + ", ".join(THRESHOLD_BAGS) + ": "
              + ", ".join(f"{g} {t:.3f}" for g, t in chosen.items()), flush=True)
        save_forest(forest, model)
    if scores.exists() and not ns.shipped:
        r = json.loads(scores.read_text())
    else:
        r = score_shipped(model, bags, train, scored, ns.sensor, DEFAULT_SENSOR if ns.shipped else ns.sensor)
        scores.write_text(json.dumps(r))
    out = Path(ns.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{name}.md").write_text("\n".join(shipped_lines(r, option)) + "\n")
    (out / f"{name}.json").write_text(json.dumps(r, indent=1) + "\n")
    print(f"wrote {out / (name + '.md')}, {out / (name + '.json')}")
    if ns.ship and ns.near_forest:
        # the thresholds were chosen at 640x480; the node's defaults serve other cameras too
        forest = load_forest(model)
        forest.meta.pop("gesture_thresholds", None)
        forest.meta.pop("threshold_curves", None)
        save_forest(forest, SHIPPED)
        print(f"shipped {model} -> {SHIPPED} (without per-gesture thresholds)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
