#!/usr/bin/env python3
"""Measure the peer on the tracking table's bags: MediaPipe Pose per view + DLT triangulation.

The issue compares the tracker with "MediaPipe Pose on each of 4 views plus DLT triangulation
(the FreeMoCap approach)". This runs that pipeline on the same held-out bags as
``tools/mocap_table.py`` and writes ``docs/peer_mediapipe.md``: the peer's 3D error on the 12
joints both skeletons define (shoulders, elbows, wrists, hips, knees, ankles), next to the
tracker's error on the same joints from the table's JSON reports::

    .venv/bin/python tools/mocap_table.py        # first: the bags and the tracker's reports
    .venv/bin/python tools/peer_mediapipe.py     # then: the peer on the same bags

With ``--bags BAG ...`` it measures the peer on any bags with ground truth instead and prints
its error per joint (mean over the frames where the joint was triangulated) and the share of
frames triangulated, the figures ``hmocap eval extremities`` gives for the package's own
keypoints (``--json OUT`` writes them)::

    .venv/bin/python tools/peer_mediapipe.py --bags held_out_1.mcap held_out_2.mcap --json peer.json

``--extremities REPORT.json ...`` (one ``hmocap eval extremities --json`` report per bag, same
order) prints the package's keypoints beside the peer, joint by joint.

MediaPipe is not a dependency of hmocap_ros (its last wheel with the pose model inside,
0.10.14, needs numpy < 2): the first run creates a separate venv, ``.venv-peer``, with
``pip install mediapipe==0.10.14 "numpy<2"`` and runs ``peer_mediapipe_worker.py`` in it.
Triangulation is ``hmocap_ros.geometry.triangulate_robust`` (undistorted DLT on the
landmarks with visibility > 0.5, a view that reprojects more than ``--max-reprojection-px``
away left out; 0 gives the plain DLT of ``triangulate``).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

from mocap_table import SEQUENCES, bag_seed, bag_stem

from hmocap_ros.geometry import triangulate, triangulate_robust
from hmocap_ros.tracking.methods import METHODS

#: our joint -> MediaPipe Pose landmark index
LANDMARKS = {"l_shoulder": 11, "r_shoulder": 12, "l_elbow": 13, "r_elbow": 14,
             "l_wrist": 15, "r_wrist": 16, "l_hip": 23, "r_hip": 24, "l_knee": 25,
             "r_knee": 26, "l_ankle": 27, "r_ankle": 28}
PEER_REQUIREMENTS = ["mediapipe==0.10.14", "numpy<2"]


def peer_python(venv: Path) -> Path:
    python = venv / "bin" / "python"
    if not python.exists():
        print(f"creating {venv} with {' '.join(PEER_REQUIREMENTS)} (once, about a minute)",
              flush=True)
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        subprocess.run([str(python), "-m", "pip", "install", "-q", *PEER_REQUIREMENTS], check=True)
    return python


def read_bag(bag: Path, stack_path: Path):
    """Rig, truth (F, J, 3), joint names and the images of every frame with truth, written to
    ``stack_path`` as an (F, V, H, W, 3) uint8 array."""
    from hmocap_ros.io import topics
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.conversions import image_to_rgb
    from hmocap_ros.io.msg_factory import stamp_to_ns
    from hmocap_ros.io.rig_messages import rig_from_msg

    with BagReader(bag) as reader:
        rig = rig_from_msg(reader.first(topics.CAMERA_RIG))
        truth, names = {}, ()
        for item in reader.messages([topics.GT_SKELETON]):
            names = tuple(str(n) for n in item.msg.joint_names)
            truth[stamp_to_ns(item.msg.header.stamp)] = np.array(
                [[p.x, p.y, p.z] for p in item.msg.positions])
        stamps = sorted(truth)
        image_topics = [topics.camera_image(n) for n in rig.names]
        cam0 = rig[0]
        stack = np.lib.format.open_memmap(stack_path, mode="w+", dtype=np.uint8,
                                          shape=(len(stamps), len(rig), cam0.height, cam0.width, 3))
        index = {s: i for i, s in enumerate(stamps)}
        for stamp, msgs in reader.frame_sets(image_topics):
            if stamp in index:
                for v, t in enumerate(image_topics):
                    stack[index[stamp], v] = image_to_rgb(msgs[t])
        stack.flush()
    return rig, np.stack([truth[s] for s in stamps]), names


def peer_on_bag(bag: Path, python: Path, max_reprojection_px: float):
    """The peer on one bag: (errors (F, 12) mm, NaN where not triangulated, ms per image)."""
    joints = list(LANDMARKS)
    with tempfile.TemporaryDirectory() as tmp:
        stack, marks = Path(tmp) / "images.npy", Path(tmp) / "landmarks.npy"
        rig, truth, names = read_bag(bag, stack)
        done = subprocess.run([str(python), str(ROOT / "tools" / "peer_mediapipe_worker.py"),
                               str(stack), str(marks)], check=True, capture_output=True, text=True)
        landmarks = np.load(marks)  # (F, V, 33, 3)
    lm = landmarks[:, :, [LANDMARKS[j] for j in joints]]
    gt = truth[:, [names.index(j) for j in joints]]
    pix = lm[..., :2].transpose(1, 0, 2, 3).reshape(len(rig), -1, 2)
    valid = lm[..., 2].transpose(1, 0, 2).reshape(len(rig), -1) > 0.5
    if max_reprojection_px > 0:
        est, _ = triangulate_robust(list(rig), pix, valid, max_reprojection_px)
    else:
        est = triangulate(list(rig), pix, valid)
    errors = 1000 * np.linalg.norm(est.reshape(gt.shape) - gt, axis=-1)
    return errors, float(done.stdout.split()[0])


def per_joint_report(bags: list[str], python: Path, max_reprojection_px: float) -> dict:
    """``--bags``: the peer's error per joint on each bag, printed and returned."""
    joints = list(LANDMARKS)
    out = {}
    for bag in bags:
        errors, ms = peer_on_bag(Path(bag), python, max_reprojection_px)
        found = np.isfinite(errors)
        within = (errors <= 100.0) & found
        out[bag] = {"ms_per_image": ms, "frames": int(len(errors)), "joints": {
            j: {"mean_error_mm": float(np.nanmean(errors[:, k])) if found[:, k].any() else None,
                "triangulated": float(found[:, k].mean()),
                "recall_100mm": float(within[:, k].mean())}
            for k, j in enumerate(joints)}}
        print(f"{Path(bag).name}: peer, {len(errors)} frames, {ms:.1f} ms per image; "
              f"12 joints {np.nanmean(errors):.1f} mm")
        for j, s in out[bag]["joints"].items():
            print(f"  {j:11s} {s['mean_error_mm'] or float('nan'):7.1f} mm  triangulated "
                  f"{s['triangulated']:.2f}  within 10 cm {s['recall_100mm']:.2f}", flush=True)
    return out


