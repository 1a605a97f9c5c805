"""ament_python package hmocap_ros (colcon in a ROS install, `pip install -e .` in the venv)."""
from glob import glob

from setuptools import find_namespace_packages, find_packages, setup

PACKAGE = "hmocap_ros"

# Every executable `ros2 run hmocap_ros <name>` finds: the nodes and the `hmocap` tool.
CONSOLE_SCRIPTS = [
    "hmocap = hmocap_ros.cli:main",
    "camera_rig_publisher = hmocap_ros.nodes.camera_rig_publisher:main",
    "foreground_segmentation = hmocap_ros.nodes.foreground_segmentation:main",
    "gesture_detection = hmocap_ros.nodes.gesture_detection:main",
    "gesture_trainer = hmocap_ros.nodes.gesture_trainer:main",
    "extremity_detection = hmocap_ros.nodes.extremity_detection:main",
    "body_tracker = hmocap_ros.nodes.body_tracker:main",
    "room_pipeline = hmocap_ros.nodes.room_pipeline:main",
    # the example apps on hmocap_ros.client (examples/, installed as the package hmocap_examples)
    "light_switch = hmocap_examples.light_switch:main",
    "presence = hmocap_examples.presence:main",
]

setup(
    name=PACKAGE,
    version="0.1.0",
    # the shipped data folders (hmocap_ros/data/*) are listed as the namespace packages Python
    # sees in them, so setuptools installs their files without asking
    packages=(find_packages(exclude=["test", "test.*", "examples", "examples.*"])
              + find_namespace_packages(include=["hmocap_ros.data", "hmocap_ros.data.*"]) + ["hmocap_examples"]),
    package_dir={"hmocap_examples": "examples"},
    package_data={PACKAGE: ["data/*", "data/**/*"]},
    include_package_data=True,
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/fastdds_*.xml") + glob("config/*.rviz")
         + glob("config/*_foxglove.json")),
        (f"share/{PACKAGE}/launch", glob("launch/*.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="hmocap_ros developers",
    maintainer_email="hmocap@example.org",
    description="Multi-view 3D body tracking and depth gesture localization for smart rooms (ROS 2 Jazzy).",
    license="Apache-2.0",
    entry_points={"console_scripts": CONSOLE_SCRIPTS},
)
