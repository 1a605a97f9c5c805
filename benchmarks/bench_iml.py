#!/usr/bin/env python
"""Thesis table 3.3 reproduced: gestures taught interactively (IML, sec. 3.4) by the simulated
user, against offline training (sec. 3.2) on exactly the frames the sessions recorded; a new
gesture taught to the shipped forest; the taught thresholds on negative-only sequences.

    hmocap bench iml --json OUT [--quick] [--gestures tee silence cross] [--work DIR]

The protocol of thesis sec. 3.4.2, per gesture of ``--gestures``:

1. **Sessions.** The simulated user (:class:`~hmocap_sim.gesture_teacher.GestureTeacher`:
   one subject in one room, as the thesis' single user) and the trainer
   (:class:`~hmocap_ros.gestures.trainer.Trainer`, a new forest, ``record=True``) in a closed
   loop in process: ``--sessions`` consecutive sessions of ``--session-min`` simulated minutes
   (rounds of do_gesture 3 s, update_positive 6 s, release 2 s, do_negatives 9 s; no testing
   phase), the forest saved after each session and continued by the next. The camera is
   640x480 (the thesis' Kinect) at ``--fps`` 3.5 frames/s: the thesis' sessions recorded
   500-700 frames in about 3 minutes (fig. 3.12), so 3.5 frames/s gives its 630 frames.
2. **Scores** after session k, AP (``hmocap eval gestures``' criterion, correct class within
   10 px at 640x480) on (a) held-out sequences of the *same* simulated person in the same room
   (``same_subject``: other takes at other spots, with the other gestures, everyday motions and
   near misses; another noise stream) and (b) other people in other rooms (``other_people``:
   the ``test`` bag of ``tools/gesture_table.py``). Labels are matched to each forest's classes
   by name (gestures a forest does not know are background).
3. **Offline** on the same frames: the recorded frames of sessions 1..k (update_positive
   frames annotated at the box centre, do_negatives frames as background), written as bags
   (:func:`~hmocap_sim.gesture_teacher.write_recording_bag`), trained with the code of
   ``hmocap train gestures`` (its defaults: 15 trees, depth 20, boosted, one mining round) and
   scored on the same bags. Times: IML = the session's simulated time (recording, annotation
   and training at once; the trainer's CPU time beside it); offline = the same recording
   time + the training's wall time on this machine.
4. **Thresholds** (sec. 3.4.1): the taught threshold of each IML forest is applied as the node
   applies it; false detection events per minute on a negative-only sequence of the same
   person in the same room (``negatives``: everyday motions and near misses of every gesture,
   no gesture) and the fraction of the same-subject frames of the gesture found at it; after
   the last session also for ``th = rho th+ + (1 - rho) th-`` at each rho of ``RHOS`` (the
   forest keeps th+ and th-).
5. **A new gesture** (``--new-gesture``, default ``thumbs_up``, which the shipped forest has
   never seen): taught to the shipped forest (continued online,
   :meth:`~hmocap_ros.gestures.online_forest.OnlineForest.from_offline`) for ``--new-sessions``
   sessions; its AP on the same-subject bag and the six known gestures' AP on the
   ``other_people`` bag against the shipped forest's.

JSON (``--json``): ``{"gestures": {g: {"sessions": [...]}}, "sessions": [{"minutes",
"iml_same_subject", "offline_same_subject", "iml_other_people", "offline_other_people",
"train_s": {...}}, ...] (means over the gestures), "thesis", "thresholds", "new_gesture",
"bags", "command"}``. Bags, forests and finished sessions are cached in ``--work`` (a run that
stops resumes). ``--quick`` runs everything small (1-round sessions, tiny bags and forests):
a check that the bench runs, not a measurement.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

from iml_table import relabelled, run_session

from hmocap_ros.commands import train_gestures
from hmocap_ros.eval.gesture_eval import DEFAULT_MODEL, GestureBagError, read_gesture_bag, run_detector, score_run
from hmocap_ros.gestures.forest_file import load_forest
from hmocap_ros.gestures.trainer import SessionOnlineParams, Trainer, TrainerParams, blend_threshold
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader, BagReadError
from hmocap_sim import gesture_set as gs
from hmocap_sim.gesture_dataset import generate
from hmocap_sim.gesture_teacher import GestureTeacher, write_recording_bag

#: Thesis table 3.3 (mean of tee, silence, cross; same subject in training and test).
THESIS = {"minutes": [3, 6, 9], "iml": [0.54, 0.78, 0.82], "offline": [0.34, 0.64, 0.87],
          "offline_train_s": [111, 256, 479]}
ROUND = dict(do_gesture_s=3.0, update_positive_s=6.0, release_s=2.0, do_negatives_s=9.0)
QUICK_ROUND = dict(do_gesture_s=1.0, update_positive_s=2.0, release_s=1.0, do_negatives_s=3.0)
RHOS = (0.5, 0.6, 0.7, 0.8, 0.9)


class Scorer:
    """The detector run once per forest and bag; scores at the taught or any other thresholds."""

    def __init__(self, bags: dict):
        self.bags = bags

    def run(self, forest, bag: str):
        data = relabelled(self.bags[bag], forest.class_names)
        return data, run_detector(data, forest)

    def score(self, forest, bag: str, thresholds: dict | None = None, run=None) -> dict:
        data, r = run if run is not None else self.run(forest, bag)
        return score_run(data, forest, r, thresholds=thresholds)


def ap(result: dict, gesture: str) -> float:
    return float(result["per_class"][gesture]["ap"])


def found(result: dict, gesture: str) -> float:
    c = result["per_class"][gesture]
    return c["found_at_node_thresholds"] / c["positives"] if c["positives"] else 0.0


def train_offline(bags: list, out: Path, ns) -> float:
    """``hmocap train gestures BAGS --out OUT`` (its code path, in process); returns wall seconds."""
    parser = argparse.ArgumentParser()
    train_gestures.add_arguments(parser)
    args = ([str(b) for b in bags] + ["--out", str(out), "--force", "--quiet", "--seed", str(ns.seed)]
            + (["--trees", "3", "--depth", "8", "--samples-per-class", "2000"] if ns.quick else []))
    t0 = time.perf_counter()
    if train_gestures.main_from_args(parser.parse_args(args)) != 0:
        raise RuntimeError(f"offline training on {bags} failed")
    return time.perf_counter() - t0


def trainer_params(ns) -> TrainerParams:
    rounds = max(1, int(round(ns.session_min * 60.0 / sum((QUICK_ROUND if ns.quick else ROUND).values()))))
    online = SessionOnlineParams(n_trees=5, max_depth=10, n_tests=16) if ns.quick else SessionOnlineParams()
    return TrainerParams(rounds=rounds, testing_s=0.0, **(QUICK_ROUND if ns.quick else ROUND), online=online)


def run_sessions(trainer: Trainer, teacher: GestureTeacher, g: str, k: int, extend: bool) -> tuple[float, int, int]:
    """One session of ``g`` in the closed loop; (trainer CPU seconds, frames recorded, positive frames)."""
    cpu, status = run_session(trainer, teacher, g, extend)
    if not trainer.taught:
        raise RuntimeError(f"session {k} of '{g}' taught nothing: {status.instruction}")
    return cpu, len(trainer.recording), sum(bool(f.gesture) for f in trainer.recording)


def threshold_row(scorer: Scorer, forest, g: str, runs: dict, th: float) -> dict:
    neg = scorer.score(forest, "negatives", {g: th}, runs["negatives"])["false_detections"]
    same = scorer.score(forest, "same_subject", {g: th}, runs["same_subject"])
    return {"threshold": th, "false_per_minute": neg["per_class"][g]["events_per_minute"],
            "false_frames": neg["per_class"][g]["frames"], "negative_minutes": neg["minutes"],
            "found_same_subject": found(same, g)}


def gesture_sessions(g: str, ns, scorer: Scorer, work: Path, log) -> list:
    """The sessions of one gesture (module docstring, 1-4); one dict per session, counts and
    times summed over the sessions so far."""
    cache = work / f"{g}.json"
    if cache.exists():
        return json.loads(cache.read_text())
    teacher = GestureTeacher(seed=ns.seed, width=ns.width, height=ns.height, fps=ns.fps)
    p = trainer_params(ns)
    trainer = Trainer(None, p, np.random.default_rng(ns.seed), focal_px=teacher.focal_px, record=True)
    bags, rows = [], []
    for k in range(1, ns.sessions + 1):
        cpu, n_frames, n_pos = run_sessions(trainer, teacher, g, k, extend=k > 1)
        model = trainer.save(work / f"{g}_iml_{k}.forest.npz")
        bag = work / f"{g}_session_{k}.mcap"
        if bag.exists():
            shutil.rmtree(bag) if bag.is_dir() else bag.unlink()
        write_recording_bag(bag, trainer.recording, teacher.camera)
        bags.append(bag)
        iml = load_forest(model)
        runs = {b: scorer.run(iml, b) for b in ("same_subject", "other_people", "negatives")}
        before = rows[-1] if rows else {"trainer_cpu_s": 0.0, "recorded_frames": 0, "positive_frames": 0}
        th = iml.meta["gesture_thresholds"][g]
        row = {"gesture": g, "session": k, "minutes": k * p.session_s() / 60.0,
               "recorded_frames": before["recorded_frames"] + n_frames,
               "positive_frames": before["positive_frames"] + n_pos,
               "trainer_cpu_s": before["trainer_cpu_s"] + cpu, "iml_nodes": trainer.online.n_nodes,
               "iml_same_subject": ap(scorer.score(iml, "same_subject", run=runs["same_subject"]), g),
               "iml_other_people": ap(scorer.score(iml, "other_people", run=runs["other_people"]), g),
               "threshold_parts": iml.meta["gesture_threshold_parts"][g],
               "taught_threshold": threshold_row(scorer, iml, g, runs, th)}
        if k == ns.sessions:
            pos, neg = row["threshold_parts"]
            row["rho"] = {f"{rho:g}": threshold_row(scorer, iml, g, runs, blend_threshold(pos, neg, rho))
                          for rho in RHOS}
        off = work / f"{g}_offline_{k}.forest.npz"
        row["offline_train_s"] = train_offline(bags, off, ns)
        offline = load_forest(off)
        row["offline_same_subject"] = ap(scorer.score(offline, "same_subject"), g)
        row["offline_other_people"] = ap(scorer.score(offline, "other_people"), g)
        rows.append(row)
        log(json.dumps({a: (round(b, 3) if isinstance(b, float) else b) for a, b in row.items()
                        if not isinstance(b, dict)}))
    cache.write_text(json.dumps(rows))
    return rows


def new_gesture(ns, scorer: Scorer, work: Path, log) -> dict:
    """``--new-gesture`` taught to the shipped forest (module docstring, 5)."""
    g = ns.new_gesture
    cache = work / f"new_{g}.json"
    if cache.exists():
        return json.loads(cache.read_text())
    shipped = load_forest(ns.model)
    if g in shipped.class_names:
        raise ValueError(f"the forest {ns.model} already knows '{g}'")
    teacher = GestureTeacher(seed=ns.seed, width=ns.width, height=ns.height, fps=ns.fps)
    p = trainer_params(ns)
    known = shipped.class_names[1:]
    base = scorer.score(shipped, "other_people")
    out = {"gesture": g, "forest": str(ns.model), "known_other_people_before": {c: ap(base, c) for c in known},
           "sessions": []}
    trainer = Trainer(shipped, p, np.random.default_rng(ns.seed), focal_px=teacher.focal_px)
    for k in range(1, ns.new_sessions + 1):
        cpu = run_sessions(trainer, teacher, g, k, extend=k > 1)[0]  # frames are counted with record=True only
        forest = load_forest(trainer.save(work / f"new_{g}_{k}.forest.npz"))
        same = scorer.score(forest, "same_subject")
        other = scorer.score(forest, "other_people")
        neg = scorer.score(forest, "negatives")["false_detections"]
        row = {"session": k, "minutes": k * p.session_s() / 60.0, "trainer_cpu_s": cpu,
               "nodes": trainer.online.n_nodes, "open_leaves": trainer.online.n_open_leaves,
               "ap_same_subject": ap(same, g), "found_same_subject": found(same, g),
               "taught_threshold": forest.meta["gesture_thresholds"][g],
               "false_per_minute": neg["per_class"][g]["events_per_minute"],
               "known_other_people": {c: ap(other, c) for c in known},
               "known_loss": {c: ap(base, c) - ap(other, c) for c in known}}
        out["sessions"].append(row)
        log(json.dumps({"new_gesture": g, "session": k, "ap_same_subject": round(row["ap_same_subject"], 3),
                        "max_known_loss": round(max(row["known_loss"].values()), 3)}))
    cache.write_text(json.dumps(out))
    return out


def make_bags(ns, work: Path) -> dict:
    """The scoring bags (module docstring): generated into ``--work`` unless given."""
    n_same, n_neg = (40, 30) if ns.quick else (ns.same_frames, ns.negative_frames)
    specs = {
        "same_subject": dict(seed=ns.seed + 500, subjects=1, subject_offset=0, frames=n_same, gestures=gs.ALL_GESTURES,
                             negatives=3, near_misses=2, near_of=gs.ALL_GESTURES, room=ns.seed),
        "negatives": dict(seed=ns.seed + 501, subjects=1, subject_offset=0, frames=n_neg, gestures=(),
                          negatives=3, near_misses=3, near_of=gs.ALL_GESTURES, room=ns.seed),
    }
    paths = {"same_subject": ns.same_bag, "negatives": ns.negative_bag, "other_people": ns.other_bag}
    for name, kw in specs.items():
        if paths[name] is None:
            paths[name] = work / f"{name}.mcap"
            if not paths[name].exists():
                generate(paths[name], width=ns.width, height=ns.height, contact=False, progress=False, **kw)
    if paths["other_people"] is None:
        if ns.quick:
            paths["other_people"] = paths["same_subject"]
        else:
            import gesture_table

            paths["other_people"] = gesture_table.make_bag(work, "test")
    return {k: Path(v) for k, v in paths.items()}


def check_labelled(path: Path) -> str:
    """'' when ``path`` is a bag with gesture labels, else the reason in one line."""
    try:
        with BagReader(path) as reader:
            if topics.GT_GESTURES not in reader.topics():
                return f"{path} has no gesture labels ({topics.GT_GESTURES}): the bench scores against them"
    except (BagReadError, FileNotFoundError, OSError) as err:
        return f"cannot read {path}: {err}"
    return ""


def summary(results: dict, ns) -> list:
    """Per session, the means over the gestures (the layout of the issue's JSON)."""
    out = []
    for k in range(ns.sessions):
        rows = [results[g][k] for g in ns.gestures]
        def mean(key, rows=rows):
            return float(np.mean([r[key] for r in rows]))

        out.append({"minutes": rows[0]["minutes"], "iml_same_subject": mean("iml_same_subject"),
                    "offline_same_subject": mean("offline_same_subject"),
                    "iml_other_people": mean("iml_other_people"), "offline_other_people": mean("offline_other_people"),
                    "train_s": {"recording": rows[0]["minutes"] * 60.0, "iml_trainer_cpu": mean("trainer_cpu_s"),
                                "offline_training": mean("offline_train_s")},
                    "taught_false_per_minute": mean("taught_false_per_minute"),
                    "taught_found_same_subject": mean("taught_found_same_subject")})
    return out


def print_tables(doc: dict, log) -> None:
    log("| after | IML same subject | offline same subject | IML other people | offline other people | "
        "thesis IML | thesis offline |")
    log("|---|---:|---:|---:|---:|---:|---:|")
    for k, s in enumerate(doc["sessions"]):
        t = doc["thesis"]
        th = (f"{t['iml'][k]:.2f} | {t['offline'][k]:.2f}" if k < len(t["iml"]) else "- | -")
        log(f"| {s['minutes']:.3g} min | {s['iml_same_subject']:.2f} | {s['offline_same_subject']:.2f} | "
            f"{s['iml_other_people']:.2f} | {s['offline_other_people']:.2f} | {th} |")


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", required=True, help="write the results here")
    p.add_argument("--gestures", nargs="+", default=["tee", "silence", "cross"])
    p.add_argument("--sessions", type=int, default=3)
    p.add_argument("--session-min", type=float, default=3.0, help="simulated minutes per session")
    p.add_argument("--fps", type=float, default=3.5, help="frame rate of the simulated camera")
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--seed", type=int, default=0, help="the simulated user and room (hmocap sim teacher --seed)")
    p.add_argument("--new-gesture", default="thumbs_up", choices=gs.NEW_GESTURES)
    p.add_argument("--new-sessions", type=int, default=2)
    p.add_argument("--model", default=str(DEFAULT_MODEL), help="the forest the new gesture is taught to")
    p.add_argument("--same-frames", type=int, default=900)
    p.add_argument("--negative-frames", type=int, default=1200)
    p.add_argument("--same-bag", help="held-out bag of the same person (default: generated)")
    p.add_argument("--negative-bag", help="negative-only bag of the same person (default: generated)")
    p.add_argument("--other-bag", help="bag of other people (default: tools/gesture_table.py's test bag)")
    p.add_argument("--work", default=str(ROOT / "out" / "bench_iml"), help="bags, forests and cached results")
    p.add_argument("--quick", action="store_true", help="everything small: a check that the bench runs")
    return p


def main(argv=None) -> int:
    ns = parser().parse_args(argv)
    if ns.quick:
        ns.gestures, ns.sessions, ns.new_sessions, ns.fps = ns.gestures[:1], 2, 1, 1.5
        ns.session_min = sum(QUICK_ROUND.values()) / 60.0
    unknown = [g for g in ns.gestures if g not in gs.ALL_GESTURES]
    if unknown or ns.sessions < 1 or ns.new_sessions < 0 or not ns.fps > 0:
        print(f"error: unknown gesture(s) {unknown} or sessions/fps out of range", file=sys.stderr)
        return 2
    for given in (ns.same_bag, ns.negative_bag, ns.other_bag):
        why = check_labelled(Path(given)) if given else ""
        if why:
            print(f"error: {why}", file=sys.stderr)
            return 2
    work = Path(ns.work)
    work.mkdir(parents=True, exist_ok=True)

    def log(line: str) -> None:
        print(line, flush=True)

    t0 = time.perf_counter()
    paths = make_bags(ns, work)
    try:
        scorer = Scorer({name: read_gesture_bag(path) for name, path in paths.items()})
    except GestureBagError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    results = {g: gesture_sessions(g, ns, scorer, work, log) for g in ns.gestures}
    for rows in results.values():
        for r in rows:
            r["taught_false_per_minute"] = r["taught_threshold"]["false_per_minute"]
            r["taught_found_same_subject"] = r["taught_threshold"]["found_same_subject"]
    doc = {"command": " ".join(["hmocap bench iml"] + (sys.argv[1:] if argv is None else list(argv))),
           "protocol": {"fps": ns.fps, "size": [ns.width, ns.height], "session_min": ns.session_min,
                        "trainer": dataclasses.asdict(trainer_params(ns)), "seed": ns.seed},
           "bags": {k: str(v) for k, v in paths.items()},
           "gestures": {g: {"sessions": rows} for g, rows in results.items()},
           "sessions": summary(results, ns), "thesis": THESIS,
           "thresholds": {g: results[g][-1]["rho"] for g in ns.gestures}}
    if ns.new_sessions:
        doc["new_gesture"] = new_gesture(ns, scorer, work, log)
    doc["wall_s"] = time.perf_counter() - t0
    print_tables(doc, log)
    Path(ns.json).parent.mkdir(parents=True, exist_ok=True)
    Path(ns.json).write_text(json.dumps(doc, indent=1) + "\n")
    log(f"wrote {ns.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
