"""``hmocap eval extremities``: the extremity detection of a multi-view bag against its ground truth.

Runs :class:`~hmocap_ros.detection.extremity_pipeline.ExtremityPipeline` (the node's code) on
every frame set of a bag with ground truth (the masks segmented as the foreground node does, or
the bag's silhouettes) and scores, per label, as the detector tests of thesis sec. 2.5:

* **truth**: the limb joints from ``/ground_truth/skeleton``; the head, hands and feet are the
  body's end-effectors (the tracker's: head, the midpoint of head joint and head top; hand, of
  wrist and hand tip; foot, the toe end site) of the true pose (``/ground_truth/joint_states``)
  on the true body shape;
* **precision**: the share of a label's detections within ``radius`` (10 cm) of its truth;
  **recall**: the share of frames with truth where a detection of that label lies within
  ``radius``; **error**: mean and median 3D distance of the label's detections;
* skin candidates are unlabelled: each is counted for the nearest true extremity (head or hand)
  within ``radius``, else as a false detection (precision over all candidates).

The detector runs without the last skeleton (the crops and carving boxes come from the
foregrounds alone), so that the figures do not depend on a tracker.
"""
from __future__ import annotations

import sys

import numpy as np

__all__ = ["evaluate_extremities", "frame_truths", "score_detections", "true_extremities"]

EXTREMITIES = ("left_hand", "right_hand", "head", "left_foot", "right_foot")  # IK end-effector order


def true_extremities(bag, stamps) -> dict:
    """stamp -> (5, 3) the true end-effectors (:data:`EXTREMITIES` order) of the frames with a
    ground-truth pose."""
    from hmocap_ros.body import BodyShape
    from hmocap_ros.body.model import load_body_model
    from hmocap_ros.body.shape_deformation import apply_shape
    from hmocap_ros.io import topics
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.msg_factory import stamp_to_ns
    from hmocap_ros.tracking.ik_proposals import IKProposer

    model = load_body_model("tracking")
    dofs = list(model.skeleton.dof_names)
    wanted = set(int(s) for s in stamps)
    poses = {}
    shape = None
    with BagReader(bag) as reader:
        available = reader.topics()
        if topics.GT_BODY_SHAPE in available:
            msg = reader.first(topics.GT_BODY_SHAPE)
            shape = BodyShape.from_named(msg.entity_names, msg.bone_scale, msg.radial_scale,
                                         msg.global_scale)
        if topics.GT_JOINT_STATES not in available:
            return {}
        for item in reader.messages([topics.GT_JOINT_STATES]):
            stamp = stamp_to_ns(item.msg.header.stamp)
            if stamp not in wanted:
                continue
            by_name = dict(zip(map(str, item.msg.name), item.msg.position))
            if all(d in by_name for d in dofs):
                poses[stamp] = np.array([by_name[d] for d in dofs])
    if not poses:
        return {}
    rest = apply_shape(model, shape)
    keys = sorted(poses)
    ends = IKProposer(model).end_effectors(np.stack([poses[k] for k in keys]), rest)
    return dict(zip(keys, ends))


def _score(dist: list, n_truth: int, radius: float) -> dict:
    d = np.asarray(dist, float)
    hits = d <= radius
    return {"detections": int(len(d)),
            "precision": float(hits.mean()) if len(d) else float("nan"),
            "mean_error_mm": float(1e3 * d.mean()) if len(d) else float("nan"),
            "median_error_mm": float(1e3 * np.median(d)) if len(d) else float("nan"),
            "frames": int(n_truth)}


def frame_truths(frames, ends: dict) -> list[dict]:
    """Per frame set, label -> (3,) true position (limb joints and end-effectors)."""
    from hmocap_ros.detection.detections import MODEL_JOINT

    names = list(frames.joint_names)
    out = []
    for k, stamp in enumerate(frames.stamps):
        truth = {lab: frames.truth[k][names.index(j)] for lab, j in MODEL_JOINT.items()
                 if j in names and np.isfinite(frames.truth[k][names.index(j)]).all()}
        if int(stamp) in ends:
            truth.update(zip(EXTREMITIES, ends[int(stamp)]))
        out.append(truth)
    return out


def score_detections(detections: list, truths: list[dict], radius: float = 0.10) -> dict:
    """Per label precision, recall and 3D error of per-frame detections (module docstring);
    ``detections[k]`` is frame k's Detections or None."""
    from hmocap_ros.detection.detectors import carries_labels
    dist: dict = {}
    found: dict = {}
    n_truth: dict = {}
    false_skin = 0
    for k, (det, truth) in enumerate(zip(detections, truths)):
        for lab in truth:
            n_truth[lab] = n_truth.get(lab, 0) + 1
        if det is None or not truth:
            continue
        if not carries_labels(det):
            upper = [lab for lab in EXTREMITIES[:3] if lab in truth]
            t = np.array([truth[lab] for lab in upper]).reshape(-1, 3)
            for pos in det.positions:
                d = np.linalg.norm(t - pos, axis=1)
                j = int(np.argmin(d)) if len(d) else -1
                if j < 0 or d[j] > radius:
                    false_skin += 1
                    continue
                dist.setdefault(upper[j], []).append(float(d[j]))
                found.setdefault(upper[j], set()).add(k)
            continue
        for lab, pos in zip(det.labels, det.positions):
            if lab not in truth:
                continue
            d = float(np.linalg.norm(pos - truth[lab]))
            dist.setdefault(lab, []).append(d)
            if d <= radius:
                found.setdefault(lab, set()).add(k)
    labels = {}
    for lab in n_truth:
        s = _score(dist.get(lab, []), n_truth[lab], radius)
        s["recall"] = len(found.get(lab, ())) / n_truth[lab]
        if false_skin and lab in EXTREMITIES[:3] and s["detections"]:
            # a skin candidate near no extremity is a false detection of any of them
            s["precision"] = s["precision"] * s["detections"] / (s["detections"] + false_skin)
        labels[lab] = s
    return {"labels": labels, "false_skin_candidates": false_skin}


def evaluate_extremities(bag, detector: str = "keypoints", silhouettes: str = "fg",
                         max_frames: int | None = None, radius: float = 0.10, out=None) -> dict:
    """Score the detector on ``bag`` (module docstring); returns the JSON-ready report."""
    from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams
    from hmocap_ros.eval.mocap_frames import load_frames

    out = sys.stderr if out is None else out
    frames = load_frames(bag, silhouettes, max_frames, out=out,
                         detector=ExtremityDetectionParams(detector=detector))
    assert frames.detections is not None  # load_frames runs the detector it is given on every frame set
    scores = score_detections(frames.detections, frame_truths(frames, true_extremities(
        bag, frames.stamps)), radius)
    return {"bag": str(bag), "detector": detector, "radius_m": radius,
            "silhouettes": frames.silhouettes, "frame_sets": int(len(frames.stamps)),
            "seconds_per_frame_set": frames.detector_s, **scores}
