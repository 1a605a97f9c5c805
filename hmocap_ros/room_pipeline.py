"""The room pipeline: segmentation -> keypoints -> tracker on one frame set, the skeleton fed back.

The one composition of the body stages (STYLE 20): the composed node ``room_pipeline`` runs it
on live frame sets in one process, and ``hmocap track`` (:func:`~hmocap_ros.eval.bag_tracking.
track_to_bag`) on every frame set of a bag. A frame set's images go through the cameras'
background models (:func:`~hmocap_ros.segmentation.background_models`, the
``foreground_segmentation`` node's code) unless its masks are given, then through the extremity
detection (:class:`~hmocap_ros.detection.extremity_pipeline.ExtremityPipeline`, the
``extremity_detection`` node's code) when the tracking method takes detections, with the last
skeleton placing the crops, then through the trackers of the room's people
(:class:`~hmocap_ros.tracking.people_tracker.PeopleTracker`, ``body_tracker``'s code). No rclpy.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from hmocap_ros.detection.detections import Detections
from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams, ExtremityPipeline, skeleton_labels
from hmocap_ros.geometry.rig import Rig
from hmocap_ros.segmentation import ForegroundParams, background_models
from hmocap_ros.tracking.params import TrackerParams
from hmocap_ros.tracking.people_tracker import PeopleTracker

__all__ = ["RoomPipeline", "RoomStep"]


@dataclass
class RoomStep:
    """What one frame set gave: its masks (None: a view missing), its detections (None: the
    method takes none, or no image came), one tracker result per body slot, and the seconds
    each stage took (``segmentation``, ``detection``, ``tracking``)."""

    stamp_ns: int
    masks: list
    detections: Detections | None
    results: list
    seconds: dict = field(default_factory=dict)


class RoomPipeline:
    """Segmentation, extremity detection and tracking of one rig's frame sets (module docstring).

    rig: the cameras; tracker: the trackers' settings (its method says whether detections are
    used); foreground: the background models' settings, or None when every frame set's masks
    are given; detection: the extremity detection's settings (None: no detection, as for a
    method that takes none) and model_path its network file; model: the tracking body; rng: slot 0's generator;
    max_people, ids: the body slots (:class:`~hmocap_ros.tracking.people_tracker.PeopleTracker`).
    A missing or corrupt network file raises :class:`~hmocap_ros.detection.tflite_model.
    ModelFileError` here.
    """

    def __init__(self, rig: Rig, tracker: TrackerParams, model, rng: np.random.Generator, *,
                 foreground: ForegroundParams | None = None,
                 detection: ExtremityDetectionParams | None = None, model_path=None,
                 max_people: int = 1, ids: Sequence[str] | None = None) -> None:
        self.rig = rig
        self.backgrounds = background_models(foreground, rig.names) if foreground is not None else None
        if detection is not None and detection.keypoints.max_people != max_people:
            # the keypoint stage follows the people the trackers follow
            detection = replace(detection, keypoints=replace(detection.keypoints,
                                                             max_people=max_people))
        self.detector = (ExtremityPipeline(rig.cameras, detection, model_path)
                         if detection is not None and tracker.tracking_method.uses_detector else None)
        self.people = PeopleTracker(model, rig, tracker, rng, max_people=max_people, ids=ids)
        #: the last skeleton (label -> room position; with several people, body id -> skeleton),
        #: which places the next frame set's crops, and its stamp
        self.previous: dict | None = None
        self.previous_stamp_ns: int | None = None
        #: the views :meth:`segment` dropped from its last frame set: (camera index, reason)
        self.dropped: list[tuple[int, str]] = []

    def segment(self, stamp_ns: int, images: Sequence[np.ndarray | None]) -> list:
        """The cameras' masks of a frame set's RGB images: None where an image is missing, or
        where its background model refuses it or its size is not the rig's (the reason in
        :attr:`dropped`, as ``(camera index, reason)``)."""
        if self.backgrounds is None:
            raise ValueError("this room pipeline segments nothing: its masks must be given")
        self.dropped = []
        masks: list[np.ndarray | None] = []
        for k, (cam, model, image) in enumerate(zip(self.rig.cameras, self.backgrounds, images)):
            mask = None
            if image is not None:
                try:
                    mask = model.apply(image, stamp_ns)
                except ValueError as err:  # a size other than the one learnt, a stamp gone back
                    self.dropped.append((k, str(err)))
            if mask is not None and mask.shape != (cam.height, cam.width):
                self.dropped.append((k, f"{mask.shape[1]}x{mask.shape[0]}, the rig says {cam.width}x{cam.height}"))
                mask = None
            masks.append(mask)
        return masks

    def step(self, stamp_ns: int, images: Sequence[np.ndarray | None] | None = None,
             masks: Sequence[np.ndarray | None] | None = None,
             budget_s: float | None = None) -> RoomStep:
        """One frame set: its RGB images (per camera, None where missing; None when there
        are none) and, when not segmented here, its masks. budget_s: seconds each body slot
        may take (:meth:`~hmocap_ros.tracking.body_tracker.BodyTracker.update`)."""
        seconds = {}
        t0 = time.perf_counter()
        if masks is None:
            if images is None:
                raise ValueError("a frame set needs images or masks")
            masks = self.segment(stamp_ns, images)
            seconds["segmentation"] = time.perf_counter() - t0
        masks = list(masks)
        detections = None
        if self.detector is not None and images is not None:
            t1 = time.perf_counter()
            detections = self.detector.detect(list(images), masks, self.previous, int(stamp_ns),
                                              self.previous_stamp_ns)
            seconds["detection"] = time.perf_counter() - t1
        t2 = time.perf_counter()
        results = self.people.update(masks, int(stamp_ns), detections, budget_s)
        seconds["tracking"] = time.perf_counter() - t2
        posed = [r for r in results if r.has_pose]
        self.previous = self.previous_stamp_ns = None
        if posed and self.people.max_people > 1:
            self.previous = {body: skeleton_labels(list(r.joint_names), r.joints)
                             for body, r in zip(self.people.ids, results)
                             if r.has_pose and r.joints is not None}
            self.previous_stamp_ns = int(stamp_ns)
        elif posed:
            assert posed[0].joints is not None  # has_pose
            self.previous = skeleton_labels(list(posed[0].joint_names), posed[0].joints)
            self.previous_stamp_ns = int(stamp_ns)
        if self.detector is not None:  # what the keypoint stage's views per set leave room for
            self.detector.report_other_stages(seconds.get("segmentation", 0.0) + seconds["tracking"])
        return RoomStep(int(stamp_ns), masks, detections, results, seconds)

    def saw(self, stamps_ns: Sequence[int]) -> None:
        """Frame sets skipped to keep up: their stamps still measure the frame period."""
        self.people.saw(stamps_ns)

    def reset(self) -> None:
        """The stream started over: tracks, crops and the last skeleton go (body shapes and
        the backgrounds stay)."""
        self.people.reset(forget_shape=False)
        if self.detector is not None:
            self.detector.reset()
        self.previous = self.previous_stamp_ns = None

    def close(self) -> None:
        """Stop the detector's worker threads."""
        if self.detector is not None:
            self.detector.close()
