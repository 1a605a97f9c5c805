"""What every hmocap_ros node shares: parameters from a frozen dataclass, config YAML, --help, start/stop.

A node's tunables are one frozen dataclass whose fields carry a ``description`` in their
metadata (:func:`hmocap_ros.params.param`; nested groups by :func:`hmocap_ros.params.group`).
:func:`declare_parameters` declares each as a ROS parameter with that description and reads them
back into the dataclass, which the algorithm takes. :func:`run_node` handles ``--help``
(printing the parameter table), loads ``config/<node_name>.yaml`` as the default parameter file,
spins, and shuts down cleanly on Ctrl-C or SIGTERM.
"""

from __future__ import annotations

import signal
import sys
import typing
from collections.abc import Callable, Sequence
from pathlib import Path

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.signals import SignalHandlerOptions

from hmocap_ros.config_files import default_config_file
from hmocap_ros.params import flat_fields, from_flat, param  # noqa: F401  (param: the nodes' configs)

#: Images and other high-rate sensor data: best effort, keep last 5.
SENSOR_QOS = qos_profile_sensor_data
#: a node class given to :func:`run_node`, and the node its ``on_shutdown`` receives
NodeT = typing.TypeVar("NodeT", bound=Node)

#: The reliabilities of an image subscription (node parameter ``image_reliability``).
IMAGE_RELIABILITIES = {"best_effort": ReliabilityPolicy.BEST_EFFORT, "reliable": ReliabilityPolicy.RELIABLE}

IMAGE_RELIABILITY_HELP = (
    "Reliability of the image subscriptions: best_effort matches every camera driver (reliable and "
    "best-effort publishers); reliable matches only reliable publishers (most drivers' default) and "
    "has lost fragments sent again, for links that drop packets. On one host with the package's DDS "
    "profile (config/fastdds_local.xml) best effort receives every full-size frame; docs/network.md.")


def image_reliability_param(default: str = "best_effort"):
    """The ``image_reliability`` field of a node's config dataclass (checked by :func:`image_qos`)."""
    return param(default, IMAGE_RELIABILITY_HELP)


def image_qos(reliability: str, depth: int) -> QoSProfile:
    """QoS of an image subscription: ``reliability`` (``best_effort`` or ``reliable``), volatile,
    keeping the last ``depth`` frames; ValueError for another reliability or a depth below 1.

    What matches (DDS request/offer): a best-effort subscription receives from reliable and
    best-effort publishers alike; a reliable one only from reliable publishers (a best-effort
    camera gives it nothing, with an incompatible-QoS warning). The queue holds frames that
    arrive while the node is busy: a node that must answer every frame (and is fast enough on
    average) keeps the burst of a stall, a moment of CPU starvation or a publisher catching up
    (one second of frames costs only memory); what overflows it is dropped, the oldest first.
    Whole frames reach the queue only when the transport carries them: on one host the
    shared-memory segment of ``config/fastdds_local.xml`` (the default 512 KiB segment of Fast
    DDS holds no 640x480 frame, and best effort then loses frames in UDP fragments).
    """
    if reliability not in IMAGE_RELIABILITIES:
        raise ValueError(f"image_reliability must be one of {', '.join(IMAGE_RELIABILITIES)}, got {reliability!r}")
    if depth < 1:
        raise ValueError(f"queue depth must be >= 1, got {depth}")
    return QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST, reliability=IMAGE_RELIABILITIES[reliability],
                      durability=DurabilityPolicy.VOLATILE)


def image_output_qos(depth: int) -> QoSProfile:
    """QoS of an image a node publishes (masks, probability and feedback images), by REP-2003:
    sensor data is published reliable and subscribed best effort, so every subscriber matches
    (RViz's Image display and a default rclpy subscription are reliable; a best-effort one
    matches a reliable publisher too). Volatile, keeping the last ``depth`` images: a reliable
    writer with a bounded history replaces its oldest sample rather than wait, so a slow
    subscriber, or a viewer that connects and vanishes, never stalls the node."""
    if depth < 1:
        raise ValueError(f"queue depth must be >= 1, got {depth}")
    return QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


