"""``hmocap eval mocap``: replay a multi-view bag through the body tracker and score it.

    hmocap eval mocap BAG [--method kf-hpf|apf|hpf|hpf-apo|dd-hpf ...] [--compare] [--particles N]
        [--layers L] [--frames N] [--seed S] [--silhouettes auto|masks|fg|gt] [--max-people N]
        [--json OUT] [--plot OUT.png]
    hmocap eval mocap BAG --tracked TRACKED.mcap [--frames N] [--json OUT] [--plot OUT.png]

No DDS: the bag is read with :class:`~hmocap_ros.io.bag_reader.BagReader` and every frame set
goes through the same code as the live nodes, in order: foreground segmentation
(:class:`~hmocap_ros.segmentation.BackgroundModel`, one per camera, learning from the bag's
empty-room frames) and :meth:`BodyTracker.update <hmocap_ros.tracking.body_tracker.BodyTracker.update>`.
Runs are deterministic for a given ``--seed``.

Inputs: any bag in the documented layout (:mod:`hmocap_ros.io.topics`): ``/camera_rig``
(latched CameraRig; the camera names give the image topics ``/<name>/image_raw``), the ground
truth ``/ground_truth/skeleton`` (joints matched by name) and, if present,
``/ground_truth/body_shape`` and ``/ground_truth/<name>/silhouette``. Frame sets are grouped
by ``header.stamp``; a camera missing from a set is passed to the tracker as a dropped view.

Silhouettes: ``fg`` (default) segments the images; the background model learns from the frames
before the first ground-truth skeleton (the empty room), or, in a bag without such frames,
where the landmark network's person masks leave the room free (``--learn-from person_masks``,
:class:`~hmocap_ros.segmentation.PersonMaskedBackground`), and says so in its output and in
the JSON (``silhouettes_fallback``). ``--learn-from empty_room`` on a bag without an empty room
falls back to ``gt`` (the bag's exact silhouettes).

Several people (``--max-people N``): N trackers run side by side, each on a person of its own
(:class:`~hmocap_ros.tracking.people_tracker.PeopleTracker`); each frame is scored on the
track whose pelvis stands nearest the subject's, as multi-person benchmarks match estimates to
people, and the report counts the changes of that track (``track_switches``).

Several people with ground truth (``hmocap sim mocap --people N``; person ``k``'s truth under
``/ground_truth/body_<k>/``, :mod:`~hmocap_ros.eval.people_truth`): each method's ``persons``
scores every person, the subject first, matched to the tracked bodies in each frame set by the
Hungarian method on the mean joint distance within a gate
(:mod:`~hmocap_ros.eval.people_scores`): the error figures below, the 12 limb joints, the
frame sets where the person is seen (by >= 2 cameras, from the per-person silhouettes) and
tracked, and the id switches. The top-level figures stay the subject's on its nearest track.

A tracked bag (``--tracked``, :mod:`~hmocap_ros.eval.tracked_eval`): the bodies that
``hmocap track`` wrote from BAG are scored in the same way, as method ``tracked``, without
running a tracker (no timing, states or anthropometry).

Output (``--json``): per method the overall mean and standard deviation of the per-frame mean
joint error (mm; thesis table 2.3), per-joint mean and std, per-frame errors, frames with and
without a pose, tracker seconds per frame and frames per second (also including segmentation),
mean time per stage, evaluations per frame, and the estimated against the true anthropometry
(entity sizes, :func:`hmocap_ros.body.entity_sizes`). ``--plot``: error over time, one line per
method.
"""
from __future__ import annotations

import json
import logging
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hmocap_ros.eval.metrics import match_joints
from hmocap_ros.eval.mocap_frames import BagFrames, load_frames
from hmocap_ros.eval.people_scores import nearest_bodies, score_tracks
from hmocap_ros.params import field_overrides, flat_record, from_flat
from hmocap_ros.tracking.methods import get_method

__all__ = ["BagFrames", "EvalResult", "evaluate", "json_default", "load_frames", "plot_errors",
           "run_method", "scores_record", "strict_json", "tracker_overrides",
           "unevaluated_methods"]

log = logging.getLogger(__name__)

#: Longest time (s) between two progress lines of a method's run.
PROGRESS_SECONDS = 10.0


@dataclass
class EvalResult:
    """Scores of one method on one bag (see the module docstring for the JSON)."""

    method: str
    summary: dict
    seconds_per_frame: float
    fps: float
    fps_with_segmentation: float
    evaluations_per_frame: float
    stage_seconds: dict
    states: list
    fit_costs: list
    anthropometry: dict | None
    params: dict = field(default_factory=dict)
    persons: list = field(default_factory=list)


# ----------------------------------------------------------------------------- runs


