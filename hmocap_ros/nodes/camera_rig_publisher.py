"""camera_rig_publisher: the room's calibration on the ROS graph (there is no tf2 here).

Loads a rig YAML (intrinsics + camera poses in the room frame, see ``config/rig_example.yaml``)
and publishes it once, latched; for every image of a rig camera it publishes that camera's
CameraInfo with the image's stamp, as a camera driver's info manager would, after checking
that the image has the calibrated size.

Subscriptions:
  ``<camera>/image_raw`` (sensor_msgs/Image, sensor-data QoS with a queue of ``queue_depth``),
  for each rig camera.
Publications:
  ``camera_rig`` (hmocap_interfaces/CameraRig, latched): the whole rig.
  ``<camera>/camera_info`` (sensor_msgs/CameraInfo, reliable, keep last ``queue_depth``):
  intrinsics, stamp and frame of each image.
Parameters: see :class:`CameraRigPublisherConfig` (``camera_rig_publisher --help``).
"""

from __future__ import annotations

from dataclasses import dataclass

from hmocap_interfaces.msg import CameraRig
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image

from hmocap_ros.config_files import find_config_file
from hmocap_ros.io.conversions import dict_to_camera_info
from hmocap_ros.io.msg_factory import RclpyFactory, stamp_to_ns
from hmocap_ros.nodes.common import LATCHED_QOS, declare_parameters, param, run_node, sensor_qos
from hmocap_ros.rig import RigError, load_rig, rig_to_msg

NODE_NAME = "camera_rig_publisher"


@dataclass(frozen=True)
class CameraRigPublisherConfig:
    rig_file: str = param("", "Rig calibration YAML; empty = the package's config/rig_example.yaml.")
    cameras: list[str] = param([], "Rig cameras to serve (names); empty = every camera of the rig.")
    check_image_size: bool = param(True, "Refuse (log an error, publish no CameraInfo for) images "
                                         "whose size differs from the calibration.")
    queue_depth: int = param(25, "Images queued per camera while the node is busy, and CameraInfo messages kept "
                                 "for a slow reliable subscriber; 25 holds one second at 25 fps.")


class CameraRigPublisher(Node):
    def __init__(self):
        super().__init__(NODE_NAME)
        self.config = declare_parameters(self, CameraRigPublisherConfig)
        self.factory = RclpyFactory()
        path = self.config.rig_file or str(find_config_file("rig_example.yaml"))
        try:
            self.rig = load_rig(path)
        except (RigError, OSError) as err:
            self.get_logger().fatal(f"cannot load the rig: {err}")
            raise SystemExit(2) from err
        names = self.config.cameras or list(self.rig.names)
        unknown = [n for n in names if n not in self.rig.names]
        if unknown:
            self.get_logger().error(f"cameras {unknown} are not in {path}; serving the others")
        self.cameras = {c.name: c for c in self.rig.cameras if c.name in names}
        stamp = self.get_clock().now().nanoseconds
        self.rig_pub = self.create_publisher(CameraRig, "camera_rig", LATCHED_QOS)
        self.rig_pub.publish(rig_to_msg(self.rig, stamp, self.factory))
        self.info_pubs = {}
        self.info_dicts = {}
        depth = max(1, self.config.queue_depth)
        info_qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)
        for name, camera in self.cameras.items():
            self.info_dicts[name] = camera.to_camera_info_dict()
            self.info_pubs[name] = self.create_publisher(CameraInfo, f"{name}/camera_info", info_qos)
            self.create_subscription(Image, f"{name}/image_raw", self._callback(name), sensor_qos(depth))
        self.get_logger().info(f"serving rig {path} ({len(self.cameras)} cameras: {', '.join(self.cameras)})")

    def _callback(self, name: str):
        def on_image(msg: Image) -> None:
            info = self.info_dicts[name]
            if self.config.check_image_size and (msg.width, msg.height) != (info["width"], info["height"]):
                self.get_logger().error(
                    f"{name}/image_raw is {msg.width}x{msg.height} but the rig calibrates "
                    f"{info['width']}x{info['height']}: no camera_info for this image",
                    throttle_duration_sec=5.0,
                )
                return
            out = dict_to_camera_info(info, stamp_to_ns(msg.header.stamp), self.factory)
            self.info_pubs[name].publish(out)

        return on_image


def main(args=None) -> int:
    return run_node(CameraRigPublisher, NODE_NAME, __doc__, CameraRigPublisherConfig, args)


if __name__ == "__main__":
    raise SystemExit(main())
