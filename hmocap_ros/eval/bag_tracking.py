"""The body tracker on a multi-view bag, into a bag (``hmocap track``, ``hmocap eval consistency``).

Runs the code of the nodes (no DDS; deterministic for a ``seed``) over every frame set of a
bag in the documented layout (:mod:`hmocap_ros.io.topics`; the rig from ``/camera_rig`` or
``rig_file``), and writes what ``body_tracker`` publishes
(:class:`~hmocap_ros.tracking.tracker_messages.TrackerMessages` and
:class:`~hmocap_ros.rep155.body_outputs.Rep155Outputs`): ``/humans/bodies/tracked``,
``/humans/bodies/<id>/joint_states`` (the URDF's joints, then the tracker's DoFs),
``/humans/bodies/<id>/urdf``, ``/humans/bodies/<id>/body_shape`` and ``/body_shape`` (latched),
``/humans/bodies/<id>/skeleton2d``, ``roi``, ``position`` and ``velocity``, ``/skeleton``,
``/skeleton_markers`` and ``/tf``, each stamped with its frame set's stamp and logged at it.
With a method that uses detections (``dd-hpf``) the extremity
detection (:class:`~hmocap_ros.detection.extremity_pipeline.ExtremityPipeline`, the
``extremity_detection`` node's code, fed back the last skeleton as the node is) runs on every
frame set too, and its ``/extremities`` go into the bag, with the landmark network on a fixed
``keypoints.views_per_set`` (``pose_rate_hz`` 0, not the live nodes' cost-driven choice, so
that a run repeats). No ground truth is needed.

Foreground (``silhouettes``): ``masks``: the bag's ``/<camera>/foreground`` (a recording of
``foreground_segmentation``); ``fg``: the images segmented as the foreground node does (a
background model per camera, :func:`~hmocap_ros.segmentation.background_models`); ``gt``: the
bag's exact silhouettes ``/ground_truth/<camera>/silhouette``. ``auto`` (default) takes the
first of these the bag has. The background of ``fg`` is learnt as ``learn_from`` says:
``empty_room`` from the first ``learn_frames`` frames, ``person_masks`` where the landmark
network's person masks leave the room free (no empty room needed). By default: in a bag with
ground truth that starts with an empty room, from the frames before the first skeleton (as
``hmocap eval mocap`` does); with ``learn_frames``, from that many first frames; else (a
recording without ground truth, or one whose subject is there from the first frame)
``person_masks``, since nothing says the room is empty at the start.

Frame sets are grouped by stamp as ``body_tracker`` groups them (``slop_ms`` 5, at least
``min_views_to_sync`` 2 views); a missing view is a dropped camera. Bad input (no rig, no foreground
source, no frame set) raises :class:`TrackError` with one line for the user. The bag is
written whole or not at all.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import NotRequired, TypedDict

import numpy as np

__all__ = ["MIN_VIEWS", "SILHOUETTES", "SLOP_MS", "TrackError", "track_to_bag"]

#: body_tracker's defaults: stamp spread (ms) within a frame set, and the fewest views of a set
SLOP_MS = 5.0
MIN_VIEWS = 2
SILHOUETTES = ("auto", "masks", "fg", "gt")
PROGRESS_PERIOD_S = 2.0
EXTREMITIES_TOPIC = "/extremities"


class TrackCounts(TypedDict):
    """What :func:`track_to_bag` returns (see there)."""

    frame_sets: int
    with_pose: int
    notes: list[str]
    warnings: dict[str, int]
    topics: dict[str, int]
    silhouettes: NotRequired[str]  # set once the bag is open and the source chosen
    people_left_out: NotRequired[dict[str, int]]  # with several people: the keypoint stage's


class TrackError(ValueError):
    """Bad input of ``hmocap track`` (one line for the user)."""


@dataclass
class _Source:
    """Where the masks come from: ``kind`` (masks, fg, gt), one topic per camera, a note."""

    kind: str
    topics: list
    note: str = ""
    learn_frames: int = 0
    learn_from: str = "empty_room"


def _source(bag, available: dict, rig, wanted: str) -> _Source:
    """The mask source of ``--silhouettes`` (module docstring); ``fg`` in a bag with ground
    truth is marked for :func:`_learn_frames` to look for its empty room."""
    from hmocap_ros.io import topics

    names = rig.names
    by_kind = {"masks": [topics.camera_foreground(n) for n in names],
               "fg": [topics.camera_image(n) for n in names],
               "gt": [topics.gt_silhouette(n) for n in names]}
    present = {kind: [t for t in ts if t in available] for kind, ts in by_kind.items()}
    if wanted != "auto":
        if not present[wanted]:
            raise TrackError(f"{bag}: none of {', '.join(by_kind[wanted])} is in the bag "
                             f"(--silhouettes {wanted})")
        kinds = [wanted]
    else:
        kinds = [kind for kind in ("masks", "fg", "gt") if present[kind]]
    if kinds:
        truth = kinds[0] == "fg" and topics.GT_SKELETON in available
        return _Source(kinds[0], by_kind[kinds[0]], note="truth" if truth else "")
    raise TrackError(f"{bag}: no foreground masks, images or silhouettes of the rig's cameras "
                     f"({', '.join(names)}) in the bag")


def _learn_frames(reader, source: _Source, requested: int | None,
                  learn_from: str | None) -> _Source:
    """Settle how the background model of ``fg`` learns (module docstring)."""
    from hmocap_ros.eval.mocap_frames import empty_room_frames
    from hmocap_ros.io import topics
    from hmocap_ros.io.msg_factory import stamp_to_ns
    from hmocap_ros.segmentation import ForegroundParams

    if source.kind != "fg":
        return source
    source.learn_frames = ForegroundParams().learn_frames if requested is None else requested
    truth = source.note == "truth"
    source.note = ""
    if learn_from == "person_masks" or (learn_from is None and requested is None and not truth):
        source.learn_from = "person_masks"
        if learn_from is None:
            source.note = ("nothing says the recording starts with an empty room: the background "
                           "is learnt where the person masks leave the room free (--learn-from "
                           "empty_room to learn it from the first --learn-frames frames)")
        return source
    if requested is not None or learn_from == "empty_room" and not truth:
        return source
    first = stamp_to_ns(reader.first(topics.GT_SKELETON).header.stamp)
    present = [t for t in source.topics if t in reader.topics(compressed_as_raw=True)]
    n_empty = empty_room_frames(reader, present, int(SLOP_MS * 1e6), first)
    if n_empty > 0:
        source.learn_frames = int(np.clip(n_empty, 1, 100))
        source.note = f"learning the background from the {source.learn_frames} frames before the subject"
    elif learn_from is None:
        source.learn_from = "person_masks"
        source.note = ("the bag has no empty-room frames before the subject appears: the background "
                       "is learnt where the person masks leave the room free")
    else:
        source.note = (f"the bag has no empty-room frames before the subject appears: the "
                       f"background is learnt from its first {source.learn_frames} frames, the "
                       f"subject with it")
    return source


def _given_masks(source: _Source, rig, msgs: dict, warn) -> list:
    """The bag's mask of each camera of a frame set (None: a dropped view)."""
    from hmocap_ros.io.image_codec import decoded_mono

    out: list[np.ndarray | None] = []
    for cam, topic in zip(rig.cameras, source.topics):
        if topic not in msgs:
            out.append(None)
            continue
        try:
            mask = decoded_mono(msgs[topic])
        except ValueError as err:  # ConversionError is one
            warn(f"{topic}: {err} (view dropped)")
            out.append(None)
            continue
        if mask.shape != (cam.height, cam.width):
            warn(f"{topic}: {mask.shape[1]}x{mask.shape[0]}, the rig says {cam.width}x{cam.height} (view dropped)")
            out.append(None)
            continue
        out.append(mask)
    return out


