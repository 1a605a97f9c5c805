"""Reading a multi-view bag for the tracker's evaluation: masks, detections and truth.

:func:`load_frames` reads any bag in the documented layout (:mod:`hmocap_ros.io.topics`),
segments each frame set's images with the same foreground model as the live node (or reads the
bag's exact silhouettes), optionally runs the extremity detection of detector-driven tracking on
each frame set (:class:`~hmocap_ros.detection.extremity_pipeline.ExtremityPipeline`, the node's
code, without the last skeleton), and collects the ground truth. Masks are stored bit-packed,
computed once for all methods. :func:`load_truth` reads the truth alone, for scoring bodies
tracked elsewhere (``hmocap eval mocap --tracked``).
"""
from __future__ import annotations

import logging
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hmocap_ros.eval.people_truth import PeopleTruth, PersonViews, read_people

if TYPE_CHECKING:
    from hmocap_ros.body import BodyShape
    from hmocap_ros.geometry.rig import Rig

__all__ = ["SILHOUETTES", "BagFrames", "empty_room_frames", "load_frames", "load_truth"]

log = logging.getLogger(__name__)
#: the silhouettes a bag's frames are evaluated on, as ``hmocap track`` takes them: auto (the
#: first the bag has of the next three), masks (the bag's ``/<camera>/foreground``), fg (the
#: images segmented), gt (the bag's exact silhouettes)
SILHOUETTES = ("auto", "masks", "fg", "gt")


@dataclass
class BagFrames:
    """Everything the evaluation needs from a bag, masks computed once for all methods.

    rig: the cameras; stamps: (F,) frame-set stamps in order; masks: per frame a list of one
    packed mask per camera (``np.packbits`` of ``mask != 0``) or None; truth: (F, J, 3) metres
    (NaN where the frame has no skeleton); joint_names: names of ``truth``'s joints;
    body_shape: the subject's BodyShape or None; silhouettes / fallback: what was used and why.
    segmentation_s: seconds of foreground segmentation per frame set.
    detections: per frame the extremity detection's Detections, when loaded for a method that
    takes them (``kf-hpf``, ``dd-hpf``), else None; detector_s: seconds of extremity detection
    per frame set.
    people_truth: (P, F, J, 3) the truth of every person (:mod:`~hmocap_ros.eval.people_truth`;
    ``people_truth[0]`` is ``truth``); person_ids: their body ids; people_views: (P, F) cameras
    that see each person (:class:`~hmocap_ros.eval.people_truth.PersonViews`), or None when the
    bag has not every person's silhouettes.
    """

    rig: Rig
    stamps: np.ndarray
    masks: list
    truth: np.ndarray
    joint_names: tuple
    body_shape: BodyShape | None
    silhouettes: str
    fallback: str = ""
    segmentation_s: float = 0.0
    shape_hw: tuple = ()
    detections: list | None = None
    detector_s: float = 0.0
    people_truth: np.ndarray | None = None
    person_ids: tuple = ()
    people_views: np.ndarray | None = None

    def mask_list(self, k: int) -> list:
        h, w = self.shape_hw
        out: list[np.ndarray | None] = []
        for packed in self.masks[k]:
            if packed is None:
                out.append(None)
            else:
                out.append(np.unpackbits(packed, count=h * w).reshape(h, w))
        return out

    @property
    def has_truth(self) -> np.ndarray:
        return np.isfinite(self.truth).all(axis=(1, 2))


def _read_truth(reader, available, bag) -> tuple[PeopleTruth, BodyShape | None]:
    """Every person's ground-truth skeletons, and the subject's shape."""
    from hmocap_ros.body import BodyShape
    from hmocap_ros.io import topics

    if topics.GT_SKELETON not in available:
        raise ValueError(f"{bag}: no {topics.GT_SKELETON}: nothing to score against")
    people = read_people(reader, available)
    body_shape: BodyShape | None = None
    if topics.GT_BODY_SHAPE in available:
        shape_msg = reader.first(topics.GT_BODY_SHAPE)
        if shape_msg is not None:
            body_shape = BodyShape.from_named(shape_msg.entity_names, shape_msg.bone_scale,
                                              shape_msg.radial_scale, shape_msg.global_scale)
    return people, body_shape


