"""Launch the hmocap_ros nodes in a ROS 2 Jazzy install (``ros2 launch hmocap_ros hmocap.launch.py``).

Not usable in the PyPI-wheel venv (no launch there): ``hmocap demo`` starts the same
processes with hmocap_ros.processes. Arguments: ``rig_file`` (rig calibration YAML).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    config = os.path.join(get_package_share_directory("hmocap_ros"), "config")
    rig_file = LaunchConfiguration("rig_file")
    return LaunchDescription([
        DeclareLaunchArgument("rig_file", default_value=os.path.join(config, "rig_example.yaml"),
                              description="Rig calibration YAML (intrinsics and camera poses)"),
        Node(package="hmocap_ros", executable="camera_rig_publisher", name="camera_rig_publisher",
             parameters=[os.path.join(config, "camera_rig_publisher.yaml"), {"rig_file": rig_file}]),
        Node(package="hmocap_ros", executable="foreground_segmentation", name="foreground_segmentation",
             parameters=[os.path.join(config, "foreground_segmentation.yaml")]),
        # The rig comes from camera_rig_publisher on the latched camera_rig topic.
        Node(package="hmocap_ros", executable="body_tracker", name="body_tracker",
             parameters=[os.path.join(config, "body_tracker.yaml")]),
        Node(package="hmocap_ros", executable="gesture_detection", name="gesture_detection",
             parameters=[os.path.join(config, "gesture_detection.yaml")]),
    ])
