"""Labelled 3D body keypoints from calibrated colour views (no rclpy).

Per view a 2D human-pose landmark network (BlazePose GHUM 3D, "Pose landmark full", run with
OpenCV dnn: :mod:`.keypoint_network`) on the crop around the person's foreground; the views'
landmarks triangulated into labelled 3D keypoints (head, hands, feet and the 12 limb joints)
with views that disagree, hidden landmarks, landmarks off the silhouette and views whose left
and right are swapped weighed or left out (:mod:`.keypoint_triangulation`);
:class:`KeypointDetector` does both for one frame set (:mod:`.keypoint_detector`).
"""

from hmocap_ros.detection.keypoint_detector import KeypointDetector, KeypointParams, roi_box
from hmocap_ros.detection.keypoint_network import (DEFAULT_MODEL, LANDMARK_NAMES, ModelFileError,
                                                   PoseLandmarkNetwork, ViewLandmarks)
from hmocap_ros.detection.keypoint_triangulation import (KEYPOINT_LABELS, Keypoints3D,
                                                         triangulate_views)

__all__ = [
    "DEFAULT_MODEL",
    "KEYPOINT_LABELS",
    "LANDMARK_NAMES",
    "KeypointDetector",
    "KeypointParams",
    "Keypoints3D",
    "ModelFileError",
    "PoseLandmarkNetwork",
    "ViewLandmarks",
    "roi_box",
    "triangulate_views",
]
