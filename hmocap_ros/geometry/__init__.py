"""Camera geometry: calibrated pinhole cameras with OpenCV lens distortion, vectorised in numpy.

The thesis (sec. 2.1) assumes "a set of projective transformations p_v, given by the camera
calibration, that map points in R^3 onto each view v" (Bouguet's model, ref. [21]). This module
is that set: a frozen :class:`PinholeCamera` per view and stateless functions over lists of them.

Frames and conventions
----------------------
* **Room frame** (the world, ``frame_id: room`` in the rig file, the frame the simulator renders
  in): metres, right-handed, **+Y up**, the floor is the plane ``y = 0``. :data:`ROOM_UP` is the
  up axis :func:`look_at` uses by default.
* **Camera optical frame** (REP-103 ``*_optical_frame``): x right, y down, z forward along the
  optical axis. A camera stores the world->camera transform ``x_cam = R @ x_world + t``; its pose
  in the room (the camera centre :attr:`PinholeCamera.position` and the orientation of the
  optical frame, :meth:`PinholeCamera.pose_quaternion`, x, y, z, w like ``geometry_msgs``) is the
  inverse of that transform.
* **Pixels**: OpenCV/ROS convention, the centre of pixel ``(col, row)`` is at ``u = col``,
  ``v = row``; the image covers ``[-0.5, width - 0.5) x [-0.5, height - 0.5)``.
* **Depth** is the z coordinate in the optical frame (distance along the optical axis), the
  convention of depth images, not the Euclidean range.
* **Distortion**: the OpenCV model (Brown-Conrady radial + tangential), ROS ``plumb_bob``
  ``D = (k1, k2, p1, p2, k3)`` and ``rational_polynomial`` ``D = (k1, k2, p1, p2, k3, k4, k5, k6)``:

  .. math::
      r^2 = x^2 + y^2,\\quad g = \\frac{1 + k_1 r^2 + k_2 r^4 + k_3 r^6}{1 + k_4 r^2 + k_5 r^4 + k_6 r^6}

      x_d = x g + 2 p_1 x y + p_2 (r^2 + 2 x^2),\\quad y_d = y g + p_1 (r^2 + 2 y^2) + 2 p_2 x y

  and ``(u, v, 1) = K (x_d, y_d, 1)``. It is implemented here in numpy (matches
  ``cv2.projectPoints`` to 1e-9 px) so that it broadcasts over cameras and point batches.

Shapes: point arrays are ``(..., 3)`` and pixel arrays ``(..., 2)`` with any batch shape; the
multi-camera functions put the camera axis first, ``(M, ...)``.

Modules, one implementation of each primitive, used by calibration, rendering, TF and tracking:
:mod:`.distortion` (the distortion model), :mod:`.pinhole_camera` (the camera and
:func:`look_at`), :mod:`.projection` (projection into M cameras at once),
:mod:`.triangulation` (rays, DLT triangulation, reprojection errors), :mod:`.rotations`
(quaternions, rotation vectors, rigid transforms) and :mod:`.rig` (the cameras of a room, its
YAML file and message). This package gathers the cameras' public names.
"""

from hmocap_ros.geometry.distortion import DISTORTION_MODELS, distort_normalized, undistort_normalized
from hmocap_ros.geometry.pinhole_camera import ROOM_UP, PinholeCamera, look_at
from hmocap_ros.geometry.projection import DEFAULT_MIN_DEPTH, Projection, project_points
from hmocap_ros.geometry.rotations import QUATERNION_TOLERANCE, matrix_to_quaternion, quaternion_to_matrix
from hmocap_ros.geometry.triangulation import pixel_rays, reprojection_errors, triangulate, triangulate_robust

__all__ = [
    "ROOM_UP",
    "DISTORTION_MODELS",
    "QUATERNION_TOLERANCE",
    "DEFAULT_MIN_DEPTH",
    "PinholeCamera",
    "Projection",
    "look_at",
    "distort_normalized",
    "undistort_normalized",
    "project_points",
    "pixel_rays",
    "triangulate",
    "triangulate_robust",
    "reprojection_errors",
    "quaternion_to_matrix",
    "matrix_to_quaternion",
]