def empty_room_frames(reader, image_topics, slop_ns: int, first_truth) -> int:
    """Frame sets before the first ground-truth skeleton: the empty room to learn from."""
    n_empty = 0
    for stamp, _ in reader.frame_sets(image_topics, slop_ns, allow_partial=True, min_topics=1):
        if first_truth is not None and stamp >= first_truth:
            break
        n_empty += 1
    return n_empty


def _mask_row(use, msgs, stamp, bg, rgb_of) -> list:
    """One mask per camera of a frame set (segmented, or the bag's silhouette), or None."""
    from hmocap_ros.io.image_codec import decoded_image

    row: list[np.ndarray | None] = []
    for k, topic in enumerate(use):
        msg = msgs.get(topic)
        if msg is None:
            row.append(None)
            continue
        try:
            if bg is not None:
                mask = bg[k].apply(rgb_of(topic), stamp)
            else:
                mask = decoded_image(msg)
                mask = mask[..., 0] if mask.ndim == 3 else mask
        except ValueError as err:
            log.warning("frame %d, %s: %s (view dropped)", stamp, topic, err)
            row.append(None)
            continue
        row.append(mask)
    return row


def _frame_sets(reader, use, use_present, pipeline, image_topics, slop_ns: int, bg,
                people: PeopleTruth, views: PersonViews | None, max_frames: int | None):
    """Every frame set's packed masks of the ``use`` topics (those in the bag:
    ``use_present``), its detections when ``pipeline`` (an ExtremityPipeline) is given, its
    truth of every person (``people``), the cameras that see each (when ``views``) and the
    timing: ``(stamps, masks, truth, detections, shape_hw, segmentation s, detection s,
    people truth, people views)``."""
    from hmocap_ros.io.image_codec import decoded_rgb

    stamps, masks, truth, people_rows, views_rows = [], [], [], [], []
    truth_by_stamp = people.by_stamp[0]
    detections: list | None = [] if pipeline is not None else None
    shape_hw: tuple = ()
    seg_time = det_time = 0.0
    n_truth = 0
    read = list(use_present)
    if pipeline is not None:
        read += [t for t in image_topics if t not in read and t in reader.topics(compressed_as_raw=True)]
    if views is not None:
        read += [t for t in views.topics if t not in read]
    for stamp, msgs in reader.frame_sets(read, slop_ns, allow_partial=True, min_topics=1):
        decoded: dict = {}  # each image decoded once, for its mask and its detections

        def rgb_of(topic: str, decoded: dict = decoded, msgs: dict = msgs) -> np.ndarray:
            if topic not in decoded:
                decoded[topic] = decoded_rgb(msgs[topic])
            return decoded[topic]

        t0 = time.perf_counter()
        row = []
        full = _mask_row(use, msgs, stamp, bg, rgb_of)
        for mask in full:
            if mask is not None:
                shape_hw = shape_hw or mask.shape[:2]
            row.append(np.packbits(mask != 0) if mask is not None
                       and mask.shape[:2] == shape_hw else None)
        seg_time += time.perf_counter() - t0
        if detections is not None:
            t0 = time.perf_counter()
            detections.append(_detect(pipeline, image_topics, msgs, stamp, rgb_of, full))
            det_time += time.perf_counter() - t0
        stamps.append(stamp)
        masks.append(row)
        gt = truth_by_stamp.get(stamp)
        people_rows.append(people.row(stamp))
        truth.append(people_rows[-1][0])
        if views is not None:
            views_rows.append(views.count(people_rows[-1], msgs))
        if gt is not None:
            n_truth += 1
            if max_frames is not None and n_truth >= max_frames:
                break
    return (stamps, masks, truth, detections, shape_hw, seg_time, det_time, people_rows,
            views_rows)


def _detect(pipeline, image_topics, msgs, stamp, rgb_of, masks):
    """The frame set's detections (the node's code), or None when it cannot run."""
    images = []
    for topic in image_topics:
        try:
            images.append(rgb_of(topic) if topic in msgs else None)
        except ValueError as err:
            log.warning("frame %d, %s: %s (no detections from this view)", stamp, topic, err)
            images.append(None)
    try:
        return pipeline.detect(images, list(masks))
    except ValueError as err:
        log.warning("frame %d: extremity detection failed: %s", stamp, err)
        return None


