#!/usr/bin/env python3
"""Thesis table 3.2 on simulated depth: offline vs online forests (random negatives, hard mining),
AP per gesture on held-out subjects and rooms; plus an alpha sweep (memory, AP) and beta values.

One command (about 20 minutes on 2 busy cores; ``--quick``: a few minutes on smaller bags)::

    .venv/bin/python tools/online_forest_table.py [--quick]

1. Generates (``hmocap sim gestures``) the training bag ``train1`` and the held-out ``test`` bag
   of ``tools/gesture_table.py`` (640x480; disjoint subjects and seeds, hence disjoint people,
   rooms, clutter and bystanders); ``--quick`` uses a 400-frame training bag of the same
   subjects and a 300-frame test bag of the test subjects.
2. Trains on the same training frames: the offline forest with the code of ``hmocap train
   gestures`` (boosted, one round of hard negative mining), and online forests (alg. 6) with
   the code of ``hmocap train gestures --online`` (5 passes; ``--quick``: 2): random negatives
   and hard mining at the default alpha = 300, beta = 0; then hard mining at other alpha and
   beta values. All 15 trees, depth <= 20, seed 0.
3. Scores each on the test bag with the code of ``hmocap eval gestures`` (correct class within
   10 px at 640x480, all-point interpolated AP).
4. Prints the Markdown tables and writes every number to ``out/online_forest_table.json``
   (``--quick``: ``out/online_forest_table_quick.json``).

Bags, forests and scores are cached in ``--workdir``, so an interrupted run resumes.
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
sys.path.insert(0, str(ROOT / "tools"))

import gesture_table as gt

from hmocap_ros.eval.gesture_eval import evaluate_gestures, read_gesture_bag
from hmocap_ros.eval.gesture_training_bags import read_training_bags
from hmocap_ros.gestures.forest import train_forest_on_frames
from hmocap_ros.gestures.forest_file import load_forest, save_forest
from hmocap_ros.gestures.online_forest import OnlineForest, train_online_on_frames
from hmocap_ros.gestures.params import OnlineParams, OnlineTrainParams, train_params_for_focal

QUICK_BAGS = {
    "train_quick": dict(seed=1000, subjects=8, subject_offset=1000, frames=400, hold=(2, 4)),
    "test_quick": dict(seed=2000, subjects=8, subject_offset=2000, frames=300),
}
#: name -> online settings (None = the offline trainer). The first three rows are table 3.2.
VARIANTS = {
    "offline (boosted, mining)": None,
    "online, random negatives": dict(negatives="random"),
    "online, hard mining": dict(negatives="hard"),
    "online, hard mining, alpha 100": dict(negatives="hard", alpha=100.0),
    "online, hard mining, alpha 1000": dict(negatives="hard", alpha=1000.0),
    "online, hard mining, beta 0.05": dict(negatives="hard", beta=0.05),
}


def bags_for(ns) -> tuple[str, str]:
    return ("train_quick", "test_quick") if ns.quick else ("train1", "test")


def make_bag(work: Path, name: str) -> Path:
    if name in QUICK_BAGS:
        gt.BAGS.setdefault(name, QUICK_BAGS[name])
    return gt.make_bag(work, name)


def train_variant(name: str, ns, train_bag: Path, model: Path, cache: dict) -> None:
    """Train one variant on the training bag and save it to ``model`` (frames read once, shared)."""
    if "data" not in cache:
        cache["data"], _ = read_training_bags([train_bag])
    data = cache["data"]
    rng = np.random.default_rng(ns.seed)
    t0 = time.perf_counter()
    settings = VARIANTS[name]
    if settings is None:
        params = train_params_for_focal(data.focal_px, n_trees=ns.trees, max_depth=ns.depth)
        forest = train_forest_on_frames(data.depth, data.labels, params, rng, class_names=data.class_names)
        forest.meta["training"].update({"focal_px": data.focal_px})
        memory = None
    else:
        params = OnlineTrainParams(online=OnlineParams(n_trees=ns.trees, max_depth=ns.depth, **settings))
        params = params.for_focal(data.focal_px)
        online = OnlineForest(data.class_names, params.features, params.online, rng,
                              {"training": {"method": "online", "focal_px": data.focal_px,
                                            "image_size": [data.width, data.height]}})
        train_online_on_frames(data.depth, data.labels, params.patches, online, rng, ns.passes)
        memory = online.memory_bytes()
        forest = online.to_forest()
    seconds = time.perf_counter() - t0
    forest.meta["table"] = {"seconds": seconds, "memory_bytes": memory}
    save_forest(forest, model)
    print(f"{name}: trained in {seconds:.0f} s ({forest.n_nodes} nodes)", flush=True)


def score_variant(name: str, model: Path, test_bag: Path) -> dict:
    forest = load_forest(model)
    e = evaluate_gestures(read_gesture_bag(test_bag), forest)
    passes = forest.meta.get("online", {}).get("passes", [])
    r = {"n_nodes": forest.n_nodes, "file_bytes": model.stat().st_size, "seconds": forest.meta["table"]["seconds"],
         "memory_bytes": forest.meta["table"]["memory_bytes"], "mean_ap": e["mean_ap"],
         "ap": {g: c["ap"] for g, c in e["per_class"].items()},
         "positives": {g: c["positives"] for g, c in e["per_class"].items()},
         "samples": sum(p["samples"] for p in passes) or forest.meta["training"].get("bag_samples_total"),
         "frame_negatives": sum(p["frame_negatives"] for p in passes), "scored_frames": e["scored_frames"]}
    print(f"{name}: mean AP {r['mean_ap']:.3f} ({' '.join(f'{g} {a:.2f}' for g, a in r['ap'].items())})", flush=True)
    return r


def tables(results: dict, ns) -> str:
    train, test = bags_for(ns)
    gestures = list(next(iter(results.values()))["ap"])
    first = next(iter(results.values()))
    sim = {b: gt.sim_command(b) for b in (train, test)}
    lines = [f"Training `{sim[train]}`; held-out `{sim[test]}` ({first['scored_frames']} scored frames, "
             f"{sum(first['positives'].values())} gestures). 15 trees, depth <= 20, seed {ns.seed}; "
             f"online: {ns.passes} passes, {OnlineParams().n_candidates} candidate tests per leaf.", "",
             "| forest | " + " | ".join(gestures) + " | mean |", "|---|" + "---:|" * (len(gestures) + 1)]
    for name in list(VARIANTS)[:3]:
        r = results[name]
        lines.append(f"| {name} | " + " | ".join(f"{r['ap'][g]:.2f}" for g in gestures)
                     + f" | **{r['mean_ap']:.3f}** |")
    lines += ["", "| forest | nodes | memory: nodes / open leaves (MB) | file (MB) | samples | negatives of "
                  "background frames | training (s) | mean AP |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in results.items():
        m = r["memory_bytes"]
        mem = f"{m['nodes'] / 1e6:.1f} / {m['open_leaves'] / 1e6:.0f}" if m else "-"
        lines.append(f"| {name} | {r['n_nodes']} | {mem} | {r['file_bytes'] / 1e6:.1f} | {r['samples']} | "
                     f"{r['frame_negatives'] if m else '-'} | {r['seconds']:.0f} | {r['mean_ap']:.3f} |")
    lines += ["", "Samples: online, the patches given to the forest over all passes (each tree takes each "
                  "k ~ Poisson(1) times); offline, the bag samples of the final round's trees. Memory: the "
                  "nodes, and the open leaves' candidate tests and statistics (in the file too, to keep growing)."]
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="smaller bags and 2 passes: a few minutes")
    p.add_argument("--workdir", default="/tmp/hmocap_online_table", help="bags, forests and scores (cache)")
    p.add_argument("--passes", type=int, default=None, help="online passes (default 5; --quick 2)")
    p.add_argument("--trees", type=int, default=15)
    p.add_argument("--depth", type=int, default=20)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", default=None, help="results JSON (default out/online_forest_table[_quick].json)")
    ns = p.parse_args(argv)
    ns.passes = ns.passes or (2 if ns.quick else 5)
    work = Path(ns.workdir)
    work.mkdir(parents=True, exist_ok=True)
    train, test = bags_for(ns)
    bags = {name: make_bag(work, name) for name in (train, test)}
    tag = f"{train}_p{ns.passes}_t{ns.trees}_d{ns.depth}_s{ns.seed}"
    results, cache = {}, {}
    for name in VARIANTS:
        stem = name.replace(", ", "_").replace(" ", "").replace("(", "").replace(")", "")
        model, scores = work / f"online_{tag}_{stem}.npz", work / f"online_{tag}_{stem}.json"
        if scores.exists():
            results[name] = json.loads(scores.read_text())
            continue
        if not model.exists():
            train_variant(name, ns, bags[train], model, cache)
        results[name] = score_variant(name, model, bags[test])
        scores.write_text(json.dumps(results[name]))
    text = tables(results, ns)
    print(text)
    out = Path(ns.json or ROOT / "out" / f"online_forest_table{'_quick' if ns.quick else ''}.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"variants": results, "bags": {b: gt.sim_command(b) for b in (train, test)},
                               "passes": ns.passes, "seed": ns.seed, "markdown": text}, indent=1) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
