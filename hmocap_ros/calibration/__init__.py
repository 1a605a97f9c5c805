"""Multi-camera rig calibration from a ChArUco board seen by the room cameras.

The algorithm modules, in the order ``hmocap calibrate`` runs them (none imports rclpy):

- :mod:`~hmocap_ros.calibration.board`: the board (:class:`BoardSpec`) and its 3D corners.
- :mod:`~hmocap_ros.calibration.live_collection`: frame sets of live topics, by stamp.
- :mod:`~hmocap_ros.calibration.session`: the cameras and the board's corners in every image.
- :mod:`~hmocap_ros.calibration.detection`: ChArUco corners per image, board consistency.
- :mod:`~hmocap_ros.calibration.initialisation`: intrinsics, per-view board poses, camera
  poses chained through a spanning tree of shared views.
- :mod:`~hmocap_ros.calibration.bundle_adjustment`: all camera and board poses refined together.
- :mod:`~hmocap_ros.calibration.room_frame`: the room frame from the board on the floor.
- :mod:`~hmocap_ros.calibration.report`: reprojection errors, the text report and the picture.
"""
