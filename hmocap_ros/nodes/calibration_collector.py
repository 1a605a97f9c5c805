"""``hmocap calibrate --live``: the calibration session gathered from the cameras' topics.

Subscribes to ``/<cam>/image_raw`` (sensor_msgs/Image), or where only that is published to
image_transport's ``/<cam>/image_raw/compressed`` (sensor_msgs/CompressedImage, JPEG or PNG), of
the cameras named by ``--cameras`` (else of every camera with such a topic seen within a few
seconds), their
``/<cam>/camera_info`` and ``/camera_rig`` for the intrinsics when they are published (each
topic once its publisher is seen, best effort when the publisher is, else reliable); groups
the images by stamp (:class:`~hmocap_ros.calibration.live_collection.FrameSetCollector`, the
nodes' stamp synchroniser) and
searches at most ``--fps`` frame sets a second for the board
(:class:`~hmocap_ros.calibration.session.CalibrationSession`) for ``--seconds`` from the first
frame set, or until every camera has seen the board ``--min-views`` times, or Ctrl-C; progress
every two seconds. ROS runs in a thread of its own; this thread searches the images.
"""

from __future__ import annotations

import argparse
import queue
import re
import threading
import time

import numpy as np

__all__ = ["collect_live"]

_DISCOVERY_S = 3.0  # waiting for the image topics when --cameras is not given
_MAX_QUEUED = 200  # frame sets waiting for the board search; more are dropped (counted)
_PROGRESS_S = 2.0
_IMAGE_TOPIC = re.compile(r"^/(.+)/image_raw(/compressed)?$")


def _discover(node, executor, log) -> list:
    deadline = time.monotonic() + _DISCOVERY_S
    names: list = []
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
        names = sorted({m.group(1) for t, types in node.get_topic_names_and_types()
                        if (m := _IMAGE_TOPIC.match(t))
                        and ("sensor_msgs/msg/CompressedImage" if m.group(2) else "sensor_msgs/msg/Image") in types})
    if not names:
        raise ValueError(f"no /<camera>/image_raw topic of sensor_msgs/Image (nor its /compressed) within "
                         f"{_DISCOVERY_S:g} s; "
                         f"name the cameras with --cameras")
    log(f"cameras found: {', '.join(names)}")
    return names