class ImagePublisher:
    """An image output with image_transport's ``raw`` and ``compressed`` transports:
    ``sensor_msgs/Image`` on ``topic`` and ``sensor_msgs/CompressedImage`` on
    ``<topic>/compressed`` (PNG for mono images such as masks, lossless; JPEG for colour),
    both with :func:`image_output_qos`. As image_transport does, the compressed image is encoded
    only while that topic has subscribers. :meth:`publish` takes the raw message."""

    def __init__(self, node: Node, topic: str, depth: int):
        from rclpy.qos_overriding_options import QoSOverridingOptions
        from sensor_msgs.msg import CompressedImage, Image

        from hmocap_ros.io.image_codec import transport_topic

        overriding = QoSOverridingOptions.with_default_policies()
        self.topic = topic
        self.raw = node.create_publisher(Image, topic, image_output_qos(depth), qos_overriding_options=overriding)
        self.compressed = node.create_publisher(CompressedImage, transport_topic(topic, "compressed"),
                                                image_output_qos(depth), qos_overriding_options=overriding)
        self.logger = node.get_logger()

    def publish(self, msg) -> None:
        """Publish the ``sensor_msgs/Image`` ``msg``, and its compressed form when subscribed."""
        self.raw.publish(msg)
        if self.compressed.get_subscription_count() == 0:
            return
        from hmocap_ros.io.conversions import ConversionError, image_to_numpy, image_to_rgb, numpy_to_compressed
        from hmocap_ros.io.msg_factory import RclpyFactory, stamp_to_ns

        try:
            pixels = image_to_numpy(msg)
            if pixels.ndim == 3:
                pixels = image_to_rgb(msg)
            out = numpy_to_compressed(pixels, "png" if pixels.ndim == 2 else "jpeg",
                                      stamp_to_ns(msg.header.stamp), msg.header.frame_id, RclpyFactory())
        except ConversionError as err:
            self.logger.error(f"{self.topic}/compressed: {err}", throttle_duration_sec=5.0)
            return
        self.compressed.publish(out)


def create_image_publisher(node: Node, topic: str, depth: int) -> ImagePublisher:
    """An :class:`ImagePublisher` of ``topic`` (raw and compressed) with :func:`image_output_qos`,
    whose reliability, history and depth a user may change with rclpy's standard parameters
    (``qos_overrides./<namespace>/<topic>.publisher.reliability`` ..., read at start)."""
    return ImagePublisher(node, topic, depth)


IMAGE_TRANSPORT_HELP = (
    "Transport of the image inputs, as image_transport names it: raw (sensor_msgs/Image on "
    "<camera>/image_raw) or compressed (sensor_msgs/CompressedImage, JPEG or PNG, on "
    "<camera>/image_raw/compressed, decoded once on arrival); masks likewise on "
    "<camera>/foreground or <camera>/foreground/compressed.")
DEPTH_TRANSPORT_HELP = (
    "Transport of the depth images, as image_transport names it: raw (sensor_msgs/Image on "
    "depth/image_raw) or compressedDepth (sensor_msgs/CompressedImage, compressed_depth_image_transport's "
    "PNG, on depth/image_raw/compressedDepth, decoded once on arrival).")


def image_transport_param(depth: bool = False):
    """The ``image_transport`` field (default ``raw``) of a node's config dataclass: the
    transports of camera images and masks (:data:`~hmocap_ros.io.image_codec.CAMERA_TRANSPORTS`),
    or with ``depth`` of depth images (:data:`~hmocap_ros.io.image_codec.DEPTH_TRANSPORTS`);
    :func:`declare_parameters` checks the value."""
    from dataclasses import field

    from hmocap_ros.io.image_codec import CAMERA_TRANSPORTS, DEPTH_TRANSPORTS

    return field(default="raw", metadata={"description": DEPTH_TRANSPORT_HELP if depth else IMAGE_TRANSPORT_HELP,
                                          "read_only": False,
                                          "transports": DEPTH_TRANSPORTS if depth else CAMERA_TRANSPORTS})


