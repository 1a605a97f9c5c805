"""Teach a gesture: gesture_trainer and gesture_detection on one depth camera, in a ROS 2 Jazzy install.

    ros2 launch hmocap_ros gesture_trainer.launch.py [forest_file:=/path/room.forest.npz]

Both nodes read ``depth/image_raw`` and ``depth/camera_info`` (remap them to the camera's
topics); gesture_detection watches ``forest_file`` and loads it each time the trainer writes it.
Start a session with ``ros2 service call /gesture_trainer/teach hmocap_interfaces/srv/TeachGesture
"{gesture: wave, new_forest: true}"`` and follow ``/gesture_trainer/feedback``
(docs/gestures_interactive.md).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription


def generate_launch_description():
    config = os.path.join(get_package_share_directory("hmocap_ros"), "config")
    forest = LaunchConfiguration("forest_file")
    return LaunchDescription([
        DeclareLaunchArgument("forest_file", default_value=os.path.join(os.getcwd(), "gestures.forest.npz"),
                              description="Forest file the trainer writes and gesture_detection watches"),
        Node(package="hmocap_ros", executable="gesture_trainer", name="gesture_trainer", output="screen",
             parameters=[os.path.join(config, "gesture_trainer.yaml"), {"forest_file": forest}]),
        Node(package="hmocap_ros", executable="gesture_detection", name="gesture_detection", output="screen",
             parameters=[os.path.join(config, "gesture_detection.yaml"), {"model_file": forest}]),
    ])