def collect_live(ns: argparse.Namespace, spec, ros_args: list, log=print):
    """Gather a :class:`~hmocap_ros.calibration.session.CalibrationSession` from the topics
    (module docstring)."""
    import rclpy
    from hmocap_interfaces.msg import CameraRig
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions
    from sensor_msgs.msg import CameraInfo, CompressedImage, Image

    from hmocap_ros.calibration.detection import MIN_CORNERS
    from hmocap_ros.calibration.live_collection import FrameSetCollector, enough_views
    from hmocap_ros.calibration.session import CalibrationSession
    from hmocap_ros.io.camera_info import camera_info_to_dict
    from hmocap_ros.io.conversion_errors import ConversionError
    from hmocap_ros.io.image_codec import decoded_rgb
    from hmocap_ros.io.msg_factory import stamp_to_ns
    from hmocap_ros.io.rig_messages import rig_from_msg

    if ns.seconds <= 0 or ns.fps <= 0 or ns.min_views < 0:
        raise ValueError("--seconds and --fps must be positive, --min-views not negative")
    rclpy.init(args=["hmocap_calibrate", *(ros_args or [])], signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("hmocap_calibrate")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinner = None
    stop = threading.Event()
    try:
        names = [n.strip().strip("/") for n in ns.cameras.split(",") if n.strip()] if ns.cameras \
            else _discover(node, executor, log)
        if len(set(names)) != len(names) or len(names) < 2:
            raise ValueError(f"--cameras must name 2 or more distinct cameras, got {names}")
        session = CalibrationSession(names, spec)
        collector = FrameSetCollector(len(names), min_interval_ns=int(1e9 / ns.fps))
        ready: queue.Queue = queue.Queue(maxsize=_MAX_QUEUED)
        lock = threading.Lock()
        counts = {"dropped": 0}
        received = np.zeros(len(names), int)

        def on_image(k: int):
            def callback(msg) -> None:
                received[k] += 1
                with lock:
                    sets = collector.add(k, stamp_to_ns(msg.header.stamp), msg)
                for item in sets:
                    try:
                        ready.put_nowait(item)
                    except queue.Full:
                        counts["dropped"] += 1
            return callback

        def rgb_of(k: int, msg):
            """The image decoded, or None (logged) when it cannot be."""
            try:
                return decoded_rgb(msg)
            except ConversionError as err:
                log(f"  /{names[k]}/image_raw: {err} (image skipped)")
                return None

        def on_info(name: str):
            def callback(msg) -> None:
                if name not in session.intrinsics or session.intrinsics[name][4] == "/camera_rig":
                    info = camera_info_to_dict(msg)
                    session.intrinsics[name] = (np.asarray(info["K"]).reshape(3, 3),
                                                np.asarray(info["D"], float), int(info["width"]),
                                                int(info["height"]), f"/{name}/camera_info")
            return callback

        def on_rig(msg) -> None:
            for cam in rig_from_msg(msg):
                if cam.name in names and cam.name not in session.intrinsics:
                    session.intrinsics[cam.name] = (cam.K, cam.D, cam.width, cam.height, "/camera_rig")

        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        node.create_subscription(CameraRig, "/camera_rig", on_rig, latched)
        wanted = {f"/{name}/image_raw": (Image, on_image(k)) for k, name in enumerate(names)}
        # image_transport's compressed topic, taken when it is published and the raw one is not
        wanted.update({f"/{name}/image_raw/compressed": (CompressedImage, on_image(k))
                       for k, name in enumerate(names)})
        wanted.update({f"/{name}/camera_info": (CameraInfo, on_info(name)) for name in names})

        def subscribe_published() -> None:
            """Subscribe each topic once it has a publisher, reliable unless one is best effort."""
            for topic in list(wanted):
                infos = node.get_publishers_info_by_topic(topic)
                if not infos:
                    continue
                best_effort = any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos)
                if topic.endswith("/compressed") and node.get_publishers_info_by_topic(topic[:-11]):
                    continue  # the raw topic is published too: it is taken
                cls, callback = wanted.pop(topic)
                wanted.pop(topic[:-11] if topic.endswith("/compressed") else topic + "/compressed", None)
                node.create_subscription(cls, topic, callback, QoSProfile(
                    depth=30, reliability=ReliabilityPolicy.BEST_EFFORT if best_effort
                    else ReliabilityPolicy.RELIABLE))

        def spin() -> None:
            next_check = 0.0
            while not stop.is_set() and rclpy.ok():
                if wanted and time.monotonic() >= next_check:
                    subscribe_published()
                    next_check = time.monotonic() + 0.2
                executor.spin_once(timeout_sec=0.05)

        spinner = threading.Thread(target=spin, daemon=True)
        spinner.start()
        log(f"collecting frame sets of {', '.join(names)} for {ns.seconds:g} s "
            f"(at most {ns.fps:g} a second)")
        start = time.monotonic()
        first = None
        seen = np.zeros(len(names), int)
        n_sets = 0
        next_progress = start + _PROGRESS_S
        try:
            while True:
                now = time.monotonic()
                if first is None and now - start > ns.seconds:
                    silent = [n for n, r in zip(names, received) if r == 0]
                    raise ValueError(f"no frame set of {', '.join(names)} (images of every camera "
                                     f"with one stamp) within {ns.seconds:g} s"
                                     + (f"; no image from {', '.join(silent)}" if silent else ""))
                if first is not None and (now - first > ns.seconds or enough_views(seen, ns.min_views)):
                    break
                try:
                    stamp, msgs = ready.get(timeout=0.1)
                except queue.Empty:
                    msgs = None
                if msgs is not None:
                    first = now if first is None else first
                    n_sets += 1
                    for k, msg in enumerate(msgs):
                        rgb = rgb_of(k, msg)
                        if rgb is not None:
                            seen[k] += session.add_image(k, stamp, rgb).n >= MIN_CORNERS
                if now >= next_progress and first is not None:
                    next_progress = now + _PROGRESS_S
                    log(f"  {now - first:4.0f} s: {n_sets} frame sets, board seen by "
                        + ", ".join(f"{n} {s}" for n, s in zip(names, seen)))
        except KeyboardInterrupt:
            log("  stopped (Ctrl-C): calibrating with what was collected")
        stop.set()
        spinner.join()
        spinner = None
        while not ready.empty():  # sets that arrived before the end
            stamp, msgs = ready.get_nowait()
            n_sets += 1
            for k, msg in enumerate(msgs):
                rgb = rgb_of(k, msg)
                if rgb is not None:
                    seen[k] += session.add_image(k, stamp, rgb).n >= MIN_CORNERS
        log(f"collected {n_sets} frame sets ({collector.n_skipped} skipped for --fps, "
            f"{collector.n_dropped} images in no complete set, {counts['dropped']} sets dropped "
            f"while busy); board seen by "
            + ", ".join(f"{n} {s}" for n, s in zip(names, seen)))
        if n_sets == 0:
            raise ValueError(f"no frame set of {', '.join(names)} collected")
        return session
    finally:
        stop.set()
        if spinner is not None:
            spinner.join()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
