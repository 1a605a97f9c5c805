"""The hmocap_ros pipeline from a rig file, in a ROS 2 Jazzy install.

    ros2 launch hmocap_ros hmocap.launch.py rig_file:=/path/to/rig.yaml [namespace:=room_1]
        [composed:=true] [gestures:=false] [depth_namespace:=/camera/camera/depth depth_image:=image_rect_raw]
        [use_sim_time:=true] [dds_profile:=local|room|/path/to/profile.xml|none]

Starts camera_rig_publisher (the rig as a latched message and on /tf_static),
foreground_segmentation (one background model per rig camera: the camera names are read from
the rig file), extremity_detection, body_tracker (or, with ``composed:=true``, room_pipeline:
the three in one process, for a room whose cameras feed one PC) and gesture_detection, each
with its config/<node>.yaml (keyed ``/**``, so the files apply in any namespace). The colour cameras
publish ``<camera>/image_raw`` for the rig's camera names, inside ``namespace``; the depth
camera of the gestures ``<depth_namespace>/<depth_image>`` and
``<depth_namespace>/camera_info``. ``use_sim_time:=true`` for a bag replayed with
``hmocap replay BAG --clock``. docs/real_sensors.md shows the camera drivers to start.
``dds_profile`` names the Fast DDS profile of the nodes (FASTRTPS_DEFAULT_PROFILES_FILE and
FASTDDS_DEFAULT_PROFILES_FILE in each node's environment): ``local`` (default,
config/fastdds_local.xml: full-size frames whole through shared memory), ``room``
(config/fastdds_room.xml: nodes on several hosts, docs/network.md), a file, or ``none`` to keep
the environment's.

Not usable in the PyPI-wheel venv (no launch there): ``hmocap demo`` starts the same nodes with
hmocap_ros.processes.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription

ARGUMENTS = {
    "rig_file": ("", "Rig calibration YAML (intrinsics and camera poses in the room); empty = the "
                     "package's config/rig_example.yaml"),
    "namespace": ("", "Namespace of every node and of its relative topics (one room of several)"),
    "composed": ("false", "Segmentation, keypoints and tracking in one process (room_pipeline) instead of "
                          "three nodes: one PC for the room's cameras"),
    "gestures": ("true", "Start gesture_detection on the depth camera (false: leave it out)"),
    "depth_namespace": ("depth", "Namespace of the depth camera's topics (relative = inside namespace)"),
    "depth_image": ("image_raw", "Depth image topic in depth_namespace (image_rect_raw for realsense2_camera)"),
    "use_sim_time": ("false", "Nodes take their time from /clock (hmocap replay --clock, ros2 bag play --clock)"),
    "dds_profile": ("local", "Fast DDS profile of the nodes: local (one host), room (several hosts), a file, "
                             "or none (the environment's)"),
}

#: The variables naming a Fast DDS profiles file: Fast DDS 2 (Jazzy) reads the first, Fast DDS 3 the second.
DDS_PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")


def _rig_cameras(rig_file: str) -> list:
    """Camera names of the rig file, in rig order."""
    from hmocap_ros.geometry.rig import RigError, load_rig

    try:
        return list(load_rig(rig_file).names)
    except RigError as err:
        raise RuntimeError(f"hmocap.launch.py: {err}") from None


def _pipeline(context):
    config = os.path.join(get_package_share_directory("hmocap_ros"), "config")
    rig_file = LaunchConfiguration("rig_file").perform(context) or os.path.join(config, "rig_example.yaml")
    namespace = LaunchConfiguration("namespace").perform(context)
    depth = LaunchConfiguration("depth_namespace").perform(context).rstrip("/") or "depth"
    depth_image = LaunchConfiguration("depth_image").perform(context)
    sim_time = {"use_sim_time": LaunchConfiguration("use_sim_time").perform(context).lower() in ("true", "1")}
    profile = LaunchConfiguration("dds_profile").perform(context)
    if profile in ("local", "room"):
        profile = os.path.join(config, f"fastdds_{profile}.xml")
    if profile not in ("", "none") and not os.path.isfile(profile):
        raise RuntimeError(f"hmocap.launch.py: dds_profile {profile} is not a file")
    dds = {} if profile in ("", "none") else {variable: profile for variable in DDS_PROFILE_VARIABLES}
    rig = Node(package="hmocap_ros", executable="camera_rig_publisher", name="camera_rig_publisher",
               namespace=namespace, output="screen", additional_env=dds,
               parameters=[os.path.join(config, "camera_rig_publisher.yaml"), {"rig_file": rig_file}, sim_time])
    stages = [
        Node(package="hmocap_ros", executable="foreground_segmentation", name="foreground_segmentation",
             namespace=namespace, output="screen", additional_env=dds,
             parameters=[os.path.join(config, "foreground_segmentation.yaml"),
                         {"cameras": _rig_cameras(rig_file)}, sim_time]),
        # The rig comes from camera_rig_publisher on the latched camera_rig topic.
        Node(package="hmocap_ros", executable="extremity_detection", name="extremity_detection",
             namespace=namespace, output="screen", additional_env=dds,
             parameters=[os.path.join(config, "extremity_detection.yaml"), sim_time]),
        Node(package="hmocap_ros", executable="body_tracker", name="body_tracker",
             namespace=namespace, output="screen", additional_env=dds,
             parameters=[os.path.join(config, "body_tracker.yaml"), sim_time]),
    ]
    composed = [
        # The rig comes from camera_rig_publisher on the latched camera_rig topic.
        Node(package="hmocap_ros", executable="room_pipeline", name="room_pipeline",
             namespace=namespace, output="screen", additional_env=dds,
             parameters=[os.path.join(config, "room_pipeline.yaml"), sim_time]),
    ]
    gestures = Node(package="hmocap_ros", executable="gesture_detection", name="gesture_detection",
                    namespace=namespace, output="screen", additional_env=dds,
                    condition=IfCondition(LaunchConfiguration("gestures")),
                    parameters=[os.path.join(config, "gesture_detection.yaml"), sim_time],
                    remappings=[("depth/image_raw", f"{depth}/{depth_image}"),
                                ("depth/camera_info", f"{depth}/camera_info")])
    one_process = LaunchConfiguration("composed").perform(context).lower() in ("true", "1")
    return [rig, *(composed if one_process else stages), gestures]


def generate_launch_description():
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=text)
         for name, (default, text) in ARGUMENTS.items()]
        + [OpaqueFunction(function=_pipeline)])
