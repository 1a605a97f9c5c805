"""hmocap_ros: markerless 3D body tracking and depth gesture localization for smart rooms (ROS 2 Jazzy)."""

__version__ = "0.1.0"
