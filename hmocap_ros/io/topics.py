"""The documented bag layout: topic names and types of camera, depth and ground-truth data.

Names here are absolute, as stored in bags; live nodes use the relative names (without
the leading slash) so they can be remapped. Every message of one frame carries the same
``header.stamp``, and bags log each message at its stamp.
"""

from __future__ import annotations

#: The rig: intrinsics and camera poses, once, latched (hmocap_interfaces/msg/CameraRig).
CAMERA_RIG = "/camera_rig"
#: Ground-truth body shape of the simulated subject, latched (hmocap_interfaces/msg/BodyShape).
GT_BODY_SHAPE = "/ground_truth/body_shape"
#: Ground-truth 3D joints in the room frame (hmocap_interfaces/msg/Skeleton).
GT_SKELETON = "/ground_truth/skeleton"
#: Ground-truth pose parameters, one per DoF of the body model (sensor_msgs/msg/JointState).
GT_JOINT_STATES = "/ground_truth/joint_states"
#: Depth camera of the gesture set-up (16UC1 millimetres, 0 = invalid) and its intrinsics.
DEPTH_IMAGE = "/depth/image_raw"
DEPTH_INFO = "/depth/camera_info"
#: Ground-truth gestures of each depth frame (hmocap_interfaces/msg/GestureArray; empty = none).
GT_GESTURES = "/ground_truth/gestures"
#: Near misses of each depth frame (GestureArray; empty = none): the missed gesture's class and
#: reference pixel, the near-miss kind as the name. Training draws background samples there.
GT_NEAR_MISSES = "/ground_truth/near_misses"


def camera_image(camera: str) -> str:
    """Colour image of a rig camera (sensor_msgs/msg/Image, rgb8)."""
    return f"/{camera}/image_raw"


def camera_foreground(camera: str) -> str:
    """Foreground mask computed by foreground_segmentation (sensor_msgs/msg/Image, mono8 0/255)."""
    return f"/{camera}/foreground"


def gt_silhouette(camera: str) -> str:
    """Exact silhouette of the person in a rig camera (sensor_msgs/msg/Image, mono8 0/255)."""
    return f"/ground_truth/{camera}/silhouette"