def create_image_subscription(node: Node, topic: str, transport: str, callback, qos: QoSProfile):
    """Subscribe the image topic ``topic`` in ``transport`` (``raw``: ``sensor_msgs/Image`` on
    ``topic``; ``compressed``, ``compressedDepth``: ``sensor_msgs/CompressedImage`` on
    ``<topic>/<transport>``);
    ``callback`` takes either message and decodes it with :mod:`hmocap_ros.io.image_codec`.
    ValueError (the node does not start) for another transport."""
    from sensor_msgs.msg import CompressedImage, Image

    from hmocap_ros.io.image_codec import transport_topic

    name = transport_topic(topic, transport)
    return node.create_subscription(Image if transport == "raw" else CompressedImage, name, callback, qos)


def sensor_qos(depth: int) -> QoSProfile:
    """Best-effort :func:`image_qos` keeping the last ``depth`` messages."""
    return image_qos("best_effort", depth)


#: Latched topics (camera_rig, body_shape): reliable, transient local, keep last 1.
LATCHED_QOS = QoSProfile(
    depth=1,
    history=HistoryPolicy.KEEP_LAST,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
#: Results (joint states, gestures): reliable, volatile, keep last 10.
RESULT_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def declare_parameters(node: Node, config_cls):
    """Declare every leaf of ``config_cls`` as a parameter of ``node`` (groups by dotted
    name, ``startup.min_views``); return the filled dataclass. ValueError (the node does not
    start) for an ``image_transport`` that is not one of its field's (:func:`image_transport_param`)."""
    from rclpy.parameter import Parameter

    values = {}
    for name, field, default, hint in flat_fields(config_cls):
        descriptor = ParameterDescriptor(
            description=field.metadata.get("description", ""),
            read_only=field.metadata.get("read_only", False),
        )
        if isinstance(default, (list, tuple)) and not default:
            # An empty list has no type for rclpy: declare it by its annotation.
            inner = typing.get_args(hint)
            ptype = {str: Parameter.Type.STRING_ARRAY, float: Parameter.Type.DOUBLE_ARRAY,
                     int: Parameter.Type.INTEGER_ARRAY, bool: Parameter.Type.BOOL_ARRAY}[inner[0]]
            # Declared by type with no value, it stays uninitialised unless YAML/-p set it.
            value = node.declare_parameter(name, ptype, descriptor).value
            values[name] = list(value) if value is not None else []
        else:
            value = node.declare_parameter(
                name, list(default) if isinstance(default, tuple) else default, descriptor).value
            values[name] = list(value) if isinstance(default, (list, tuple)) else value
    from hmocap_ros.io.image_codec import check_transport

    for name, field, _, _ in flat_fields(config_cls):  # checked now: nodes subscribe once the rig has come
        if "transports" in field.metadata:
            check_transport(str(values[name]), field.metadata["transports"])
    return from_flat(config_cls, values)


def unknown_parameter_overrides(node: Node) -> list[str]:
    """Parameters set for ``node`` (``-p``, ``--params-file``) that it never declared: a
    misspelt or outdated name (a grouped setting is named with its group,
    ``weighting.working_width``), which rclpy would otherwise ignore without a word."""
    declared = set(node._parameters)  # noqa: SLF001  (rclpy keeps no public list of overrides)
    return sorted(name for name in node._parameter_overrides if name not in declared)


def _suggestion(name: str, declared) -> str:
    leaf = name.rsplit(".", 1)[-1]
    near = [d for d in declared if d.rsplit(".", 1)[-1] == leaf]
    return f" (did you mean {' or '.join(sorted(near))}?)" if near else ""


def parameter_table(config_cls) -> str:
    """The parameters of a config dataclass as text: dotted name, type, default, description."""
    rows = []
    for name, field, default, hint in flat_fields(config_cls):
        tname = getattr(hint, "__name__", str(hint))
        rows.append(f"  {name} ({tname}, default {default!r})\n      {field.metadata.get('description', '')}")
    return "\n".join(rows)


def print_help(node_name: str, doc: str, config_cls=None) -> int:
    """``--help``: usage, the module doc in plain text and the parameters; the exit status (141
    when the reader of the help went away, as ``body_tracker --help | head``)."""
    from hmocap_ros.terminal import TerminalManners, plain_text

    manners = TerminalManners(node_name)
    with manners:
        print(f"usage: {node_name} [--ros-args [-p NAME:=VALUE ...] [--params-file FILE] [-r FROM:=TO ...]]\n")
        print(plain_text((doc or "").strip()) + "\n")
        if config_cls is not None:
            print("parameters (ROS parameters, defaults from config/%s.yaml when present):" % node_name)
            for cls in config_cls if isinstance(config_cls, (list, tuple)) else [config_cls]:
                print(plain_text(parameter_table(cls)))
        sys.stdout.flush()
    return manners.status or 0


def ros_args_with_default_config(node_name: str, argv: Sequence[str]) -> list[str]:
    """argv with the node's default parameter file prepended (user files and -p still override)."""
    argv = list(argv)
    path = default_config_file(node_name)
    if path is None:
        return argv
    return [argv[0], "--ros-args", "--params-file", str(path), *argv[1:]]


class ShutdownFlag:
    """Set by SIGINT/SIGTERM so a node's loop can finish its work (flush files) before exiting."""

    def __init__(self):
        self.requested = False
        self.signal_name = ""

    def install(self) -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._handle)

    def _handle(self, signum, _frame) -> None:
        self.requested = True
        self.signal_name = signal.Signals(signum).name


