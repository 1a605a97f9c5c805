"""``hmocap eval mocap``: replay a multi-view bag through the body tracker and score it against
its ground truth (the evaluation: :mod:`hmocap_ros.eval.mocap_eval`), or, with ``--tracked``,
score the bodies of a bag that ``hmocap track`` wrote (:mod:`hmocap_ros.eval.tracked_eval`).
Exit status 2 with one line on bad input, 1 when a method posed no frame with ground truth."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from hmocap_ros.detection.detectors import detector_names
from hmocap_ros.eval.mocap_eval import (
    evaluate,
    json_default,
    plot_errors,
    strict_json,
    tracker_overrides,
    unevaluated_methods,
)
from hmocap_ros.eval.mocap_frames import SILHOUETTES
from hmocap_ros.tracking.methods import method_names

__all__ = ["TRACKING_OPTIONS", "add_arguments", "main_from_args"]

#: the options of a tracker's run, by destination: (flag, default); --tracked takes none of them
TRACKING_OPTIONS = {
    "method": ("--method", None), "compare": ("--compare", False),
    "particles": ("--particles", 0), "layers": ("--layers", 0), "seed": ("--seed", 0),
    "silhouettes": ("--silhouettes", "fg"), "learn_from": ("--learn-from", None),
    "given_shape": ("--given-shape", False), "param": ("--param", None),
    "max_people": ("--max-people", 1), "detector": ("--detector", None), "rig": ("--rig", None),
    "threads": ("--threads", None),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help="bag (.mcap or rosbag2 folder) in the documented layout")
    parser.add_argument("--method", action="append", choices=method_names(),
                        help="tracker method; repeat to compare several (default: body_tracker's)")
    parser.add_argument("--compare", action="store_true", help="run every method (" + ", ".join(method_names()) + ")")
    parser.add_argument("--particles", type=int, default=0,
                        help="particles per layer (default: the method's, ~3500 evaluations)")
    parser.add_argument("--layers", type=int, default=0, help="APF layers (default 14)")
    parser.add_argument("--frames", type=int, default=None,
                        help="score at most this many frames with ground truth")
    parser.add_argument("--seed", type=int, default=0, help="seed of the tracker (default 0)")
    parser.add_argument("--silhouettes", choices=SILHOUETTES, default="fg",
                        help="masks: the bag's /<camera>/foreground; fg: segment the images "
                             "(default); gt: the bag's exact silhouettes; auto: the first the bag "
                             "has")
    parser.add_argument("--learn-from", choices=("empty_room", "person_masks"), default=None,
                        help="how the background model learns with fg (default: empty_room when "
                             "the bag starts with an empty room, else person_masks)")
    parser.add_argument("--given-shape", action="store_true",
                        help="track with the bag's true body shape (no anthropometry estimation)")
    parser.add_argument("--param", action="append", metavar="KEY=VALUE",
                        help="override a tracker setting by its dotted name, e.g. "
                             "filter.sweeps=1 (repeatable; body_tracker --help lists them)")
    parser.add_argument("--max-people", type=int, default=1,
                        help="people followed at once (one tracker each); the subject is scored "
                             "on the track nearest it (default 1)")
    parser.add_argument("--detector", choices=detector_names(), default=None,
                        help="extremity detector of kf-hpf and dd-hpf (default: extremity_detection's)")
    parser.add_argument("--rig", metavar="RIG.yaml", default=None,
                        help="track with this rig (e.g. from hmocap calibrate) instead of the "
                             "bag's /camera_rig; the truth stays the bag's")
    parser.add_argument("--threads", type=int, default=None,
                        help="numba threads (default: numba's, one per core)")
    parser.add_argument("--tracked", metavar="TRACKED.mcap", default=None,
                        help="score the bodies of this bag of hmocap track (made from BAG) "
                             "instead of tracking; takes none of the tracker's options")
    parser.add_argument("--json", metavar="OUT", help="write the report as JSON")
    parser.add_argument("--plot", metavar="OUT.png", help="plot the error over time")


def _tracking_options(ns: argparse.Namespace) -> list[str]:
    """The tracker's options given in ``ns`` (those set off their defaults)."""
    return [flag for dest, (flag, default) in TRACKING_OPTIONS.items()
            if getattr(ns, dest) != default]


def main_from_args(ns: argparse.Namespace) -> int:
    if ns.tracked:
        given = _tracking_options(ns)
        if given:
            print(f"hmocap eval mocap: --tracked scores a tracked bag; {', '.join(given)} "
                  f"only apply when tracking", file=sys.stderr)
            return 2
        from hmocap_ros.eval.tracked_eval import evaluate_tracked

        try:
            report = evaluate_tracked(ns.bag, ns.tracked, max_frames=ns.frames)
        except (ValueError, OSError, RuntimeError) as err:
            print(f"hmocap eval mocap: {err}", file=sys.stderr)
            return 2
        return _report(ns, report)
    if ns.threads:
        import numba

        numba.set_num_threads(ns.threads)
    from hmocap_ros.tracking.params import TrackerParams

    methods = list(method_names()) if ns.compare else (ns.method or [TrackerParams().method])
    methods = list(dict.fromkeys(methods))
    from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams

    try:
        overrides = tracker_overrides(ns.param)
        rig = None
        if ns.rig:
            from hmocap_ros.geometry.rig import load_rig

            rig = load_rig(Path(ns.rig))
        detector = ns.detector or ExtremityDetectionParams().detector
        report = evaluate(ns.bag, methods, silhouettes=ns.silhouettes, max_frames=ns.frames,
                          seed=ns.seed, particles=ns.particles, layers=ns.layers,
                          overrides=overrides, given_shape=ns.given_shape,
                          max_people=ns.max_people, rig=rig,
                          fg_params={"learn_from": ns.learn_from} if ns.learn_from else None,
                          detector=detector)
        if ns.rig:
            report["rig"] = str(ns.rig)
    except (ValueError, OSError, RuntimeError) as err:
        print(f"hmocap eval mocap: {err}", file=sys.stderr)
        return 2
    return _report(ns, report)


def _report(ns: argparse.Namespace, report: dict) -> int:
    """Write the report's files, print each method's result; the exit status."""
    if ns.json:
        Path(ns.json).parent.mkdir(parents=True, exist_ok=True)
        Path(ns.json).write_text(json.dumps(strict_json(report), indent=1, allow_nan=False,
                                            default=json_default))
    if ns.plot:
        plot_errors(report, ns.plot)
    for method, result in report["methods"].items():  # the result on stdout (progress went to stderr)
        print(f"{Path(ns.bag).name} {method}: mean joint error {result['mean_mm']:.1f} mm "
              f"(std {result['std_mm']:.1f}, median {result['median_mm']:.1f}) over "
              f"{result['frames_with_pose']}/{result['frames']} frames"
              + (f", {result['seconds_per_frame']:.2f} s/frame" if "seconds_per_frame" in result else "")
              + (f", {result['track_switches']} track switches" if report["max_people"] > 1 else ""))
        if len(result["persons"]) > 1:
            for person in result["persons"]:
                print(f"  {person['person_id']}: 12 limb joints {person['limb_joints_mm']:.1f} mm, "
                      f"mean {person['mean_mm']:.1f} mm, tracked on {person['frames_tracked']}/"
                      f"{person['frames_seen']} frame sets seen, {person['id_switches']} id "
                      f"switches")
    failed = unevaluated_methods(report)
    if failed:
        print(f"hmocap eval mocap: no frame evaluated ({', '.join(failed)}: no pose on any of the "
              f"{report['frames_with_truth']} frames with ground truth)", file=sys.stderr)
        return 1
    return 0