#: our joint -> the label of the extremity detector's report
_EXTREMITY_LABEL = {j: ("left_" if j[0] == "l" else "right_") + j[2:] for j in LANDMARKS}


def side_by_side(peer: dict, ours: dict) -> list[str]:
    """Lines: per joint the peer's and the keypoints' mean error (mm) and share of frames
    within 10 cm, and the difference."""
    lines = [f"{'joint':11s} {'peer mm':>8s} {'ours mm':>8s} {'diff':>6s}  {'peer<10cm':>9s} "
             f"{'ours<10cm':>9s}"]
    for j, s in peer["joints"].items():
        o = ours["labels"].get(_EXTREMITY_LABEL[j], {})
        mine = o.get("mean_error_mm", float("nan"))
        theirs = s["mean_error_mm"] if s["mean_error_mm"] is not None else float("nan")
        lines.append(f"{j:11s} {theirs:8.1f} {mine:8.1f} {mine - theirs:+6.1f}  "
                     f"{s['recall_100mm']:9.2f} {o.get('recall', float('nan')):9.2f}")
    return lines


def _label(method: str, detector: str) -> str:
    """The table label of a method; DD-HPF+ names its detector."""
    label = METHODS[method].label
    return f"{label} ({detector})" if METHODS[method].uses_detector else label


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--workdir", default="/tmp/hmocap_mocap_table",
                   help="where mocap_table.py left its bags and JSON reports")
    p.add_argument("--peer-venv", default=str(ROOT / ".venv-peer"))
    p.add_argument("--max-reprojection-px", type=float, default=20.0,
                   help="leave out a view that reprojects further than this (0: plain DLT)")
    p.add_argument("--out", default=str(ROOT / "docs" / "peer_mediapipe.md"))
    p.add_argument("--detector", choices=("keypoints", "skin"), default="keypoints",
                   help="the table's reports made with this extremity detector")
    p.add_argument("--methods", nargs="*", default=["hpf-apo", "dd-hpf"],
                   help="tracker methods of the table's reports to compare (those present)")
    p.add_argument("--bags", nargs="+", default=None,
                   help="measure the peer per joint on these bags (with ground truth) instead")
    p.add_argument("--json", default=None, help="with --bags: write the figures here")
    p.add_argument("--extremities", nargs="+", default=None, metavar="REPORT",
                   help="with --bags: hmocap eval extremities --json reports, one per bag, "
                        "printed beside the peer")
    ns = p.parse_args(argv)
    python = peer_python(Path(ns.peer_venv))
    if ns.bags:
        if ns.extremities and len(ns.extremities) != len(ns.bags):
            p.error("--extremities needs one report per bag")
        report = per_joint_report(ns.bags, python, ns.max_reprojection_px)
        if ns.json:
            Path(ns.json).write_text(json.dumps(report, indent=1))
        for bag, ours in zip(ns.bags, ns.extremities or ()):
            print(f"\n{Path(bag).name}: the peer and the package's keypoints ({ours})")
            print("\n".join(side_by_side(report[bag], json.loads(Path(ours).read_text()))))
        return 0
    work = Path(ns.workdir)
    joints = list(LANDMARKS)
    rows, per_joint_all = [], []
    for i, (label, clip, _start, seconds) in enumerate(SEQUENCES):
        for distractors in (False, True):
            stem = bag_stem(clip, seconds, bag_seed(i, distractors), distractors)
            bag, report = work / f"{stem}.mcap", work / f"{stem}_{ns.detector}.json"
            if not (bag.exists() and report.exists()):
                print(f"skip {stem}: run tools/mocap_table.py first", flush=True)
                continue
            with tempfile.TemporaryDirectory() as tmp:
                stack, marks = Path(tmp) / "images.npy", Path(tmp) / "landmarks.npy"
                rig, truth, names = read_bag(bag, stack)
                t0 = time.perf_counter()
                done = subprocess.run([str(python), str(ROOT / "tools" / "peer_mediapipe_worker.py"),
                                       str(stack), str(marks)], check=True, capture_output=True,
                                      text=True)
                wall = time.perf_counter() - t0
                landmarks = np.load(marks)  # (F, V, 33, 3)
            ms_per_image = float(done.stdout.split()[0])
            lm = landmarks[:, :, [LANDMARKS[j] for j in joints]]  # (F, V, 12, 3)
            gt = truth[:, [names.index(j) for j in joints]]
            # every frame's joints in one call: (V, F * 12, 2) pixels
            pix = lm[..., :2].transpose(1, 0, 2, 3).reshape(len(rig), -1, 2)
            valid = lm[..., 2].transpose(1, 0, 2).reshape(len(rig), -1) > 0.5
            if ns.max_reprojection_px > 0:
                est, _ = triangulate_robust(list(rig), pix, valid, ns.max_reprojection_px)
            else:
                est = triangulate(list(rig), pix, valid)
            errors = 1000 * np.linalg.norm(est.reshape(gt.shape) - gt, axis=-1)  # (F, 12)
            per_frame = np.nanmean(errors, axis=1)
            reported = json.loads(report.read_text())["methods"]
            methods = [m for m in ns.methods if m in reported]
            ours12 = {m: float(np.mean([reported[m]["per_joint"][j]["mean_mm"] for j in joints]))
                      for m in methods}
            ours19 = {m: reported[m]["mean_mm"] for m in methods}
            rows.append((label, seconds, distractors, float(np.nanmean(per_frame)),
                         float(np.nanstd(per_frame)), float(np.isfinite(errors).mean()),
                         ms_per_image, ours12, ours19))
            per_joint_all.append(np.nanmean(errors, axis=0))
            print(f"{label:16s} {'distractors' if distractors else 'clean':11s} peer "
                  f"{rows[-1][3]:.1f} mm ({100 * rows[-1][5]:.0f} % joints triangulated, "
                  f"{ms_per_image:.1f} ms/image, {wall:.0f} s)  " + ", ".join(
                      f"{m} {v:.1f} mm" for m, v in ours12.items()) + " on the same joints",
                  flush=True)
    if not rows:
        print("no bags: run tools/mocap_table.py first", file=sys.stderr)
        return 1
    lines = ["# The peer: MediaPipe Pose per view + DLT (generated by tools/peer_mediapipe.py)", "",
             "Same held-out bags as `docs/tracking_results.md` (4 cameras, 640x480, 25 fps). "
             "Error: mean (std) over frames of the mean 3D error of the 12 joints both "
             "skeletons define (shoulders, elbows, wrists, hips, knees, ankles), mm.", "",
             "| sequence | scene | peer: MediaPipe + DLT | joints triangulated | " + " | ".join(
                 f"{_label(m, ns.detector)}, same 12 joints" for m in methods) + " | " + " | ".join(
                 f"{_label(m, ns.detector)}, 19 joints" for m in methods) + " |",
             "|---|---|---|---|" + "---|" * (2 * len(methods))]
    for label, seconds, distractors, mean, std, cover, _ms, ours12, ours19 in rows:
        lines.append(f"| {label} ({seconds:g} s) | {'distractors' if distractors else 'clean'} | "
                     f"{mean:.1f} ({std:.1f}) | {100 * cover:.0f} % | "
                     + " | ".join(f"{ours12[m]:.1f}" for m in methods) + " | "
                     + " | ".join(f"{ours19[m]:.1f}" for m in methods) + " |")
    # a bag where both followed the other person (errors of metres) would swamp the means
    same_person = [k for k, r in enumerate(rows)
                   if r[3] < 500.0 and all(v < 500.0 for v in r[7].values())]
    head = ("| mean of the rows above where both followed the subject | |"
            if len(same_person) < len(rows) else "| mean | |")
    lines.append(f"{head} **{np.mean([rows[k][3] for k in same_person]):.1f}** | | " + " | ".join(
        f"**{np.mean([rows[k][7][m] for k in same_person]):.1f}**" for m in methods) + " | "
        + " | ".join(f"{np.mean([rows[k][8][m] for k in same_person]):.1f}" for m in methods)
        + " |")
    ms = np.mean([r[6] for r in rows])
    lines += ["", f"MediaPipe Pose 0.10.14 (model_complexity 1, video mode, one tracker per view): "
              f"{ms:.1f} ms per 640x480 image on this machine = {1000 / (4 * ms):.1f} frames/s for "
              "4 views, triangulation not counted. Views with landmark visibility <= 0.5 are not "
              f"used; a view reprojecting more than {ns.max_reprojection_px:g} px is left out "
              "(0 = plain DLT).", "",
              "Peer error per joint (mm, mean over the bags of the mean row): " + ", ".join(
                  f"{j} {v:.0f}" for j, v in zip(
                      joints, np.nanmean([per_joint_all[k] for k in same_person], axis=0))) + "."]
    out = Path(ns.out)
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