def _images(topics_: list, msgs: dict, warn, what: str) -> list:
    """Each camera's RGB image of a frame set (None: missing or not decodable, warned of)."""
    from hmocap_ros.io.image_codec import decoded_rgb

    out: list[np.ndarray | None] = []
    for topic in topics_:
        image = None
        if topic in msgs:
            try:
                image = decoded_rgb(msgs[topic])
            except ValueError as err:
                warn(f"{topic}: {err} ({what})")
        out.append(image)
    return out


def _extremities_msg(det, stamp_ns: int, frame_id: str, factory):
    from hmocap_ros.io.msg_factory import make_header

    def vectors(kind, rows):
        return [factory.make(kind, x=float(x), y=float(y), z=float(z)) for x, y, z in rows]

    return factory.make("hmocap_interfaces/msg/Extremities", header=make_header(factory, stamp_ns, frame_id),
                        detector=det.detector, labels=list(det.labels),
                        positions=vectors("geometry_msgs/msg/Point", det.positions),
                        normals=vectors("geometry_msgs/msg/Vector3", np.nan_to_num(det.normals)),
                        scores=np.asarray(det.scores, np.float32),
                        persons=np.asarray([] if det.persons is None else det.persons, np.int32),
                        person_ids=list(det.person_ids) if det.persons is not None else [])


