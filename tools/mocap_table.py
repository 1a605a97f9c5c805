#!/usr/bin/env python3
"""Reproduce thesis tables 2.3/2.4 on the simulator: APF, HPF, HPF+APO, DD-HPF+ on the shipped motions.

One command renders an evaluation bag per shipped CMU clip (``hmocap sim mocap``: 4 cameras,
640x480, 25 fps, one second of empty room first so the background model can learn), once
without and once with distractors (a door that opens, a rolling ball, a second person), then
replays each through the same code as ``hmocap eval mocap`` (foreground segmentation, then the
tracker with its estimated anthropometry; DD-HPF+ also gets the detections of the extremity
detector, ``--detector keypoints`` or ``skin``) for the
methods of :data:`hmocap_ros.tracking.methods.METHODS` at about 3,500 weight evaluations per
frame, and writes a Markdown table of mean (std) 3D joint errors in mm, the per-frame error
plots and the JSON reports::

    .venv/bin/python tools/mocap_table.py                       # docs/tracking_results.md
    .venv/bin/python tools/mocap_table.py --seconds 1 --clips 13_26   # quick look
    .venv/bin/python tools/mocap_table.py --reuse               # resume an interrupted run
    .venv/bin/python tools/mocap_table.py --param filter.sweeps=1 --out t.md

The tracker follows up to ``--max-people`` people (default 2: the subject and the bystander
of the distractor scenes each get a tracker, :class:`~hmocap_ros.tracking.people_tracker.
PeopleTracker`), and each frame is scored on the track nearest the subject; ``--max-people 1``
gives the single tracker, which follows whoever the cameras see best.

Held out: the tracker's settings were chosen on other CMU clips (13_29, 02_05, 01_01 from the
project's shared CMU clips, simulator seeds 21-23); these clips are rendered with other seeds
(other subjects, clothing, rooms and placements: seed 101.. without, 201.. with distractors).
Bags are cached in ``--workdir`` (about 400 MB per 4 s bag) and reused when present.
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

from hmocap_ros.eval.mocap_eval import (
    evaluate,
    json_default,
    plot_errors,
    settings_diff,
    stored_params,
    tracker_overrides,
)
from hmocap_ros.tracking.methods import METHODS, method_names
from hmocap_sim.mocap_dataset import MocapSimConfig, generate

BVH = ROOT / "hmocap_ros" / "data" / "bvh"
#: (label, clip, start s, seconds): the shipped clips; the walk and the run are used whole.
SEQUENCES = (
    ("Wave (13_26)", "13_26.bvh", 12.0, 4.0),
    ("Laugh (14_19)", "14_19_first1201.bvh", 2.0, 4.0),
    ("Walk (02_01)", "002_01.bvh", 0.0, 2.8),
    ("Run (09_01)", "09_01.bvh", 0.0, 1.2),
    ("Crouch, throw (02_06)", "002_06_first511.bvh", 4.0, 4.0),
    ("Walk (07_01)", "007_01.bvh", 0.0, 2.5),
)


def bag_seed(index: int, distractors: bool) -> int:
    """Simulator seed of the ``index``-th sequence: 101.. without, 201.. with distractors."""
    return (201 if distractors else 101) + index


def bag_stem(clip: str, seconds: float, seed: int, distractors: bool) -> str:
    """File stem of an evaluation bag (and of its JSON report) in the work directory."""
    return f"{Path(clip).stem}_s{seed}{'_distractors' if distractors else ''}_{seconds:g}s"


def _bag(work: Path, clip: str, start: float, seconds: float, seed: int, distractors: bool) -> Path:
    path = work / f"{bag_stem(clip, seconds, seed, distractors)}.mcap"
    if not path.exists():
        t0 = time.perf_counter()
        generate(MocapSimConfig(out=path, bvh=BVH / clip, start=start, seconds=seconds, seed=seed,
                                distractors=distractors, progress=False))
        print(f"rendered {path.name} in {time.perf_counter() - t0:.0f} s", flush=True)
    return path


def _cell(res: dict) -> str:
    return f"{res['mean_mm']:.1f} ({res['std_mm']:.1f})"


def _reusable(path: Path, ns, overrides: dict) -> dict | None:
    """The report at ``path`` if it was made with this run's seed, max-people and methods and
    with the tracker settings this run would use (the defaults with ``--param``), compared
    as flat ``{dotted name: value}`` records (:func:`~hmocap_ros.eval.mocap_eval.
    settings_diff`): a report whose settings differ from these, or lack one, is not reused;
    one made with ``--param KEY=VALUE`` is once VALUE is KEY's default."""
    if not path.exists():
        return None
    try:
        report = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if report.get("seed") != ns.seed or report.get("max_people") != ns.max_people \
            or report.get("silhouettes") != "fg" or not set(ns.methods) <= set(report["methods"]) \
            or report.get("detector", "skin") != ns.detector:
        return None
    if any(report["methods"][m].get("params") is None
           or settings_diff(report["methods"][m]["params"], stored_params(m, overrides))
           for m in ns.methods):
        return None
    return report


