#!/usr/bin/env python
"""Thesis table 3.3 in shape: gestures taught interactively (IML) by the simulated user against
offline training on exactly the frames the sessions recorded.

Per gesture of ``--gestures``, the protocol of thesis sec. 3.4.2 with sessions of one simulated
minute:

1. The simulated user (:class:`~hmocap_sim.gesture_teacher.GestureTeacher`: one subject in
   one room, as the thesis' single user) and the trainer
   (:class:`~hmocap_ros.gestures.trainer.Trainer`, a new forest per gesture, ``record=True``) run
   in a closed loop in process (no DDS) for ``--minutes`` consecutive sessions of ``--session-s``
   seconds (rounds of do_gesture 3 s, update_positive 6 s, release 2 s, do_negatives 9 s; no
   testing phase). The forest is saved after each session and the next one continues it.
2. After session k the forest is scored on the held-out bag, and each session's recorded
   frames (update_positive frames annotated at the box centre, do_negatives frames as
   background) are written as a bag (:func:`~hmocap_sim.gesture_teacher.write_recording_bag`);
   the offline forest of k minutes is trained on sessions 1..k with the code of ``hmocap train
   gestures`` (its defaults: 15 trees, depth 20, boosted, one round of hard negative mining)
   and scored on the same bag.
3. Time: IML = the simulated session time (recording, annotation and training happen at
   once; the trainer's process time per session is given beside it); offline = the same
   recording time + the training's wall time on this machine.

The held-out bag is ``tools/gesture_table.py``'s ``test`` bag (640x480, seed 2000, subjects
2000-2007: other people and rooms than the simulated user's), generated into ``--work`` if it is
not there; its labels are renamed to each forest's classes by name (gestures a forest does not
know are background). AP: ``hmocap eval gestures``' criterion (correct class within 10 px at
640x480). The shipped forest knows every gesture the simulator has (``GESTURE_CLASSES``), so no
gesture is new to it; its AP on the bag is given for reference.

    .venv/bin/python tools/iml_table.py --gestures tee silence cross --minutes 3

Prints the Markdown table and writes every number to ``--out``.
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

import gesture_table as gt

from hmocap_ros.commands import train_gestures
from hmocap_ros.eval.gesture_eval import evaluate_gestures, read_gesture_bag
from hmocap_ros.gestures.forest_file import load_forest
from hmocap_ros.gestures.trainer import SessionOnlineParams, Trainer, TrainerParams
from hmocap_sim.gesture_teacher import GestureTeacher, write_recording_bag

OFFLINE_MODEL = ROOT / "hmocap_ros" / "data" / "gesture_forest.npz"
ROUND = dict(do_gesture_s=3.0, update_positive_s=6.0, release_s=2.0, do_negatives_s=9.0)


def relabelled(data, class_names: tuple):
    """``data`` with its labels renumbered to ``class_names`` by name (others: background)."""
    index = {n: i for i, n in enumerate(class_names)}
    labels = []
    for lab in data.labels:
        name = data.class_names[lab[0]] if lab is not None else ""
        labels.append((index[name], lab[1], lab[2]) if lab is not None and name in index else None)
    return dataclasses.replace(data, labels=labels)


def ap_of(data, forest, gesture: str) -> float:
    e = evaluate_gestures(relabelled(data, forest.class_names), forest)
    return float(e["per_class"][gesture]["ap"])


def train_offline(bags: list, out: Path, ns) -> float:
    """``hmocap train gestures BAGS --out OUT`` (its code path, in process); returns wall seconds."""
    parser = argparse.ArgumentParser()
    train_gestures.add_arguments(parser)
    args = parser.parse_args([str(b) for b in bags] + ["--out", str(out), "--force", "--quiet",
                                                        "--trees", str(ns.trees), "--depth", str(ns.depth),
                                                        "--seed", str(ns.seed)])
    t0 = time.perf_counter()
    if train_gestures.main_from_args(args) != 0:
        raise RuntimeError(f"offline training on {bags} failed")
    return time.perf_counter() - t0


def run_session(trainer: Trainer, teacher: GestureTeacher, g: str, extend: bool):
    """One teaching session of ``g``, the simulated user in the closed loop with the trainer (a
    fresh recording); (trainer CPU seconds, the last status)."""
    trainer.recording.clear()
    trainer.start(g, teacher.next_stamp, extend=extend)
    status = trainer.status(teacher.next_stamp, teacher.camera.width, teacher.camera.height)
    cpu = 0.0
    while trainer.state != "done":
        depth, stamp = teacher.next_frame(status)
        t0 = time.process_time()
        status = trainer.on_frame(depth, stamp)
        cpu += time.process_time() - t0
    return cpu, status


def run_gesture(g: str, ns, data, work: Path) -> list:
    """The sessions of one gesture (module docstring); one dict per session, its counts and times
    summed over the sessions so far."""
    teacher = GestureTeacher(seed=ns.seed, width=ns.width, height=ns.height, fps=ns.fps)
    rounds = max(1, int(round(ns.session_s / sum(ROUND.values()))))
    p = TrainerParams(rounds=rounds, testing_s=0.0, **ROUND,
                      online=SessionOnlineParams(n_trees=ns.trees, max_depth=ns.depth,
                                                 alpha=SessionOnlineParams().alpha if ns.alpha is None else ns.alpha))
    trainer = Trainer(None, p, np.random.default_rng(ns.seed), focal_px=teacher.focal_px, record=True)
    bags, rows = [], []
    for k in range(1, ns.minutes + 1):
        cpu, _ = run_session(trainer, teacher, g, extend=k > 1)
        model = trainer.save(work / f"{g}_iml_{k}.forest.npz")
        bag = work / f"{g}_session_{k}.mcap"
        if bag.exists():
            shutil.rmtree(bag) if bag.is_dir() else bag.unlink()
        n_frames = write_recording_bag(bag, trainer.recording, teacher.camera)
        n_pos = sum(bool(f.gesture) for f in trainer.recording)
        bags.append(bag)
        before = rows[-1] if rows else {"trainer_cpu_s": 0.0, "recorded_frames": 0, "positive_frames": 0}
        row = {"gesture": g, "minutes": k, "simulated_s": k * p.session_s(),
               "trainer_cpu_s": before["trainer_cpu_s"] + cpu, "recorded_frames": before["recorded_frames"] + n_frames,
               "positive_frames": before["positive_frames"] + n_pos, "iml_nodes": trainer.online.n_nodes,
               "threshold": trainer.thresholds.get(g), "ap_iml": ap_of(data, load_forest(model), g)}
        if not ns.no_offline:
            off = work / f"{g}_offline_{k}.forest.npz"
            row["offline_train_s"] = train_offline(bags, off, ns)
            row["ap_offline"] = ap_of(data, load_forest(off), g)
        rows.append(row)
        print(json.dumps({a: (round(b, 3) if isinstance(b, float) else b) for a, b in row.items()}), flush=True)
    return rows


def mmss(seconds: float) -> str:
    s = int(round(seconds))
    return f"{s // 60}:{s % 60:02d}"


def table(rows: list, shipped: dict) -> list[str]:
    lines = ["| gesture | session | frames recorded (positive) | AP IML | AP offline | AP shipped forest | "
             "IML time (trainer CPU) | offline time: recording + training |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        off = r.get("ap_offline")
        lines.append(
            f"| {r['gesture']} | {r['simulated_s'] / 60:g} min | {r['recorded_frames']} ({r['positive_frames']}) | "
            f"{r['ap_iml']:.2f} | {'-' if off is None else f'{off:.2f}'} | "
            f"{shipped.get(r['gesture'], float('nan')):.2f} | "
            f"{mmss(r['simulated_s'])} ({r['trainer_cpu_s']:.0f} s) | "
            + ("-" if off is None else f"{mmss(r['simulated_s'])} + {mmss(r['offline_train_s'])} = "
                                       f"{mmss(r['simulated_s'] + r['offline_train_s'])}") + " |")
    for k in sorted({r["minutes"] for r in rows}):
        sel = [r for r in rows if r["minutes"] == k]
        off = [r["ap_offline"] for r in sel if "ap_offline" in r]
        lines.append(f"| mean | {sel[0]['simulated_s'] / 60:g} min | | {np.mean([r['ap_iml'] for r in sel]):.2f} | "
                     f"{np.mean(off) if off else float('nan'):.2f} | | | |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gestures", nargs="+", default=["tee", "silence", "cross"])
    ap.add_argument("--minutes", type=int, default=3, help="consecutive sessions per gesture, scored after each")
    ap.add_argument("--session-s", type=float, default=60.0, help="simulated seconds per session (rounds of 20 s)")
    ap.add_argument("--fps", type=float, default=10.0, help="frame rate of the simulated camera")
    ap.add_argument("--trees", type=int, default=15)
    ap.add_argument("--depth", type=int, default=20)
    ap.add_argument("--alpha", type=float, default=None,
                    help=f"samples a leaf sees before it splits (default {SessionOnlineParams().alpha:g})")
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=240)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--test-bag", default="test", choices=sorted(gt.BAGS),
                    help="held-out bag of tools/gesture_table.py (val: for choices; test: for the table)")
    ap.add_argument("--no-offline", action="store_true", help="IML only")
    ap.add_argument("--work", default=str(ROOT / "out" / "iml_table"), help="folder for the bags and forests")
    ap.add_argument("--out", default=str(ROOT / "out" / "iml_table.json"))
    ns = ap.parse_args(argv)
    work = Path(ns.work)
    work.mkdir(parents=True, exist_ok=True)
    data = read_gesture_bag(gt.make_bag(work, ns.test_bag))
    shipped_eval = evaluate_gestures(data, load_forest(OFFLINE_MODEL))
    shipped = {g: c["ap"] for g, c in shipped_eval["per_class"].items()}
    rows = []
    for g in ns.gestures:
        rows += run_gesture(g, ns, data, work)
    lines = table(rows, shipped)
    print("\n".join(lines))
    Path(ns.out).parent.mkdir(parents=True, exist_ok=True)
    Path(ns.out).write_text(json.dumps({"command": " ".join(["tools/iml_table.py"] + sys.argv[1:]), "rows": rows,
                                        "shipped_forest": shipped, "test_bag": gt.sim_command(ns.test_bag),
                                        "table": lines}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