def track_to_bag(bag, out, *, method: str | None = None, detector: str | None = None,
                 silhouettes: str = "auto", learn_frames: int | None = None,
                 learn_from: str | None = None, max_people: int = 1,
                 seed: int = 0, overrides: dict | None = None, body_id: str = "b0",
                 publish_tf: bool = True, rig_file: str | None = None, max_frames: int | None = None,
                 progress=None, detection_overrides: dict | None = None) -> TrackCounts:
    """Track every frame set of ``bag`` and write body_tracker's messages to the new bag ``out``
    (module docstring). Returns ``frame_sets``, ``with_pose`` (frame sets with a body),
    ``silhouettes`` (the source used), ``notes``, ``warnings`` (text -> count) and ``topics``
    (topic -> messages written). ``detection_overrides``: extremity detection settings by dotted
    name (``keypoints.views_per_set``, ...). :class:`TrackError` for bad input."""
    from hmocap_ros.body import load_body_model
    from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams
    from hmocap_ros.detection.keypoint_network import ModelFileError
    from hmocap_ros.eval.mocap_eval import method_params
    from hmocap_ros.geometry.rig import RigError, load_rig
    from hmocap_ros.io import topics
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.bag_writer import LATCHED, whole_bag
    from hmocap_ros.io.msg_factory import RosbagsFactory
    from hmocap_ros.io.rig_messages import rig_from_msg
    from hmocap_ros.params import replace_dotted
    from hmocap_ros.rep155.body_outputs import Rep155Outputs
    from hmocap_ros.room_pipeline import RoomPipeline
    from hmocap_ros.segmentation import ForegroundParams
    from hmocap_ros.tracking.params import TrackerParams
    from hmocap_ros.tracking.people_tracker import body_ids
    from hmocap_ros.tracking.tracker_messages import TrackerMessages, latched_topics

    if silhouettes not in SILHOUETTES:
        raise TrackError(f"--silhouettes must be one of {', '.join(SILHOUETTES)}, got {silhouettes!r}")
    if max_people < 1:
        raise TrackError(f"--max-people must be >= 1, got {max_people}")
    if learn_frames is not None and learn_frames < 1:
        raise TrackError(f"--learn-frames must be >= 1, got {learn_frames}")
    params = method_params(method or TrackerParams().method, overrides=overrides)
    counts: TrackCounts = {"frame_sets": 0, "with_pose": 0, "notes": [], "warnings": {}, "topics": {}}
    detection_params = ExtremityDetectionParams(detector=detector) if detector else ExtremityDetectionParams()
    # the views per set fixed (keypoints.views_per_set), not by the machine's speed: a run repeats
    detection_params = replace_dotted(detection_params, {"keypoints.pose_rate_hz": 0.0,
                                                         **(detection_overrides or {})})

    def warn(text: str) -> None:
        counts["warnings"][text] = counts["warnings"].get(text, 0) + 1

    with BagReader(bag) as reader:
        available = reader.topics(compressed_as_raw=True)
        if rig_file:
            try:
                rig = load_rig(rig_file)
            except (RigError, OSError) as err:
                raise TrackError(f"cannot load the rig {rig_file}: {err}") from err
        else:
            rig_msg = reader.first(topics.CAMERA_RIG) if topics.CAMERA_RIG in available else None
            if rig_msg is None:
                raise TrackError(f"{bag}: no {topics.CAMERA_RIG} message: the cameras are unknown "
                                 f"(give the rig file with --rig)")
            rig = rig_from_msg(rig_msg)
        source = _learn_frames(reader, _source(bag, available, rig, silhouettes), learn_frames,
                               learn_from)
        if source.note:
            counts["notes"].append(source.note)
        counts["silhouettes"] = source.kind
        image_topics = [topics.camera_image(n) for n in rig.names]
        detection = None
        if params.tracking_method.uses_detector:
            if any(t in available for t in image_topics):
                detection = detection_params
            else:
                counts["notes"].append(f"no images in the bag: {params.method} runs without detections")
        fg = (ForegroundParams(learn_frames=source.learn_frames, learn_from=source.learn_from)
              if source.kind == "fg" else None)
        ids = body_ids(body_id, max_people)
        model = load_body_model("tracking")
        try:
            room = RoomPipeline(rig, params, model, np.random.default_rng(seed), foreground=fg,
                                detection=detection, max_people=max_people, ids=ids)
        except ModelFileError as err:
            raise TrackError(str(err)) from err
        read = [t for t in source.topics if t in available]
        if room.detector is not None:
            read += [t for t in image_topics if t in available and t not in read]
        total = max(available[t].count for t in read)
        factory = RosbagsFactory()
        builder = TrackerMessages(model, ids, rig.frame_id, factory, publish_tf=publish_tf)
        rep155 = Rep155Outputs(ids, rig.frame_id, rig.cameras, factory)
        latched = {"/" + t for t in latched_topics(ids)}
        last_report = time.monotonic()
        with whole_bag(out) as writer:
            for topic in sorted(latched):
                writer.add_topic(topic, "hmocap_interfaces/msg/BodyShape", LATCHED)
            for body in ids:
                writer.add_topic(f"/humans/bodies/{body}/urdf", "std_msgs/msg/String", LATCHED)
            for stamp, msgs in reader.frame_sets(read, int(SLOP_MS * 1e6), allow_partial=True,
                                                 min_topics=min(MIN_VIEWS, len(read))):
                images = None
                if source.kind == "fg" or room.detector is not None:
                    images = _images(image_topics, msgs, warn, "view dropped" if source.kind == "fg"
                                     else "no detections from this view")
                given = _given_masks(source, rig, msgs, warn) if source.kind != "fg" else None
                step = room.step(int(stamp), images, given)
                if given is None:
                    for k, reason in room.dropped:
                        warn(f"{image_topics[k]}: {reason} (view dropped)")
                if step.detections is not None:
                    writer.write(EXTREMITIES_TOPIC, _extremities_msg(step.detections, stamp, rig.frame_id,
                                                                     factory), stamp)
                results = step.results
                models = [t.model for t in room.people.trackers]
                built = builder.frame_set(int(stamp), results, models)
                for error in built.errors:
                    warn(error)
                heights = [float(r.shape.height(m)) if r.shape is not None else float("nan")
                           for r, m in zip(results, models)]
                for topic, msg in rep155.messages(int(stamp), results, heights, built.messages):
                    writer.write(topic if topic.startswith("/") else "/" + topic, msg, stamp)
                counts["frame_sets"] += 1
                counts["with_pose"] += any(r.has_pose for r in results)
                if progress is not None and time.monotonic() - last_report >= PROGRESS_PERIOD_S:
                    last_report = time.monotonic()
                    progress(f"{counts['frame_sets']}/{total} frame sets, "
                             + ", ".join(f"{b}: {r.state}" for b, r in zip(ids, results)))
                if max_frames is not None and counts["frame_sets"] >= max_frames:
                    break
            if counts["frame_sets"] == 0:
                raise TrackError(f"{bag}: no frame set with {min(MIN_VIEWS, len(read))} views on "
                                 f"{', '.join(read)}")
            counts["topics"] = {t: n for t, n in writer.counts.items() if n}
            if room.detector is not None:
                counts["people_left_out"] = dict(getattr(room.detector.detector, "people_left_out", {}))
    return counts
