"""The rig as a ``hmocap_interfaces/msg/CameraRig`` message and back (no rclpy).

Messages are built through a message factory (:mod:`hmocap_ros.io.msg_factory`) so the same code
makes rosbags dataclasses and rclpy messages; the rig itself is
:class:`hmocap_ros.geometry.rig.Rig`.
"""
from __future__ import annotations

from hmocap_ros.geometry.pinhole_camera import PinholeCamera
from hmocap_ros.geometry.rig import Rig, RigError

__all__ = ["CAMERA_RIG_TYPE", "rig_from_msg", "rig_to_msg"]

#: ROS type name of the rig message.
CAMERA_RIG_TYPE = "hmocap_interfaces/msg/CameraRig"


def _default_factory():
    """A rosbags factory whose typestore knows hmocap_interfaces (CameraRig)."""
    from hmocap_ros.io.msg_factory import RosbagsFactory
    from hmocap_ros.io.typestore import hmocap_typestore

    return RosbagsFactory(hmocap_typestore())


def rig_to_msg(rig: Rig, stamp_ns: int = 0, factory=None):
    """``hmocap_interfaces/msg/CameraRig`` of ``rig``, built with ``factory.make(typename, **fields)``.

    ``factory`` is a ``hmocap_ros.io.msg_factory`` factory (``RclpyFactory`` in a node; the
    default is a ``RosbagsFactory`` on :func:`hmocap_ros.io.typestore.hmocap_typestore`). Each
    CameraInfo carries ``stamp_ns`` and the camera's optical ``frame_id``; the header carries
    the rig's ``frame_id``.
    """
    from hmocap_ros.io.conversions import dict_to_camera_info
    from hmocap_ros.io.msg_factory import make_header

    factory = _default_factory() if factory is None else factory
    stamp_ns = int(stamp_ns)
    header = make_header(factory, stamp_ns, rig.frame_id)
    infos, poses = [], []
    for camera in rig.cameras:
        infos.append(dict_to_camera_info(camera.to_camera_info_dict(), stamp_ns=stamp_ns, factory=factory))
        x, y, z = (float(v) for v in camera.position)
        qx, qy, qz, qw = (float(v) for v in camera.pose_quaternion())
        poses.append(factory.make(
            "geometry_msgs/msg/Pose",
            position=factory.make("geometry_msgs/msg/Point", x=x, y=y, z=z),
            orientation=factory.make("geometry_msgs/msg/Quaternion", x=qx, y=qy, z=qz, w=qw),
        ))
    return factory.make(CAMERA_RIG_TYPE, header=header, camera_names=list(rig.names), camera_info=infos,
                        camera_poses=poses)


def rig_from_msg(msg) -> Rig:
    """:class:`Rig` from a ``CameraRig`` message (rclpy message or rosbags dataclass)."""
    from hmocap_ros.io.conversions import camera_info_to_dict

    names = list(msg.camera_names)
    infos = list(msg.camera_info)
    poses = list(msg.camera_poses)
    if not (len(names) == len(infos) == len(poses)):
        raise RigError(
            f"CameraRig message: {len(names)} camera_names, {len(infos)} camera_info and "
            f"{len(poses)} camera_poses must have the same length"
        )
    if not names:
        raise RigError("CameraRig message has no cameras")
    cameras = []
    for name, info, pose in zip(names, infos, poses):
        position = (pose.position.x, pose.position.y, pose.position.z)
        orientation = (pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w)
        try:
            cameras.append(PinholeCamera.from_camera_info(camera_info_to_dict(info), name, position, orientation))
        except ValueError as error:
            raise RigError(f"CameraRig message: camera {name!r}: {error}") from None
    frame_id = msg.header.frame_id or "room"
    try:
        return Rig(frame_id, tuple(cameras))
    except RigError as error:
        raise RigError(f"CameraRig message: {error}") from None
