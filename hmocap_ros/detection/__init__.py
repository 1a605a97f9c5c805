"""Labelled 3D body keypoints from calibrated colour views (no rclpy).

Per view a 2D human-pose landmark network (BlazePose GHUM 3D, "Pose landmark full", run with
LiteRT: :mod:`.keypoint_network`) on the crop MediaPipe's pipeline gives it (:mod:`.keypoint_roi`:
from the view's previous landmarks, the previous skeleton, or MediaPipe's pose detector,
:mod:`.pose_detector`); the views' landmarks triangulated into labelled 3D keypoints (head,
hands, feet and the 12 limb joints) with views that disagree, hidden landmarks, landmarks off
the silhouette and views whose left and right are swapped weighed or left out
(:mod:`.keypoint_triangulation`); :class:`KeypointDetector` does both for one frame set
(:mod:`.keypoint_detector`).
"""

from hmocap_ros.detection.keypoint_detector import KeypointDetector, foreground_box
from hmocap_ros.detection.keypoint_network import DEFAULT_MODEL, LANDMARK_NAMES, PoseLandmarkNetwork, ViewLandmarks
from hmocap_ros.detection.keypoint_roi import Roi, box_roi
from hmocap_ros.detection.keypoint_triangulation import KEYPOINT_LABELS, Keypoints3D, triangulate_views
from hmocap_ros.detection.params import KeypointParams
from hmocap_ros.detection.pose_detector import PoseDetection, PoseDetector
from hmocap_ros.detection.tflite_model import ModelFileError

__all__ = [
    "DEFAULT_MODEL",
    "KEYPOINT_LABELS",
    "LANDMARK_NAMES",
    "KeypointDetector",
    "KeypointParams",
    "Keypoints3D",
    "ModelFileError",
    "PoseDetection",
    "PoseDetector",
    "PoseLandmarkNetwork",
    "Roi",
    "ViewLandmarks",
    "box_roi",
    "foreground_box",
    "triangulate_views",
]