def _result_args(args: list[str]) -> list[str]:
    """The command-line arguments that change the table (not where files go, nor --reuse)."""
    out, skip = [], False
    for a in args:
        if skip:
            skip = False
            continue
        if a in ("--workdir", "--out", "--figures"):
            skip = True
        elif a != "--reuse" and not a.startswith(("--workdir=", "--out=", "--figures=")):
            out.append(a)
    return out


#: the 12 joints the body model and BlazePose both define (the peer's table)
LIMB_JOINTS = ("l_shoulder", "r_shoulder", "l_elbow", "r_elbow", "l_wrist", "r_wrist",
               "l_hip", "r_hip", "l_knee", "r_knee", "l_ankle", "r_ankle")


def _limbs(per_joint: dict, joints=LIMB_JOINTS) -> float:
    values = [per_joint[j]["mean_mm"] for j in joints
              if j in per_joint and per_joint[j]["mean_mm"] is not None]
    return float(np.mean(values)) if len(values) == len(joints) else float("nan")


def limb_table(rows, methods) -> list[str]:
    """The 12 limb joints and the wrists of each method beside the keypoints alone (the
    extremity detector's own triangulated joints), per row."""
    lines = ["", "The 12 limb joints both skeletons define (shoulders, elbows, wrists, hips, "
             "knees, ankles): mean 3D error (mm) of each method and of the keypoints alone "
             "(the extremity detector's triangulated joints, frames where it found them); "
             "wrists in brackets.", "",
             "| sequence | scene | keypoints alone | " + " | ".join(
                 METHODS[m].label for m in methods) + " |",
             "|---|---|---|" + "---|" * len(methods)]
    wrists = ("l_wrist", "r_wrist")
    for label, seconds, distractors, report in rows:
        kp = report.get("keypoints") or {}
        cells = [f"{_limbs(kp):.1f} ({_limbs(kp, wrists):.0f})" if kp else "-"]
        for m in methods:
            pj = report["methods"][m]["per_joint"]
            cells.append(f"{_limbs(pj):.1f} ({_limbs(pj, wrists):.0f})")
        lines.append(f"| {label} ({seconds:g} s) | {'distractors' if distractors else 'clean'} "
                     "| " + " | ".join(cells) + " |")
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--workdir", default="/tmp/hmocap_mocap_table")
    p.add_argument("--clips", nargs="*", default=None,
                   help="subset of clip stems (13_26 14_19_first1201 002_01 09_01 "
                        "002_06_first511 007_01)")
    p.add_argument("--seconds", type=float, default=None, help="cap every sequence's length")
    p.add_argument("--methods", nargs="*", default=list(method_names()), choices=method_names())
    p.add_argument("--seed", type=int, default=0, help="tracker seed")
    p.add_argument("--no-distractors", action="store_true", help="skip the distractor bags")
    p.add_argument("--max-people", type=int, default=2,
                   help="people followed at once; the subject is scored on its track")
    p.add_argument("--reuse", action="store_true",
                   help="reuse a bag's JSON report from an earlier (interrupted) run when it has "
                        "the same seed, max-people, methods and tracker settings (the current "
                        "defaults with --param), instead of tracking it again")
    p.add_argument("--detector", choices=("keypoints", "skin"), default="keypoints",
                   help="extremity detector of KF-HPF and DD-HPF+ (default keypoints)")
    p.add_argument("--param", action="append", metavar="KEY=VALUE", default=[],
                   help="override a tracker setting by its dotted name for every method, e.g. "
                        "filter.sweeps=1 (repeatable), as in hmocap eval mocap")
    p.add_argument("--out", default=str(ROOT / "docs" / "tracking_results.md"))
    p.add_argument("--figures", default=str(ROOT / "docs" / "figures"))
    ns = p.parse_args(argv)
    try:
        overrides = tracker_overrides(ns.param)
    except ValueError as err:
        p.error(str(err))

    work = Path(ns.workdir)
    work.mkdir(parents=True, exist_ok=True)
    figures = Path(ns.figures)
    conditions = [False] if ns.no_distractors else [False, True]
    rows = []
    t_start = time.perf_counter()
    for i, (label, clip, start, seconds) in enumerate(SEQUENCES):
        if ns.clips and Path(clip).stem not in ns.clips:
            continue
        seconds = min(seconds, ns.seconds) if ns.seconds else seconds
        for distractors in conditions:
            seed = bag_seed(i, distractors)
            bag = _bag(work, clip, start, seconds, seed, distractors)
            stem = bag.stem
            name = f"{stem}_{ns.detector}.json"
            report = _reusable(work / name, ns, overrides) if ns.reuse else None
            if report is None:
                report = evaluate(bag, ns.methods, silhouettes="fg", seed=ns.seed,
                                  max_people=ns.max_people, overrides=overrides,
                                  detector=ns.detector)
                report["overrides"] = overrides
                (work / name).write_text(
                    json.dumps(report, indent=1, default=json_default))
            else:
                print(f"reused {name}", flush=True)
            plot_errors(report, figures / f"tracking_{stem}.png",
                        title=f"{label}{' with distractors' if distractors else ''}")
            rows.append((label, seconds, distractors, report))
            print(f"{label:16s} {'distractors' if distractors else 'clean':11s} " + "  ".join(
                f"{m} {_cell(report['methods'][m])}" for m in ns.methods), flush=True)

    lines = ["| sequence | scene | " + " | ".join(METHODS[m].label for m in ns.methods) + " |",
             "|---|---|" + "---|" * len(ns.methods)]
    for label, seconds, distractors, report in rows:
        best = min(ns.methods, key=lambda m: report["methods"][m]["mean_mm"])
        cells = [f"**{_cell(report['methods'][m])}**" if m == best else _cell(report["methods"][m])
                 for m in ns.methods]
        lines.append(f"| {label} ({seconds:g} s) | {'distractors' if distractors else 'clean'} | "
                     + " | ".join(cells) + " |")
    speed = {m: sum(r["methods"][m]["seconds_per_frame"] for *_, r in rows) / max(len(rows), 1)
             for m in ns.methods}
    evals = {m: sum(r["methods"][m]["evaluations_per_frame"] for *_, r in rows) / max(len(rows), 1)
             for m in ns.methods}
    switches = sum(r["methods"][m]["track_switches"] for *_, r in rows for m in ns.methods)
    lines += ["", "Mean (std) over the frames of the per-frame mean 3D joint error (mm, 19 joints); "
              "foreground from the images (`--silhouettes fg`), body shape estimated at start; "
              f"up to {ns.max_people} people followed, the subject scored on its track "
              f"(track switches: {switches}).",
              "Evaluations per frame (summed over the people followed, fresh searches "
              "included): " + ", ".join(f"{m} {evals[m]:.0f}" for m in ns.methods)
              + "; seconds per frame: " + ", ".join(f"{m} {speed[m]:.2f}" for m in ns.methods) + "."]
    # anthropometry (sec. 2.3): per-entity size error of the shape each run estimated at start
    anth = [r["methods"][m]["anthropometry"] for *_, r in rows for m in ns.methods
            if r["methods"][m].get("anthropometry") and "error_mm" in r["methods"][m]["anthropometry"]]
    if anth:
        names = list(anth[0]["error_mm"])
        lines += ["", "Anthropometry estimated at the start of each run (sec. 2.3) against the "
                  "simulated subject: mean absolute entity size error (mm) over "
                  f"{len(anth)} runs, and that of the unadapted model.", "",
                  "| entity | estimated | unadapted model |", "|---|---|---|"]
        for n in names:
            est = np.mean([abs(a["error_mm"][n]) for a in anth])
            neutral = np.mean([1000.0 * abs(a["true_m"][n] - a["neutral_m"][n]) for a in anth]) \
                if "neutral_m" in anth[0] else float("nan")
            lines.append(f"| {n} | {est:.0f} | {neutral:.0f} |")
        lines.append(f"| **mean** | **{np.mean([a['mean_abs_error_mm'] for a in anth]):.0f}** | "
                     f"**{np.mean([a['neutral_mean_abs_error_mm'] for a in anth]):.0f}** |")
        if all("stature_m" in a for a in anth):
            lines.insert(lines.index("| entity | estimated | unadapted model |"),
                         "The last column scales the model's proportions to the subject's true "
                         "height (a fit of the stature alone).\n")
            start = lines.index("| entity | estimated | unadapted model |")
            lines[start] = "| entity | estimated | unadapted model | stature alone |"
            lines[start + 1] = "|---|---|---|---|"
            for i, n in enumerate(names + ["mean"]):
                if n == "mean":
                    value = np.mean([a["stature_mean_abs_error_mm"] for a in anth])
                    lines[start + 2 + i] += f" **{value:.0f}** |"
                else:
                    value = np.mean([1000.0 * abs(a["true_m"][n] - a["stature_m"][n]) for a in anth])
                    lines[start + 2 + i] += f" {value:.0f} |"
    lines += limb_table(rows, ns.methods)
    table = "\n".join(lines)
    out = Path(ns.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    command = " ".join(["tools/mocap_table.py"] + _result_args(sys.argv[1:] if argv is None
                                                               else list(argv)))
    out.write_text(f"# Tracking results (generated by `{command}`)\n\n" + table + "\n")
    print(table)
    print(f"wrote {out} in {time.perf_counter() - t_start:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
