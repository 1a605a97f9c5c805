"""camera_rig_publisher: the room's calibration on the ROS graph, as a message and as tf2 frames.

Loads a rig YAML (intrinsics + camera poses in the room frame, see ``config/rig_example.yaml``)
and publishes it latched, both as one ``CameraRig`` message and as the static transforms room
frame -> each camera's optical frame on ``/tf_static``; for every image of a rig camera it
publishes that camera's CameraInfo with the image's stamp, as a camera driver's info manager
would, after checking that the image has the calibrated size.

Subscriptions:
  ``<camera>/image_raw`` (sensor_msgs/Image; with ``image_transport:=compressed``
  ``<camera>/image_raw/compressed``, sensor_msgs/CompressedImage, its size read from the JPEG or
  PNG header without decoding; ``image_reliability`` with a queue of
  ``queue_depth``: :func:`~hmocap_ros.nodes.common.image_qos`), for each served camera.
Publications:
  ``camera_rig`` (hmocap_interfaces/CameraRig, latched): the whole rig.
  ``/tf_static`` (tf2_msgs/TFMessage, reliable, transient local, keep last 1, as tf2's static
  broadcaster): ``fixed_frame`` (``world``, +Z up, the root) -> the rig's room frame
  (``frame_id`` of the rig file, +Y up) -> ``<camera>_optical_frame`` (the camera's
  ``frame_id``: x right, y down, z forward) for every rig camera; see :mod:`hmocap_ros.io.tf`.
  Only with ``publish_tf``.
  ``<camera>/camera_info`` (sensor_msgs/CameraInfo, reliable, keep last ``queue_depth``):
  intrinsics, stamp and frame of each image.
``rig_file`` and ``cameras`` may be changed at run time: the new rig is loaded and published
again (``camera_rig`` and ``/tf_static``), or the change is refused with the reason. The rig
file: docs/calibration.md; the frames: docs/viewing.md ("Frames"). Parameters: ``--help``
prints them after this text.
"""

from __future__ import annotations

from dataclasses import dataclass

from hmocap_interfaces.msg import CameraRig
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo
from tf2_msgs.msg import TFMessage

from hmocap_ros.config_files import find_config_file
from hmocap_ros.geometry.rig import Rig, RigError, load_rig
from hmocap_ros.io.conversions import ConversionError, dict_to_camera_info
from hmocap_ros.io.image_codec import image_size
from hmocap_ros.io.msg_factory import RclpyFactory, stamp_to_ns
from hmocap_ros.io.rig_messages import rig_to_msg
from hmocap_ros.io.tf import DEFAULT_FIXED_FRAME, TF_STATIC_TOPIC, rig_transforms, tf_message
from hmocap_ros.nodes.common import (
    LATCHED_QOS,
    create_image_subscription,
    declare_parameters,
    image_qos,
    image_reliability_param,
    image_transport_param,
    param,
    run_node,
)

NODE_NAME = "camera_rig_publisher"


@dataclass(frozen=True)
class CameraRigPublisherConfig:
    rig_file: str = param("", "Rig calibration YAML; empty = the package's config/rig_example.yaml. "
                              "Settable at run time.")
    cameras: list[str] = param([], "Rig cameras to serve (names); empty = every camera of the rig. "
                                   "Settable at run time.")
    check_image_size: bool = param(True, "Refuse (log an error, publish no CameraInfo for) images "
                                         "whose size differs from the calibration.")
    queue_depth: int = param(25, "Images queued per camera while the node is busy, and CameraInfo messages kept "
                                 "for a slow reliable subscriber; 25 holds one second at 25 fps.")
    image_reliability: str = image_reliability_param()
    image_transport: str = image_transport_param()
    publish_tf: bool = param(True, "Publish the room frame -> camera optical frame transforms of every rig "
                                   "camera on /tf_static (latched, as tf2's static broadcaster).")
    fixed_frame: str = param(DEFAULT_FIXED_FRAME, "The +Z-up fixed frame (REP 103) at the root of /tf_static, "
                                                  "parent of the room frame (+Y up) at the same origin: RViz's "
                                                  "and Foxglove's floor grid. Empty = the room frame is the root "
                                                  "(another node places it, e.g. a robot's map -> room).")


