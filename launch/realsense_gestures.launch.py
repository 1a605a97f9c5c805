"""Gestures from an Intel RealSense depth camera, in a ROS 2 Jazzy install.

    ros2 launch hmocap_ros realsense_gestures.launch.py [serial_no:=_123456789] [profile:=640,480,30]

Starts the camera through realsense2_camera's rs_launch.py (depth only, in namespace
``camera`` under the name ``camera``) and gesture_detection on its depth stream:
``/camera/camera/depth/image_rect_raw`` (16UC1 in millimetres: realsense2_camera sets or
rescales every device to millimetres, the SR300/SR305's 1/8 mm included, so
``depth_unit_m`` stays 0, REP 118) and ``/camera/camera/depth/camera_info``, whose focal length
the forest's offsets are rescaled to. The gestures come out on ``/gestures`` in the frame
``camera_depth_optical_frame``. docs/real_sensors.md explains the choices.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription

CAMERA = "/camera/camera"  # <camera_namespace>/<camera_name> of rs_launch.py


def generate_launch_description():
    config = os.path.join(get_package_share_directory("hmocap_ros"), "config")
    realsense = os.path.join(get_package_share_directory("realsense2_camera"), "launch", "rs_launch.py")
    return LaunchDescription([
        DeclareLaunchArgument("serial_no", default_value="''",
                              description="Serial number of the camera (with a leading _); empty = the first found"),
        DeclareLaunchArgument("profile", default_value="640,480,30",
                              description="Depth stream width,height,fps (848,480,30 is the D400 series' best)"),
        IncludeLaunchDescription(
            PythonLaunchDescriptionSource(realsense),
            launch_arguments={
                "camera_namespace": "camera",
                "camera_name": "camera",
                "serial_no": LaunchConfiguration("serial_no"),
                "enable_color": "false",
                "enable_depth": "true",
                "depth_module.depth_profile": LaunchConfiguration("profile"),
                "pointcloud.enable": "false",
                "align_depth.enable": "false",
            }.items(),
        ),
        Node(package="hmocap_ros", executable="gesture_detection", name="gesture_detection", output="screen",
             parameters=[os.path.join(config, "gesture_detection.yaml"), {"depth_unit_m": 0.0}],
             remappings=[("depth/image_raw", f"{CAMERA}/depth/image_rect_raw"),
                         ("depth/camera_info", f"{CAMERA}/depth/camera_info")]),
    ])
