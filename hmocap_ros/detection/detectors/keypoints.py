"""A 2D landmark network per view, triangulated over the views
(:mod:`hmocap_ros.detection.keypoint_detector`): labelled head, hands, feet and limb joints."""
from __future__ import annotations

from hmocap_ros.detection.detections import Detections
from hmocap_ros.detection.keypoint_detector import KeypointDetector

__all__ = ["KeypointsDetector", "per_body"]


class KeypointsDetector:
    """The landmark network on the crop MediaPipe's pipeline gives it (from the view's
    previous landmarks, the previous skeleton or a pose detector), triangulated robustly over
    the views, with confidences (beyond the thesis, whose sec. 2.5 admits any part detector).
    Each view keeps a track from frame set to frame set (:meth:`reset` drops them). Settings:
    ``params.keypoints``; ``model_path`` the landmark network (None: the shipped one)."""

    name = "keypoints"
    description = "BlazePose landmarks per view, triangulated over the views"
    labelled = True

    def __init__(self, cameras, params, model_path=None):
        self.network = KeypointDetector(tuple(cameras), params.keypoints, model_path)

    @property
    def views_left_out(self) -> dict:
        """Per camera name, the frame sets whose landmarks disagreed with the others."""
        return self.network.views_left_out

    @property
    def views_run(self) -> int:
        """The views whose landmark network ran on the last frame set."""
        return self.network.last_views_run

    def report_other_stages(self, seconds: float) -> None:
        """A frame set's seconds outside the detector (segmentation, tracking), counted when
        ``pose_rate_hz`` chooses the views per set."""
        self.network.other_stages_s = float(seconds)

    def reset(self) -> None:
        self.network.reset()

    def close(self) -> None:
        self.network.close()

    @property
    def people_left_out(self) -> dict:
        """With several people: what was left out and how often (``occluded``, ``other
        person``, ``one view``)."""
        return self.network.people_left_out

    def detect(self, images, masks, previous=None, stamp_ns=None,
               previous_stamp_ns=None) -> Detections:
        """One person's keypoints (``max_people`` 1; ``previous`` that person's skeleton), or
        every person's (``max_people`` > 1; ``previous`` body id -> skeleton), each detection
        with its person (:attr:`Detections.persons`)."""
        if self.network.params.max_people > 1:
            bodies = per_body(previous)
            people = self.network.detect_people(images, masks, bodies, stamp_ns,
                                                previous_stamp_ns)
            return Detections.of_people(self.name, [
                (p.body_id, p.keypoints.labels, p.keypoints.positions, p.keypoints.scores)
                for p in people])
        kp = self.network.detect(images, masks, previous, stamp_ns, previous_stamp_ns)
        return Detections(self.name, tuple(kp.labels), kp.positions, kp.scores)


def per_body(previous: dict | None) -> dict:
    """``previous`` as body id -> skeleton (label -> position); ValueError for one skeleton
    without its body id, which cannot place that body's crops among several people."""
    if not previous:
        return {}
    if all(isinstance(v, dict) for v in previous.values()):
        return previous
    raise ValueError("with several people the previous skeletons come by body id "
                     "(body id -> label -> position)")
