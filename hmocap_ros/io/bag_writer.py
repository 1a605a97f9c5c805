"""Writing rosbag2 MCAP bags with rosbags (no rosbag2 needed).

A bag path ending in ``.mcap`` gives a single MCAP file (readable by ``ros2 bag play``,
Foxglove, ``mcap-ros2-support`` and :mod:`hmocap_ros.io.bag_reader`); any other path
gives a rosbag2 directory (``metadata.yaml`` + ``<name>.mcap``). The single file is
written into a hidden sibling directory and moved into place on :meth:`BagWriter.close`.

Latched topics are stored with a transient-local offered QoS profile, so a replay
re-publishes them as latched.
"""

from __future__ import annotations

import shutil
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from rosbags.interfaces import Connection, Qos
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.typesys.store import Typestore

from .msg_factory import typename_of
from .typestore import hmocap_typestore


class BagWriteError(RuntimeError):
    """A bag could not be written."""


@dataclass(frozen=True)
class QosProfile:
    """The QoS facts a bag keeps about a topic (rmw enum values, as rosbag2 stores them)."""

    reliability: int = 1  # 1 reliable, 2 best effort
    durability: int = 2  # 1 transient local (latched), 2 volatile
    depth: int = 10

    @property
    def latched(self) -> bool:
        return self.durability == 1


LATCHED = QosProfile(durability=1, depth=1)
VOLATILE = QosProfile()


def _rosbags_qos(profile: QosProfile):
    """The rosbags ``Qos`` record for a profile (infinite deadlines as rosbag2 writes them)."""
    from rosbags.interfaces import (
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    infinite = QosTime(sec=2147483647, nsec=4294967295)
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=profile.depth,
        reliability=QosReliability(profile.reliability),
        durability=QosDurability(profile.durability),
        deadline=infinite,
        lifespan=infinite,
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=infinite,
        avoid_ros_namespace_conventions=False,
    )


class BagWriter:
    """Context manager writing messages (objects or raw CDR bytes) to an MCAP bag.

    >>> with BagWriter("run.mcap") as bag:                      # doctest: +SKIP
    ...     bag.write("cam_1/image_raw", image_msg, stamp_ns)
    """

    def __init__(self, path: str | Path, typestore: Typestore | None = None, compress: bool = True):
        self.path = Path(path)
        self.typestore = typestore or hmocap_typestore()
        self.single_file = self.path.suffix == ".mcap"
        if self.path.exists():
            raise BagWriteError(f"{self.path} exists already; refusing to overwrite it")
        if self.single_file:
            self._dir = self.path.with_name(f".{self.path.stem}.writing")
            if self._dir.exists():
                shutil.rmtree(self._dir)
        else:
            self._dir = self.path
        self._writer = Writer(self._dir, version=9, storage_plugin=StoragePlugin.MCAP)
        if compress:
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._connections: dict[str, Connection] = {}
        self.counts: dict[str, int] = {}
        self._open = False

    def open(self) -> BagWriter:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._writer.open()
        self._open = True
        return self

    def add_topic(self, topic: str, msgtype: str, qos: QosProfile = VOLATILE) -> None:
        """Declare a topic (done implicitly by :meth:`write` for volatile topics)."""
        if topic in self._connections:
            if self._connections[topic].msgtype != msgtype:
                raise BagWriteError(
                    f"topic {topic!r} already holds {self._connections[topic].msgtype}, not {msgtype}"
                )
            return
        if msgtype not in self.typestore.fielddefs:
            raise BagWriteError(f"unknown message type {msgtype!r} for topic {topic!r}")
        self._connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=self.typestore, offered_qos_profiles=[_rosbags_qos(qos)]
        )
        self.counts[topic] = 0

    def write(self, topic: str, msg, stamp_ns: int, msgtype: str | None = None) -> None:
        """Write one message: a rosbags dataclass, or raw CDR ``bytes`` with ``msgtype`` given."""
        if not self._open:
            raise BagWriteError("the bag is not open (use it as a context manager)")
        if isinstance(msg, (bytes, bytearray, memoryview)):
            if msgtype is None and topic not in self._connections:
                raise BagWriteError(f"raw data for new topic {topic!r} needs its msgtype")
            raw = bytes(msg)
        else:
            msgtype = msgtype or typename_of(msg)
            raw = bytes(self.typestore.serialize_cdr(msg, msgtype))
        if topic not in self._connections:
            self.add_topic(topic, msgtype)
        self._writer.write(self._connections[topic], int(stamp_ns), raw)
        self.counts[topic] += 1

    def close(self) -> None:
        """Flush and close; for a single-file bag, move the MCAP file into place."""
        if not self._open:
            return
        self._open = False
        self._writer.close()
        if self.single_file:
            inner = self._dir / f"{self._dir.name}.mcap"
            shutil.move(str(inner), str(self.path))
            shutil.rmtree(self._dir)

    def __enter__(self) -> BagWriter:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()


@contextmanager
def whole_bag(path: str | Path, **kwargs):
    """A :class:`BagWriter` for generated data: if the block raises or is interrupted
    (Ctrl-C), the bag is removed instead of closed into place, so a data set on disk is either
    complete or absent (a cache that checks ``exists()`` never takes a truncated one).
    Recorders keep what they have instead: they use :class:`BagWriter` itself."""
    path = Path(path)
    writer = BagWriter(path, **kwargs)
    try:
        with writer as bag:
            yield bag
    except BaseException:
        if path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)
        raise
