"""Message <-> numpy conversions: Image, CompressedImage, CameraInfo, PointCloud2, JointState.

The one place that knows the wire layout of these messages (STYLE habit 5: cv_bridge and
ros2_numpy are unavailable and break on NumPy 2).

* Decoders (``image_to_numpy``, ``pointcloud2_to_array``, ...) read any object with the
  message's attributes, so rclpy messages and rosbags dataclasses both work. They honour
  ``step``/``row_step`` padding and ``is_bigendian``, and always return a fresh, writeable,
  C-contiguous, native-endian array that shares no memory with the message.
* Encoders (``numpy_to_image``, ``array_to_pointcloud2``, ...) take ``factory=None`` (the shared
  :class:`~hmocap_ros.io.msg_factory.RosbagsFactory`) or a
  :class:`~hmocap_ros.io.msg_factory.RclpyFactory`, and write little-endian, unpadded data.
* Malformed input raises :class:`ConversionError` (a ``ValueError``) whose message names the
  field at fault, so a node can log it and drop the message.

Layouts follow sensor_msgs (``image_encodings.hpp``; ``point_cloud2.py`` of sensor_msgs_py for
structured dtypes) and image_transport's compressed / compressedDepth plugins.

One module per message type: :mod:`.images`, :mod:`.compressed_images`, :mod:`.camera_info`,
:mod:`.point_clouds`, :mod:`.joint_states`; errors in :mod:`.conversion_errors`. This module
gathers their public names.
"""

from hmocap_ros.io.camera_info import CAMERA_INFO_KEYS, camera_info_to_dict, dict_to_camera_info
from hmocap_ros.io.compressed_images import compressed_to_numpy, numpy_to_compressed
from hmocap_ros.io.conversion_errors import (
                                             CameraInfoConversionError,
                                             CompressedImageError,
                                             ConversionError,
                                             ImageConversionError,
                                             JointStateConversionError,
                                             PointCloudConversionError,
)
from hmocap_ros.io.images import (
                                             EncodingLayout,
                                             depth_image_to_metres,
                                             encoding_layout,
                                             image_to_numpy,
                                             image_to_rgb,
                                             numpy_to_image,
)
from hmocap_ros.io.joint_states import joint_state_to_dict, make_joint_state
from hmocap_ros.io.point_clouds import (
                                             array_to_pointcloud2,
                                             pointcloud2_dtype,
                                             pointcloud2_to_array,
                                             pointcloud2_to_xyz,
                                             xyz_to_pointcloud2,
)

__all__ = [
    "CAMERA_INFO_KEYS",
    "CameraInfoConversionError",
    "CompressedImageError",
    "ConversionError",
    "ImageConversionError",
    "JointStateConversionError",
    "PointCloudConversionError",
    "camera_info_to_dict",
    "compressed_to_numpy",
    "depth_image_to_metres",
    "dict_to_camera_info",
    "EncodingLayout",
    "encoding_layout",
    "image_to_numpy",
    "image_to_rgb",
    "joint_state_to_dict",
    "make_joint_state",
    "numpy_to_compressed",
    "numpy_to_image",
    "array_to_pointcloud2",
    "pointcloud2_dtype",
    "pointcloud2_to_array",
    "pointcloud2_to_xyz",
    "xyz_to_pointcloud2",
]