def _anthropometry(model, estimate, truth, truth_model=None) -> dict | None:
    """Entity sizes (sec. 2.3.2) of the estimated shape on ``model`` (the tracker's mesh: a
    shape's factors scale each mesh's own surface), and of the true shape on ``truth_model``
    (the simulator's; default ``model``)."""
    from hmocap_ros.body import ENTITY_NAMES, entity_sizes

    if estimate is None:
        return None
    truth_model = model if truth_model is None else truth_model
    est = entity_sizes(model, estimate)
    out = {"estimated_m": dict(zip(ENTITY_NAMES, map(float, est))),
           "global_scale": float(estimate.global_scale)}
    if truth is not None:
        from hmocap_ros.body import BodyShape

        true = entity_sizes(truth_model, truth)
        neutral = entity_sizes(model, None)
        # a fit of the stature alone: the model's proportions scaled to the true height
        ratio = float(truth.height(truth_model) / BodyShape.neutral().height(model))
        stature = entity_sizes(model, BodyShape(np.ones(len(ENTITY_NAMES)),
                                                np.ones(len(ENTITY_NAMES)), ratio))
        out["true_m"] = dict(zip(ENTITY_NAMES, map(float, true)))
        out["neutral_m"] = dict(zip(ENTITY_NAMES, map(float, neutral)))
        out["stature_m"] = dict(zip(ENTITY_NAMES, map(float, stature)))
        out["stature_mean_abs_error_mm"] = 1000.0 * float(np.abs(stature - true).mean())
        out["error_mm"] = {n: 1000.0 * float(a - b) for n, a, b in zip(ENTITY_NAMES, est, true)}
        out["mean_abs_error_mm"] = 1000.0 * float(np.abs(est - true).mean())
        out["neutral_mean_abs_error_mm"] = 1000.0 * float(np.abs(neutral - true).mean())
        out["true_global_scale"] = float(truth.global_scale)
    return out


def method_params(method: str, particles: int = 0, layers: int = 0,
                  overrides: dict | None = None):
    """The TrackerParams of one method's run (``particles``/``layers`` 0: the method's own
    budget; ``overrides``: ``--param`` settings by dotted name)."""
    from hmocap_ros.tracking.params import TrackerParams

    values = {"filter.particles": particles, "filter.layers": layers, **(overrides or {})}
    values["method"] = method
    return from_flat(TrackerParams, values)


def params_record(params) -> dict:
    """``params`` as a report stores them (``methods.<m>.params``): dotted name -> value."""
    return flat_record(params)


def stored_params(method: str, overrides: dict | None = None) -> dict:
    """The settings a run of ``method`` with ``overrides`` uses, in JSON types, as a report
    read back from disk holds them: what a tool compares a stored report's params with."""
    return json.loads(json.dumps(params_record(method_params(method, overrides=overrides)),
                                 default=json_default))


def settings_diff(stored: dict, wanted: dict) -> list[str]:
    """``"key stored -> wanted"`` for each setting a stored report's ``params`` differ in from
    those a run would use now (:func:`stored_params`)."""
    return [f"{k} {stored.get(k)!r} -> {v!r}" for k, v in wanted.items() if stored.get(k) != v]


def keypoint_errors(frames: BagFrames) -> dict | None:
    """The extremity detector's labelled joints alone against the truth: per body-model joint
    (:data:`~hmocap_ros.detection.detections.MODEL_JOINT`) the mean 3D error (mm) over the
    frames where it was detected, and its recall (the share of frames with truth where it was);
    None without detections."""
    from hmocap_ros.detection.detections import MODEL_JOINT

    if frames.detections is None:
        return None
    names = list(frames.joint_names)
    out = {}
    truth_frames = np.flatnonzero(frames.has_truth)
    for label, joint in MODEL_JOINT.items():
        if joint not in names:
            continue
        j = names.index(joint)
        errors = []
        for k in truth_frames:
            det = frames.detections[k]
            pos = det.position(label) if det is not None else None
            if pos is not None:
                errors.append(1000.0 * float(np.linalg.norm(pos - frames.truth[k, j])))
        out[joint] = {"mean_mm": float(np.mean(errors)) if errors else None,
                      "recall": len(errors) / max(len(truth_frames), 1)}
    return out