def run_node(
    node_factory: Callable[[], NodeT],
    node_name: str,
    doc: str,
    config_cls=None,
    args: Sequence[str] | None = None,
    on_shutdown: Callable[[NodeT], None] | None = None,
) -> int:
    """Standard ``main`` of a node: --help, default config, spin until Ctrl-C/SIGTERM, clean shutdown.

    A node whose construction rejects its parameters (``ValueError``) logs one fatal line
    naming the problem and returns 2, without a traceback."""
    argv = list(sys.argv if args is None else args)
    if any(a in ("-h", "--help") for a in argv[1:]) and "--ros-args" not in argv[1:2]:
        return print_help(node_name, doc, config_cls)
    flag = ShutdownFlag()
    rclpy.init(args=ros_args_with_default_config(node_name, argv), signal_handler_options=SignalHandlerOptions.NO)
    flag.install()
    node = None
    try:
        try:
            node = node_factory()
        except ValueError as err:
            rclpy.logging.get_logger(node_name).fatal(f"cannot start: {err}")
            return 2
        for name in unknown_parameter_overrides(node):
            node.get_logger().error(f"unknown parameter {name!r} ignored"
                                    + _suggestion(name, node._parameters))  # rclpy keeps the declared ones there
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while not flag.requested and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            if on_shutdown is not None:
                on_shutdown(node)
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


