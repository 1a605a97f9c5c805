"""The person's mask in a view from the landmark network's segmentation output (no rclpy).

BlazePose's landmark network (:mod:`hmocap_ros.detection.keypoint_network`) outputs, besides
the landmarks, a segmentation of the person over its crop. :class:`PersonMasks` runs it on each
camera's image with the crop the landmark pipeline would use (:mod:`hmocap_ros.detection`):
the pose detector places a camera's first crop, the camera's own landmarks (auxiliary points
33 and 34, MediaPipe's ``pose_landmarks_to_roi``) the next ones; a pose presence below
``min_pose_score`` means nobody, and the next call asks the detector again. One instance serves
several cameras (a crop track per camera key) on one network.
"""
from __future__ import annotations

import numpy as np

__all__ = ["PersonMasks"]


class PersonMasks:
    """Per camera the probability that each pixel is the person (module docstring).

    ``threads``: LiteRT threads of the network and the detector; ``min_pose_score``: the pose
    presence below which a view shows nobody; ``min_detection_score``: the detector's.
    :class:`~hmocap_ros.detection.tflite_model.ModelFileError` when a model file is missing or
    corrupt. Not thread-safe.
    """

    def __init__(self, threads: int = 1, min_pose_score: float = 0.5,
                 min_detection_score: float = 0.5, model_path=None, detector_path=None):
        from hmocap_ros.detection.keypoint_network import PoseLandmarkNetwork
        from hmocap_ros.detection.pose_detector import PoseDetector

        self._network = PoseLandmarkNetwork(model_path, threads, segmentation=True)
        self._detector = PoseDetector(detector_path, threads, min_detection_score)
        self.min_pose_score = float(min_pose_score)
        self._tracks: dict = {}
        self.runs = 0

    def reset(self, key=None) -> None:
        """Forget the crop of camera ``key`` (every camera's when None)."""
        if key is None:
            self._tracks.clear()
        else:
            self._tracks.pop(key, None)

    def probability(self, key, image_rgb: np.ndarray) -> np.ndarray | None:
        """Float32 ``(H, W)`` in [0, 1]: the person's segmentation in camera ``key``'s RGB uint8
        image, or None when nobody is there."""
        return self.segment(key, image_rgb)[1]

    def segment(self, key, image_rgb: np.ndarray):
        """``(landmarks, probability)`` of camera ``key``'s RGB uint8 image: the network's
        :class:`~hmocap_ros.detection.keypoint_network.ViewLandmarks` and the person's
        segmentation (float32 ``(H, W)`` in [0, 1]); ``(None, None)`` when nobody is there."""
        from hmocap_ros.detection.keypoint_roi import landmarks_roi

        height, width = image_rgb.shape[:2]
        roi = self._tracks.get(key)
        if roi is None:
            found = self._detector.detect(image_rgb)
            roi = found[0].roi() if found else None
            if roi is None:
                return None, None
        self.runs += 1
        view, probability = self._network.segment(image_rgb, roi)
        if view.score < self.min_pose_score:
            self._tracks[key] = None
            return None, None
        following = landmarks_roi(view.xy)
        self._tracks[key] = following if following is not None and following.overlaps(width, height) else None
        return view, probability