def load_frames(bag: str | Path, silhouettes: str = "fg", max_frames: int | None = None,
                slop_ns: int = 0, fg_params: dict | None = None, out=None,
                detector=None, rig=None) -> BagFrames:
    """Read a bag, segment (or read) the silhouettes of every frame set, collect the truth.

    silhouettes: one of :data:`SILHOUETTES`. max_frames: stop after this many frame sets with
    a ground-truth skeleton. fg_params: ForegroundParams fields to override. The background is learnt as ``fg_params``'s
    ``learn_from`` says, by default from the bag's empty-room frames (the frames before the
    first skeleton: ``learn_frames`` is set from them) and, in a bag without them, where the
    landmark network's person masks leave the room free (``person_masks``); ``empty_room``
    asked for on a bag without an empty room falls back to the exact silhouettes.
    detector: ExtremityDetectionParams: also run the extremity detection on every frame set
    (the detections of detector-driven tracking), or None. rig: the cameras to track with
    instead of the bag's ``/camera_rig`` (e.g. a calibrated rig), with the bag's camera names.
    """
    from hmocap_ros.io import topics
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.rig_messages import rig_from_msg
    from hmocap_ros.segmentation import ForegroundParams, background_models

    out = sys.stderr if out is None else out
    given_rig = rig
    fg_params = dict(fg_params or {})
    learn_from = fg_params.pop("learn_from", None)
    if silhouettes not in SILHOUETTES:
        raise ValueError(f"silhouettes must be one of {', '.join(SILHOUETTES)}, "
                         f"got {silhouettes!r}")
    with BagReader(bag) as reader:
        available = reader.topics(compressed_as_raw=True)
        rig_msg = reader.first(topics.CAMERA_RIG) if topics.CAMERA_RIG in available else None
        if rig_msg is None:
            raise ValueError(f"{bag}: no {topics.CAMERA_RIG} message: the cameras are unknown")
        rig = bag_rig = rig_from_msg(rig_msg)
        if rig is not None and given_rig is not None:
            if set(given_rig.names) != set(rig.names):
                raise ValueError(f"the rig's cameras ({', '.join(given_rig.names)}) are not the "
                                 f"bag's ({', '.join(rig.names)})")
            rig = type(given_rig)(given_rig.frame_id, tuple(given_rig[n] for n in rig.names))
        people, body_shape = _read_truth(reader, available, bag)
        truth_by_stamp, joint_names = people.by_stamp[0], people.joint_names
        views: PersonViews | None = None
        if bag_rig is not None:  # the truth's cameras, whatever rig the tracker is given
            views = PersonViews(bag_rig, joint_names, len(people.ids), available)
            views = views if views.known else None
        names = rig.names
        image_topics = [topics.camera_image(n) for n in names]
        gt_topics = [topics.gt_silhouette(n) for n in names]
        mask_topics = [topics.camera_foreground(n) for n in names]
        present_images = [t for t in image_topics if t in available]
        if silhouettes == "auto":  # the first the bag has, as hmocap track's
            silhouettes = next((kind for kind, ts in (("masks", mask_topics), ("fg", image_topics),
                                                      ("gt", gt_topics))
                                if any(t in available for t in ts)), "fg")
        if not present_images and silhouettes == "fg":
            raise ValueError(f"{bag}: none of the image topics {image_topics} is in the bag")
        fallback = ""
        if silhouettes == "fg":
            n_empty = empty_room_frames(reader, present_images, slop_ns,
                                         min(truth_by_stamp) if truth_by_stamp else None)
            if learn_from is None:
                learn_from = "empty_room" if n_empty else "person_masks"
                if not n_empty:
                    fallback = ("the bag has no empty-room frames before the subject appears: the "
                                "background is learnt where the person masks leave the room free")
                    print(f"hmocap eval mocap: {fallback}", file=out)
            elif learn_from == "empty_room" and n_empty == 0:
                fallback = ("the bag has no empty-room frames before the subject appears, so no "
                            "background model can learn from an empty room: using the "
                            "ground-truth silhouettes")
                silhouettes = "gt"
                print(f"hmocap eval mocap: {fallback}", file=out)
        use = {"gt": gt_topics, "masks": mask_topics}.get(silhouettes, image_topics)
        use_present = [t for t in use if t in available]
        if not use_present:
            what = {"gt": "silhouette", "masks": "foreground"}.get(silhouettes, "image")
            raise ValueError(f"{bag}: no {what} topics ({use})")
        bg = None
        if silhouettes == "fg":
            if learn_from == "empty_room":
                fg_params["learn_frames"] = int(np.clip(n_empty, 1, 100))
            bg = background_models(ForegroundParams(**{**fg_params, "learn_from": learn_from}),
                                   names)
        pipeline = None
        if detector is not None:
            from hmocap_ros.detection.extremity_pipeline import ExtremityPipeline

            pipeline = ExtremityPipeline(rig.cameras, detector)
        frames = _frame_sets(reader, use, use_present, pipeline, image_topics, slop_ns,
                             bg, people, views, max_frames)
    stamps, masks, truth, detections, shape_hw, seg_time, det_time, people_rows, views_rows = frames
    n_people, n_joints = len(people.ids), len(joint_names)
    return BagFrames(rig=rig, stamps=np.asarray(stamps, dtype=np.int64), masks=masks,
                     truth=np.stack(truth) if truth else np.zeros((0, len(joint_names), 3)),
                     joint_names=joint_names, body_shape=body_shape, silhouettes=silhouettes,
                     fallback=fallback, segmentation_s=seg_time / max(len(stamps), 1),
                     shape_hw=tuple(shape_hw), detections=detections,
                     detector_s=det_time / max(len(stamps), 1),
                     people_truth=(np.stack(people_rows, axis=1) if people_rows
                                   else np.zeros((n_people, 0, n_joints, 3))),
                     person_ids=people.ids,
                     people_views=(None if views is None
                                   else np.stack(views_rows, axis=1) if views_rows
                                   else np.zeros((n_people, 0), dtype=np.int64)))


