"""A bag's camera images rewritten as image_transport's ``compressed`` transport (no rclpy).

:func:`compress_bag_images` copies a bag with every camera image (``/<camera>/image_raw``,
sensor_msgs/Image) written as image_transport's ``compressed`` topic
(``/<camera>/image_raw/compressed``, sensor_msgs/CompressedImage, JPEG or lossless PNG) and every
other topic (rig, masks, ground truth) unchanged, as a recording of compressed cameras would
hold them. Readers take either kind alike (:class:`~hmocap_ros.io.bag_reader.BagReader`).
"""
from __future__ import annotations

import re
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["CompressedCopy", "compress_bag_images"]

_CAMERA_IMAGE = re.compile(r"^/[^/]+/image_raw$")


@dataclass(frozen=True)
class CompressedCopy:
    """What :func:`compress_bag_images` wrote: camera images, the seconds spent encoding them,
    and the bytes of their ``data`` before and after."""

    images: int
    encode_seconds: float
    raw_bytes: int
    compressed_bytes: int


def compress_bag_images(source: str | Path, out: str | Path, codec: str = "jpeg", quality: int = 90,
                        frames: int | None = None, topics: list[str] | None = None) -> CompressedCopy:
    """Write ``out``: ``source`` with its camera images (or the image topics ``topics``: masks
    too) as ``codec`` (``jpeg`` at ``quality``, or ``png``) CompressedImage on
    ``<topic>/compressed`` (module docstring), or with ``compressedDepth`` its 16UC1 depth images
    ``topics`` on ``<topic>/compressedDepth``; with ``frames``, only the messages up to the stamp
    of the ``frames``-th image of the first of them (and the latched ones). The images keep their
    stamps, frame ids and log times; a colour image is encoded as RGB, a mono one as mono."""
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.bag_writer import LATCHED, VOLATILE, whole_bag
    from hmocap_ros.io.compressed_images import numpy_to_compressed
    from hmocap_ros.io.image_codec import transport_topic
    from hmocap_ros.io.images import image_to_numpy, image_to_rgb
    from hmocap_ros.io.msg_factory import RosbagsFactory, stamp_to_ns
    from hmocap_ros.io.typestore import hmocap_typestore

    factory = RosbagsFactory(hmocap_typestore())
    transport = "compressedDepth" if codec == "compressedDepth" else "compressed"
    images, seconds, raw_bytes, compressed_bytes = 0, 0.0, 0, 0
    with BagReader(source) as reader:
        available = reader.topics()
        cameras = sorted(t for t, info in available.items() if info.msgtype == "sensor_msgs/msg/Image"
                         and (t in topics if topics is not None else _CAMERA_IMAGE.match(t)))
        last = None
        if frames is not None and cameras:
            stamps = sorted(stamp_to_ns(m.msg.header.stamp) for m in reader.messages(cameras[:1]))
            last = stamps[min(frames, len(stamps)) - 1] if stamps else None
        with whole_bag(out) as writer:
            for topic, info in available.items():
                compressed = topic in cameras
                writer.add_topic(transport_topic(topic, transport) if compressed else topic,
                                 "sensor_msgs/msg/CompressedImage" if compressed else info.msgtype,
                                 LATCHED if info.latched else VOLATILE)
            for item in reader.messages():
                if last is not None and item.log_time_ns > last and not available[item.topic].latched:
                    break
                msg, topic = item.msg, item.topic
                if topic in cameras:
                    t0 = time.perf_counter()
                    pixels = image_to_numpy(msg) if msg.encoding in ("mono8", "16UC1") else image_to_rgb(msg)
                    raw_bytes += len(msg.data)
                    msg = numpy_to_compressed(pixels, codec, stamp_to_ns(msg.header.stamp), msg.header.frame_id,
                                              factory, quality=quality)
                    seconds += time.perf_counter() - t0
                    images += 1
                    compressed_bytes += len(msg.data)
                    topic = transport_topic(topic, transport)
                writer.write(topic, msg, item.log_time_ns)
    return CompressedCopy(images, seconds, raw_bytes, compressed_bytes)
