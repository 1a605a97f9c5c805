"""Recordings made outside ROS into bags: synchronised video files and another tool's camera
calibration (``hmocap import videos``; no rclpy).

- :mod:`.videos`: probing and decoding the files, several at once, frame sets by frame index.
- :mod:`.camera_fit`: a calibrated camera fitted to its video's frames (turned, scaled, cut)
  and turned upright.
- :mod:`.importer`: matching videos with cameras, the frame sets, the bag.
"""
from hmocap_ros.video_import.importer import (
                                              BASE_STAMP_NS,
                                              ImportOptions,
                                              ImportPlan,
                                              ImportResult,
                                              VideoImportError,
                                              bag_camera_name,
                                              import_videos,
                                              plan_import,
)

__all__ = ["BASE_STAMP_NS", "ImportOptions", "ImportPlan", "ImportResult", "VideoImportError",
           "bag_camera_name", "import_videos", "plan_import"]