def run_method(frames: BagFrames, method: str, *, seed: int = 0, particles: int = 0,
               layers: int = 0, overrides: dict | None = None, given_shape: bool = False,
               max_people: int = 1, progress=None) -> EvalResult:
    """Track every frame set of ``frames`` with one method and score the frames with truth.

    max_people: trackers run side by side (:class:`~hmocap_ros.tracking.people_tracker.
    PeopleTracker`); the tracked bodies are scored by
    :func:`~hmocap_ros.eval.people_scores.score_tracks`: each scored frame on the track nearest
    the subject (a change of track between scored frames counts as a switch), and in
    ``persons`` every person with truth on the bodies matched to them.
    Time and evaluations per frame are those of all trackers together.
    """
    from hmocap_ros.body import load_body_model
    from hmocap_ros.tracking.people_tracker import PeopleTracker

    model = load_body_model("tracking")
    params = method_params(method, particles, layers, overrides)
    uses_detector = params.tracking_method.uses_detector
    shape = frames.body_shape if given_shape else None
    people = PeopleTracker(model, frames.rig, params, np.random.default_rng(seed), shape=shape,
                           max_people=max_people)
    est_idx, true_idx = match_joints(model.joint_names, frames.joint_names)
    names = [model.joint_names[i] for i in est_idx]
    truth_roots = frames.truth[:, true_idx[0]]
    has_truth = frames.has_truth
    bodies = np.full((len(frames.stamps), people.max_people, len(est_idx), 3), np.nan)
    states, costs = [], []
    stage: dict[str, float]
    times, stage, evals = [], {}, []
    for k, stamp in enumerate(frames.stamps):
        dets = frames.detections[k] if (frames.detections is not None and uses_detector) else None
        results = people.update(frames.mask_list(k), int(stamp), dets)
        for t, r in enumerate(results):
            if r.joints is not None:  # has_pose
                bodies[k, t] = r.joints[est_idx]
        slot = max(int(nearest_bodies(bodies[k:k + 1, :, 0], truth_roots[k:k + 1])[0]), 0)
        result = results[slot]
        if has_truth[k]:
            states.append(result.state)
            costs.append(None if not np.isfinite(result.fit_cost) else float(result.fit_cost))
            times.append(sum(r.timings["total"] for r in results))
            evals.append(sum(r.timings["evaluations"] for r in results))
            for key in ("observe", "hull", "init", "filter", "skinning", "projection", "xor",
                        "detection", "proposals", "research"):
                stage[key] = stage.get(key, 0.0) + sum(r.timings.get(key, 0.0) for r in results)
        if progress is not None:
            progress(k, len(frames.stamps), result)
    scores = score_tracks(frames, bodies, names, true_idx, people.ids)
    summary = scores.summary
    summary["max_people"] = int(max_people)
    subject = scores.subject_body
    n = max(len(times), 1)
    spf = float(np.sum(times) / n)
    seg = frames.segmentation_s + (frames.detector_s if uses_detector else 0.0)
    return EvalResult(
        method=method, summary=summary, seconds_per_frame=spf,
        fps=1.0 / spf if spf > 0 else float("inf"),
        fps_with_segmentation=1.0 / (spf + seg) if spf + seg > 0 else float("inf"),
        evaluations_per_frame=float(np.mean(evals)) if evals else 0.0,
        stage_seconds={k: v / n for k, v in stage.items()}, states=states, fit_costs=costs,
        anthropometry=_anthropometry(people.trackers[subject].model,
                                     people.trackers[subject].shape, frames.body_shape, model),
        params=params_record(params), persons=scores.persons)


def scores_record(summary: dict, persons: list) -> dict:
    """A method's scores as the report stores them (``methods.<m>``): the subject's figures of
    :func:`~hmocap_ros.eval.people_scores.score_tracks` and every person's (``persons``)."""
    keys = ("mean_mm", "std_mm", "median_mm", "frames", "frames_with_pose", "per_joint",
            "per_frame_mm", "track_switches")
    return {**{k: summary[k] for k in keys}, "persons": persons}