class CameraRigPublisher(Node):
    def __init__(self):
        super().__init__(NODE_NAME)
        self.config = declare_parameters(self, CameraRigPublisherConfig)
        self.image_qos = image_qos(self.config.image_reliability, self.config.queue_depth)
        self.factory = RclpyFactory()
        self.rig_pub = self.create_publisher(CameraRig, "camera_rig", LATCHED_QOS)
        self.tf_pub = self.create_publisher(TFMessage, TF_STATIC_TOPIC, LATCHED_QOS) if self.config.publish_tf else None
        self.rig: Rig | None = None
        self.path = ""
        self.served: dict[str, tuple] = {}  # camera -> (CameraInfo dict, publisher, subscription)
        self.rig_file, self.cameras = self.config.rig_file, list(self.config.cameras)
        try:
            rig, path = self._load(self.config.rig_file)
            self._serve(rig, path, self.config.cameras)
        except ValueError as err:  # RigError included
            self.get_logger().fatal(f"cannot load the rig: {err}")
            raise SystemExit(2) from err
        self.add_on_set_parameters_callback(self._on_set_parameters)

    # -- rig ----------------------------------------------------------------------------

    @staticmethod
    def _load(rig_file: str) -> tuple[Rig, str]:
        if rig_file:
            return load_rig(rig_file), rig_file
        path = find_config_file("rig_example.yaml")
        if path is None:
            raise RigError("no rig_file given and the package's config/rig_example.yaml is not installed")
        return load_rig(path), str(path)

    def _serve(self, rig: Rig, path: str, cameras: list[str]) -> None:
        """Publish ``rig`` (latched message and static transforms) and serve the CameraInfo of
        ``cameras`` (empty = all); cameras no longer served lose their subscription.
        ``ValueError`` (nothing changed) for frames tf2 cannot take (``fixed_frame`` = the room)."""
        transforms = rig_transforms(rig, self.config.fixed_frame) if self.tf_pub is not None else []
        names = list(cameras) or list(rig.names)
        unknown = [n for n in names if n not in rig.names]
        if unknown:
            self.get_logger().error(f"cameras {unknown} are not in {path}; serving the others")
        wanted = [n for n in rig.names if n in names]
        for name in [n for n in self.served if n not in wanted]:
            _, pub, sub = self.served.pop(name)
            self.destroy_subscription(sub)
            self.destroy_publisher(pub)
        depth = max(1, self.config.queue_depth)
        for name in wanted:
            info = rig[name].to_camera_info_dict()
            if name in self.served:
                self.served[name] = (info, *self.served[name][1:])
                continue
            pub = self.create_publisher(CameraInfo, f"{name}/camera_info",
                                        QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE))
            sub = create_image_subscription(self, f"{name}/image_raw", self.config.image_transport,
                                            self._callback(name), self.image_qos)
            self.served[name] = (info, pub, sub)
        self.rig, self.path = rig, path
        stamp = self.get_clock().now().nanoseconds
        self.rig_pub.publish(rig_to_msg(rig, stamp, self.factory))
        frames = ""
        if self.tf_pub is not None:
            self.tf_pub.publish(tf_message(transforms, stamp, self.factory))
            frames = f"; {TF_STATIC_TOPIC}: " + ", ".join(f"{t.parent} -> {t.child}" for t in transforms)
        self.get_logger().info(f"serving rig {path} ({len(wanted)} cameras: {', '.join(wanted)}){frames}")

    def _on_set_parameters(self, params) -> SetParametersResult:
        changed = {p.name: p.value for p in params}
        fixed = sorted(set(changed) & {"check_image_size", "queue_depth", "image_reliability", "image_transport",
                                        "publish_tf",
                                        "fixed_frame"})
        if fixed:
            return SetParametersResult(successful=False, reason=f"{', '.join(fixed)}: read at start, restart the node")
        if not {"rig_file", "cameras"} & set(changed):
            return SetParametersResult(successful=True)
        rig_file = str(changed.get("rig_file", self.rig_file) or "")
        cameras = list(changed.get("cameras", self.cameras) or [])
        try:
            rig, path = self._load(rig_file)
            self._serve(rig, path, cameras)
        except ValueError as err:  # RigError included
            reason = f"cannot load the rig: {err}"
            self.get_logger().error(f"{reason}; still serving {self.path}")
            return SetParametersResult(successful=False, reason=reason)
        self.rig_file, self.cameras = rig_file, cameras
        return SetParametersResult(successful=True)

    def _callback(self, name: str):
        def on_image(msg) -> None:
            served = self.served.get(name)
            if served is None:
                return
            info = served[0]
            if self.config.check_image_size:
                try:
                    width, height = image_size(msg)  # a compressed image's from its header
                except ConversionError as err:
                    self.get_logger().error(f"{name}/image_raw: {err}", throttle_duration_sec=5.0)
                    return
            if self.config.check_image_size and (width, height) != (info["width"], info["height"]):
                self.get_logger().error(
                    f"{name}/image_raw is {width}x{height} but the rig calibrates "
                    f"{info['width']}x{info['height']}: no camera_info for this image",
                    throttle_duration_sec=5.0,
                )
                return
            out = dict_to_camera_info(info, stamp_to_ns(msg.header.stamp), self.factory)
            served[1].publish(out)

        return on_image


def main(args=None) -> int:
    return run_node(CameraRigPublisher, NODE_NAME, __doc__, CameraRigPublisherConfig, args)


if __name__ == "__main__":
    raise SystemExit(main())