def load_truth(bag: str | Path, max_frames: int | None = None) -> BagFrames:
    """The ground truth of ``bag`` without its images: one frame set per stamp at which any
    person has truth, in order, with the cameras that see each person where the bag has every
    person's silhouettes (as :func:`load_frames` counts them); no masks (``silhouettes`` "").
    max_frames: stop after this many frame sets with the subject's truth."""
    from hmocap_ros.io import topics
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.rig_messages import rig_from_msg

    with BagReader(bag) as reader:
        available = reader.topics(compressed_as_raw=True)
        rig_msg = reader.first(topics.CAMERA_RIG) if topics.CAMERA_RIG in available else None
        if rig_msg is None:
            raise ValueError(f"{bag}: no {topics.CAMERA_RIG} message: the cameras are unknown")
        rig = rig_from_msg(rig_msg)
        people, body_shape = _read_truth(reader, available, bag)
        stamps = sorted(set().union(*(set(by_stamp) for by_stamp in people.by_stamp)))
        if max_frames is not None:
            with_subject = np.cumsum([s in people.by_stamp[0] for s in stamps])
            stamps = stamps[:int(np.searchsorted(with_subject, max_frames)) + 1]
        rows = [people.row(s) for s in stamps]
        n_people, n_joints = len(people.ids), len(people.joint_names)
        truth = (np.stack(rows, axis=1) if rows else np.zeros((n_people, 0, n_joints, 3)))
        views = PersonViews(rig, people.joint_names, n_people, available)
        seen = None
        if views.known:
            seen = np.zeros((n_people, len(stamps)), dtype=np.int64)
            index = {s: k for k, s in enumerate(stamps)}
            for stamp, msgs in reader.frame_sets(views.topics, 0, allow_partial=True,
                                                 min_topics=1):
                if stamp in index:
                    seen[:, index[stamp]] = views.count(rows[index[stamp]], msgs)
    return BagFrames(rig=rig, stamps=np.asarray(stamps, dtype=np.int64), masks=[[] for _ in stamps],
                     truth=truth[0], joint_names=people.joint_names, body_shape=body_shape,
                     silhouettes="", people_truth=truth, person_ids=people.ids, people_views=seen)