def evaluate(bag: str | Path, methods=("kf-hpf",), *, silhouettes: str = "fg",
             max_frames: int | None = None, seed: int = 0, particles: int = 0, layers: int = 0,
             overrides: dict | None = None, given_shape: bool = False,
             fg_params: dict | None = None, max_people: int = 1, detector: str = "keypoints",
             rig=None, out=None) -> dict:
    """Evaluate ``methods`` on one bag; returns the JSON-ready report (``max_people``: see
    :func:`run_method`; ``detector``: the extremity detector of the methods that use one;
    ``rig``: cameras to track with instead of the bag's, e.g. a calibrated rig)."""
    from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams

    out = sys.stderr if out is None else out
    t0 = time.perf_counter()
    print(f"{Path(bag).name}: reading the bag"
          + (", segmenting the images" if silhouettes == "fg" else "")
          + (" and detecting extremities" if any(get_method(m).uses_detector for m in methods) else "")
          + " ...", file=out, flush=True)
    frames = load_frames(bag, silhouettes, max_frames, fg_params=fg_params, out=out,
                         detector=(ExtremityDetectionParams(detector=detector)
                                   if any(get_method(m).uses_detector for m in methods)
                                   else None), rig=rig)
    report: dict[str, Any] = {
        "bag": str(bag),
        "rig": "the bag's" if rig is None else "given",
        "silhouettes": frames.silhouettes,
        "silhouettes_fallback": frames.fallback,
        "frame_sets": int(len(frames.stamps)),
        "frames_with_truth": int(frames.has_truth.sum()),
        "cameras": list(frames.rig.names),
        "image_size": list(frames.shape_hw[::-1]),
        "segmentation_seconds_per_frame": frames.segmentation_s,
        "detector": detector,
        "detection_seconds_per_frame": frames.detector_s,
        "seed": seed,
        "given_shape": bool(given_shape),
        "max_people": int(max_people),
        "keypoints": keypoint_errors(frames),
        "methods": {},
    }
    print(f"{Path(bag).name}: {len(frames.stamps)} frame sets ({int(frames.has_truth.sum())} with "
          f"ground truth) read in {time.perf_counter() - t0:.0f} s", file=out, flush=True)
    for method in methods:
        res = run_method(frames, method, seed=seed, particles=particles, layers=layers,
                         overrides=overrides, given_shape=given_shape, max_people=max_people,
                         progress=ProgressPrinter(method, out))
        s = res.summary
        report["methods"][method] = {
            **scores_record(s, res.persons),
            "seconds_per_frame": res.seconds_per_frame, "fps": res.fps,
            "fps_with_segmentation": res.fps_with_segmentation,
            "evaluations_per_frame": res.evaluations_per_frame,
            "stage_seconds_per_frame": res.stage_seconds, "states": res.states,
            "fit_costs": res.fit_costs, "anthropometry": res.anthropometry,
            "params": res.params,
        }
        print(f"{Path(bag).name} {method:8s} mean {s['mean_mm']:.1f} mm (std {s['std_mm']:.1f}) "
              f"over {s['frames_with_pose']}/{s['frames']} frames, "
              f"{res.seconds_per_frame:.2f} s/frame"
              + (f", {s['track_switches']} track switches" if max_people > 1 else ""), file=out)
    report["wall_seconds"] = time.perf_counter() - t0
    return report


class ProgressPrinter:
    """``run_method``'s progress callback: one line on ``out`` about every tenth of the frame
    sets, at least every :data:`PROGRESS_SECONDS`, and at the last one (frame, state, time)."""

    def __init__(self, method: str, out, seconds: float = PROGRESS_SECONDS):
        self.method, self.out, self.seconds = method, out, seconds
        self.t0 = self.last = time.perf_counter()
        self.next_k = 0

    def __call__(self, k: int, n: int, result) -> None:
        now = time.perf_counter()
        if k + 1 < n and k < self.next_k and now - self.last < self.seconds:
            return
        self.next_k = k + max(1, n // 10)
        self.last = now
        print(f"  {self.method}: frame set {k + 1}/{n} ({result.state}), {now - self.t0:.0f} s",
              file=self.out, flush=True)


def strict_json(obj):
    """``obj`` with every non-finite float (NaN, inf) replaced by None, numpy scalars and
    arrays by Python values: what ``json.dumps(..., allow_nan=False)`` accepts."""
    if isinstance(obj, dict):
        return {str(k): strict_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict_json(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return strict_json(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        value = float(obj)
        return value if np.isfinite(value) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def unevaluated_methods(report: dict) -> list[str]:
    """Methods of ``report`` that scored no frame (no pose on any frame with ground truth)."""
    return [m for m, r in report["methods"].items() if not r["frames_with_pose"]]


# ----------------------------------------------------------------------------- plot


def plot_errors(report: dict, path: str | Path, title: str | None = None) -> None:
    """Per-frame mean joint error over time, one line per method (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.5), dpi=120)
    for method, res in report["methods"].items():
        y = np.array([np.nan if v is None else v for v in res["per_frame_mm"]])
        x = np.arange(len(y)) / 25.0
        ax.plot(x, y, label=f"{method} (mean {res['mean_mm']:.0f} mm)")
    ax.set_xlabel("time since the subject appeared (s, 25 fps)")
    ax.set_ylabel("mean 3D joint error (mm)")
    ax.set_title(title or Path(report["bag"]).name)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


# ----------------------------------------------------------------------------- options


def tracker_overrides(items) -> dict:
    """TrackerParams settings by dotted name from ``KEY=VALUE`` strings (``--param``; see
    :func:`hmocap_ros.params.field_overrides`)."""
    from hmocap_ros.tracking.params import TrackerParams

    return field_overrides(TrackerParams, items, "tracker parameter")


def detection_overrides(items) -> dict:
    """ExtremityDetectionParams settings by dotted name from ``KEY=VALUE`` strings
    (``--detection-param``; see :func:`hmocap_ros.params.field_overrides`)."""
    from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams

    return field_overrides(ExtremityDetectionParams, items, "extremity detection parameter")


def json_default(obj):
    """``json.dumps``' ``default``: numpy scalars and arrays as Python values, tuples as lists,
    anything else as its string."""
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, tuple):
        return list(obj)
    return str(obj)