def take_rig(node: Node, rig_file: str, set_rig: Callable) -> None:
    """Give ``set_rig`` the rig of ``rig_file`` now (ValueError naming the file when it cannot
    be read: the node does not start), or, with no file, every changed rig of the latched
    ``camera_rig`` topic (:func:`changed_rig`)."""
    from hmocap_interfaces.msg import CameraRig

    from hmocap_ros.geometry.rig import RigError, load_rig

    if rig_file:
        try:
            rig = load_rig(rig_file)
        except (RigError, OSError) as err:
            raise ValueError(f"cannot load the rig: {err}") from err
        set_rig(rig)
        return

    def on_rig(msg) -> None:
        rig = changed_rig(msg, getattr(node, "rig", None), node.get_logger())  # the node's rig, None before the first
        if rig is not None:
            set_rig(rig)

    node.create_subscription(CameraRig, "camera_rig", on_rig, LATCHED_QOS)
    node.get_logger().info("waiting for the rig on camera_rig")


def changed_rig(msg, current, logger):
    """The rig of a ``camera_rig`` message when it differs from ``current`` (a node's rig or
    None); None when it is the same rig or invalid (logged)."""
    from hmocap_ros.geometry.rig import RigError
    from hmocap_ros.io.rig_messages import rig_from_msg

    try:
        rig = rig_from_msg(msg)
    except (RigError, ValueError) as err:
        logger.error(f"camera_rig: {err}")
        return None
    if current is not None and rig.isclose(current):
        return None
    return rig


def depth_camera_from_info(msg, current, logger):
    """The PinholeCamera of a ``depth/camera_info`` message, or ``current`` when it cannot be
    read (logged, throttled); a new camera, or one whose focal length changed, is logged."""
    from hmocap_ros.geometry import PinholeCamera
    from hmocap_ros.io.conversions import ConversionError, camera_info_to_dict

    try:
        camera = PinholeCamera.from_camera_info(camera_info_to_dict(msg))
    except (ConversionError, ValueError) as err:
        logger.error(f"depth/camera_info: {err}", throttle_duration_sec=5.0)
        return current
    if current is None or camera.fx != current.fx:
        logger.info(f"depth camera {camera.width}x{camera.height}, fx {camera.fx:g} px")
    return camera


def depth_from_msg(msg, encodings, logger):
    """The image of a ``depth/image_raw`` message (sensor_msgs/Image, or compressedDepth's
    CompressedImage: 16UC1 in mm, 32FC1 in m) as a numpy array, or None (logged, throttled) when
    its encoding is not one of ``encodings`` or it cannot be converted."""
    from hmocap_ros.io.conversions import ConversionError
    from hmocap_ros.io.image_codec import decoded_image, image_encoding

    try:
        encoding = image_encoding(msg)
    except ConversionError as err:
        logger.error(f"depth/image_raw: {err}", throttle_duration_sec=5.0)
        return None
    if encoding not in encodings:
        logger.error(f"depth/image_raw has encoding '{encoding}'; expected one of {encodings}",
                     throttle_duration_sec=5.0)
        return None
    try:
        return decoded_image(msg)
    except ConversionError as err:
        logger.error(f"depth/image_raw: {err}", throttle_duration_sec=5.0)
        return None


def rgb_from_msg(msg, topic: str, logger):
    """The RGB image (H, W, 3) of a colour camera's Image or CompressedImage message, or None
    (logged, throttled) when it cannot be converted or decoded."""
    from hmocap_ros.io.conversions import ConversionError
    from hmocap_ros.io.image_codec import decoded_rgb

    try:
        return decoded_rgb(msg)
    except ConversionError as err:
        logger.error(f"{topic}: {err}", throttle_duration_sec=5.0)
        return None


def message_class(typename: str):
    """The rclpy message class for 'pkg/msg/Name' (ImportError with a clear text if unknown)."""
    import importlib

    parts = typename.split("/")
    if len(parts) != 3:
        raise ImportError(f"not a ROS 2 message type name: {typename!r}")
    pkg, kind, name = parts
    try:
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ImportError, AttributeError) as err:
        raise ImportError(f"message type {typename} is not installed here ({err})") from err


def package_path(*parts: str) -> Path:
    """A path inside the installed hmocap_ros Python package."""
    return Path(__file__).resolve().parents[1].joinpath(*parts)
