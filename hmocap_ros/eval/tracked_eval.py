"""``hmocap eval mocap BAG --tracked TRACKED``: score the bodies of a bag that ``hmocap track``
wrote against the truth of the bag it tracked.

The room pipeline (``hmocap track``, :func:`~hmocap_ros.eval.bag_tracking.track_to_bag`) runs
what the evaluation's own replay cannot: the keypoint stage fed back the tracked skeletons by
body id, which the multi-person keypoints need. Its bag holds one ``/skeleton``
(hmocap_interfaces/Skeleton) per body with a pose per frame set, with the body's id and the frame
set's stamp, and one ``/humans/bodies/tracked`` per frame set. Those skeletons are scored as
the evaluation scores its own trackers' (:func:`~hmocap_ros.eval.people_scores.score_tracks`):
over the truth bag's frame sets with truth (:func:`~hmocap_ros.eval.mocap_frames.load_truth`),
a body without a skeleton in a frame set, and a frame set missing from the tracked bag, count
as without a pose. The tracked bag records no method: its scores go under
:data:`TRACKED_METHOD`.
"""
from __future__ import annotations

import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hmocap_ros.eval.metrics import match_joints
from hmocap_ros.eval.mocap_eval import scores_record
from hmocap_ros.eval.mocap_frames import load_truth
from hmocap_ros.eval.people_scores import score_tracks

__all__ = ["SKELETON_TOPIC", "TRACKED_METHOD", "TrackedBodies", "evaluate_tracked", "read_tracked"]

#: the tracker's skeletons in a bag of ``hmocap track``
SKELETON_TOPIC = "/skeleton"
#: its list of the bodies tracked, one message per frame set
TRACKED_TOPIC = "/humans/bodies/tracked"
#: the method name of a tracked bag's scores
TRACKED_METHOD = "tracked"


@dataclass
class TrackedBodies:
    """The skeletons of a tracked bag at a truth bag's frame sets (:func:`read_tracked`).

    joint_names: the skeletons' joints; body_ids: the bodies, in the order of ``bodies``;
    bodies: (F, T, J, 3) metres, NaN where a body has no skeleton; frame_sets: (F,) whether the
    tracked bag has the frame set; skeletons_elsewhere: skeletons at stamps that are no frame
    set of the truth bag (a frame set without truth, before the subject appears).
    """

    joint_names: tuple
    body_ids: tuple
    bodies: np.ndarray
    frame_sets: np.ndarray
    skeletons_elsewhere: int


def _id_order(body_id: str) -> tuple:
    """Bodies in the order of their ids, numbers by value (``b2`` before ``b10``)."""
    return tuple((0, int(part), "") if part.isdigit() else (1, 0, part)
                 for part in re.split(r"(\d+)", body_id) if part)


def read_tracked(tracked: str | Path, stamps: np.ndarray) -> TrackedBodies:
    """The ``/skeleton`` messages of the bag ``tracked`` at the frame sets ``stamps`` (ns).

    Raises ValueError when the bag has no ``/skeleton`` topic, or when none of its frame sets
    (``/humans/bodies/tracked``'s stamps, else its skeletons') is one of ``stamps``: the bag
    tracked another recording.
    """
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.msg_factory import stamp_to_ns

    index = {int(s): k for k, s in enumerate(stamps)}
    skeletons: dict[str, dict[int, dict[str, np.ndarray]]] = {}
    tracked_stamps: set[int] = set()
    names: tuple = ()
    elsewhere = 0
    with BagReader(tracked) as reader:
        available = reader.topics()
        if SKELETON_TOPIC not in available:
            raise ValueError(f"{tracked}: no {SKELETON_TOPIC}: not a bag of hmocap track")
        read = [SKELETON_TOPIC] + ([TRACKED_TOPIC] if TRACKED_TOPIC in available else [])
        for item in reader.messages(read):
            stamp = stamp_to_ns(item.msg.header.stamp)
            tracked_stamps.add(stamp)
            if item.topic != SKELETON_TOPIC:
                continue
            if stamp not in index:
                elsewhere += 1
                continue
            msg = item.msg
            msg_names = tuple(str(n) for n in msg.joint_names)
            names = names or msg_names
            points = np.array([[p.x, p.y, p.z] for p in msg.positions], dtype=np.float64)
            skeletons.setdefault(str(msg.body_id), {})[index[stamp]] = dict(zip(msg_names, points))
    frame_sets = np.array([int(s) in tracked_stamps for s in stamps], dtype=bool)
    if not frame_sets.any():
        raise ValueError(f"{tracked}: none of its {len(tracked_stamps)} frame sets is at a stamp "
                         f"of the truth's {len(stamps)}: it tracked another bag")
    ids = tuple(sorted(skeletons, key=_id_order))
    bodies = np.full((len(stamps), len(ids), len(names), 3), np.nan)
    for t, body in enumerate(ids):
        for k, joints in skeletons[body].items():
            bodies[k, t] = [joints.get(n, (np.nan,) * 3) for n in names]
    return TrackedBodies(joint_names=names, body_ids=ids, bodies=bodies, frame_sets=frame_sets,
                         skeletons_elsewhere=elsewhere)


def evaluate_tracked(bag: str | Path, tracked: str | Path, *, max_frames: int | None = None,
                     out=None) -> dict:
    """Score the tracked bag ``tracked`` against ``bag``'s truth (module docstring); returns the
    JSON-ready report, with :func:`~hmocap_ros.eval.mocap_eval.evaluate`'s scores of one method,
    :data:`TRACKED_METHOD`. max_frames: score at most this many frame sets with the subject's
    truth. Raises ValueError (or the bag reader's errors) on bad input."""
    out = sys.stderr if out is None else out
    t0 = time.perf_counter()
    frames = load_truth(bag, max_frames)
    if not frames.has_truth.any():
        raise ValueError(f"{bag}: no frame set with the subject's truth")
    found = read_tracked(tracked, frames.stamps)
    if found.joint_names:
        est_idx, true_idx = match_joints(found.joint_names, frames.joint_names)
        if not len(est_idx):
            raise ValueError(f"{tracked}: none of the skeletons' joints is one of the truth's")
        names = [found.joint_names[i] for i in est_idx]
        bodies = found.bodies[:, :, est_idx]
    else:  # no skeleton at the truth's frame sets: none with a pose
        names, true_idx = list(frames.joint_names), np.arange(len(frames.joint_names))
        bodies = np.full((len(frames.stamps), 0, len(names), 3), np.nan)
    scores = score_tracks(frames, bodies, names, true_idx, found.body_ids)
    missing = int(np.count_nonzero(~found.frame_sets))
    if missing:
        print(f"{Path(tracked).name}: {missing} of the {len(frames.stamps)} frame sets with truth "
              f"are not in the tracked bag (scored as without pose)", file=out)
    report: dict[str, Any] = {
        "bag": str(bag),
        "tracked": str(tracked),
        "frame_sets": int(len(frames.stamps)),
        "frames_with_truth": int(frames.has_truth.sum()),
        "frame_sets_not_tracked": missing,
        "skeletons_elsewhere": found.skeletons_elsewhere,
        "cameras": list(frames.rig.names),
        "max_people": len(found.body_ids),
        "body_ids": list(found.body_ids),
        "methods": {TRACKED_METHOD: scores_record(scores.summary, scores.persons)},
        "wall_seconds": time.perf_counter() - t0,
    }
    return report
