"""Writing rosbag2 MCAP bags (no rosbag2 needed), safe against the writer being killed.

A bag path ending in ``.mcap`` gives a single MCAP file (readable by ``ros2 bag play``,
Foxglove, ``mcap-ros2-support`` and :mod:`hmocap_ros.io.bag_reader`); any other path
gives a rosbag2 directory (``metadata.yaml`` + ``<name>.mcap``, the YAML written on close).

The MCAP file is written at its final path. Messages collect in a chunk that is compressed and
appended when it reaches ``chunk_size`` bytes or is ``flush_period_s`` old, whichever comes
first (``flush_period_s=None``: by size only, so that the same messages always give the same
bytes, whatever the wall clock did while they were written); every append leaves the file a
valid MCAP without summary (see :mod:`~hmocap_ros.io.summaryless_mcap`), so a writer killed at
any moment leaves a bag holding every message up to its last flush. :meth:`BagWriter.close` adds
the summary (indexes and statistics). A full disk raises :class:`BagDiskFullError` and leaves
the bag readable as flushed before.

Latched topics are stored with a transient-local offered QoS profile, so a replay
re-publishes them as latched.
"""

from __future__ import annotations

import errno
import os
import shutil
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import yaml
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.interfaces import Qos
from rosbags.rosbag2.metadata import dump_qos_v9
from rosbags.typesys.store import Typestore

from .msg_factory import typename_of
from .summaryless_mcap import MCAP_TRAILER
from .typestore import hmocap_typestore


class BagWriteError(RuntimeError):
    """A bag could not be written."""


class BagDiskFullError(BagWriteError):
    """The disk filled up while writing a bag; the bag keeps what was flushed before."""


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


class SealedMcapFile:
    """Output stream for an MCAP writer that keeps the file on disk a valid MCAP.

    Written bytes are held in memory; :meth:`flush` appends them with one write, followed by
    :data:`MCAP_TRAILER`, which the next flush overwrites. :meth:`close` appends the rest
    (the writer's summary and footer) without the trailer. A failed write (disk full) puts the
    trailer back after the last flushed bytes and raises :class:`BagWriteError`."""

    def __init__(self, path: Path):
        self.path = path
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self._end = 0
        self._pending = bytearray()

    @property
    def pending(self) -> int:
        return len(self._pending)

    def write(self, data) -> int:
        self._pending += data
        return len(data)

    def tell(self) -> int:
        return self._end + len(self._pending)

    def flush(self) -> None:
        self._append(MCAP_TRAILER)

    def sync(self) -> None:
        """Push the flushed bytes to the disk itself (a power cut keeps them)."""
        os.fdatasync(self._fd)

    def close(self) -> None:
        """Append what is pending without trailer, cut the file there and close it."""
        try:
            self._append(b"")
            os.ftruncate(self._fd, self._end)
        finally:
            os.close(self._fd)

    def abandon(self) -> None:
        """Close, leaving the file as last flushed (a summary-less MCAP)."""
        os.close(self._fd)

    def _append(self, trailer: bytes) -> None:
        if not self._pending and trailer:
            return
        data = memoryview(bytes(self._pending) + trailer)
        try:
            offset = self._end
            while data:
                written = os.pwrite(self._fd, data, offset)
                data, offset = data[written:], offset + written
        except OSError as err:
            self._pending.clear()
            try:
                os.pwrite(self._fd, MCAP_TRAILER, self._end)
                os.ftruncate(self._fd, self._end + len(MCAP_TRAILER))
            except OSError:
                pass  # the reader stops at the last complete record anyway
            if err.errno == errno.ENOSPC:
                raise BagDiskFullError(
                    f"disk full writing {self.path}: the bag keeps what was written before") from err
            raise BagWriteError(f"cannot write {self.path}: {err.strerror}") from err
        self._end += len(self._pending)
        self._pending.clear()


@dataclass(frozen=True)
class TopicRecord:
    """A topic's entry in rosbag2 metadata: ``qos`` as rosbag2 stores offered QoS profiles."""

    topic: str
    msgtype: str
    qos: list
    count: int
    type_hash: str = ""


def rosbag2_info(file_name: str, topics: list[TopicRecord], start_ns: int, end_ns: int) -> dict:
    """The ``rosbag2_bagfile_information`` of a one-file MCAP bag (rosbag2 metadata version 9)."""
    count = sum(t.count for t in topics)
    start = start_ns if count else 0
    duration = max(0, end_ns - start_ns) if count else 0
    return {
        "version": 9,
        "storage_identifier": "mcap",
        "relative_file_paths": [file_name],
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": count,
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": t.topic,
                    "type": t.msgtype,
                    "serialization_format": "cdr",
                    "offered_qos_profiles": t.qos,
                    "type_description_hash": t.type_hash,
                },
                "message_count": t.count,
            }
            for t in topics
        ],
        "compression_format": "",
        "compression_mode": "",
        "files": [{"path": file_name, "starting_time": {"nanoseconds_since_epoch": start},
                   "duration": {"nanoseconds": duration}, "message_count": count}],
        "custom_data": None,
        "ros_distro": "jazzy",
    }


def write_rosbag2_metadata(directory: Path, info: dict) -> None:
    """Write ``metadata.yaml`` of a rosbag2 directory (replaced whole, never half-written)."""
    tmp = directory / ".metadata.yaml.tmp"
    tmp.write_text(yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False))
    tmp.replace(directory / "metadata.yaml")


def mcap_rosbag2_metadata(info: dict) -> dict[str, str]:
    """The ``rosbag2`` metadata record rosbag2 keeps inside an MCAP file."""
    return {"serialized_metadata": yaml.safe_dump(info, sort_keys=False).strip()}


def open_mcap_writer(stream: SealedMcapFile, compress: bool = True,
                     chunk_size: int = 1 << 20) -> McapWriter:
    """A started ``mcap`` writer with the ros2 profile, its header already on disk."""
    writer = McapWriter(stream,  # type: ignore[arg-type]  # a stream for write() and tell(), all the Writer calls
                        chunk_size=chunk_size,
                        compression=CompressionType.ZSTD if compress else CompressionType.NONE)
    writer.start(profile="ros2", library="hmocap_ros")
    stream.flush()
    return writer


@dataclass
class _Channel:
    channel_id: int
    msgtype: str
    qos: list
    type_hash: str
    count: int = 0


class BagWriter:
    """Context manager writing messages (objects or raw CDR bytes) to an MCAP bag.

    >>> with BagWriter("run.mcap") as bag:                      # doctest: +SKIP
    ...     bag.write("cam_1/image_raw", image_msg, stamp_ns)

    ``flush_period_s`` bounds how long a message waits in memory before it is on disk: call
    :meth:`flush_if_due` from time to time when messages may stop coming (``write`` calls it).
    A recorder needs it (a killed recorder loses at most that much); a writer of generated
    data gives ``None`` (chunks closed by size only), which makes its bytes a function of the
    messages alone.
    """

    def __init__(self, path: str | Path, typestore: Typestore | None = None, compress: bool = True,
                 flush_period_s: float | None = 1.0, chunk_size: int = 1 << 20):
        self.path = Path(path)
        self.typestore = typestore or hmocap_typestore()
        self.single_file = self.path.suffix == ".mcap"
        if self.path.exists():
            raise BagWriteError(f"{self.path} exists already; refusing to overwrite it")
        self.mcap_path = self.path if self.single_file else self.path / f"{self.path.name}.mcap"
        self.compress = compress
        self.flush_period_s = flush_period_s
        self.chunk_size = chunk_size
        self._channels: dict[str, _Channel] = {}
        self._schemas: dict[str, int] = {}
        self._stream: SealedMcapFile | None = None
        self._mcap: McapWriter | None = None
        self._failed = False
        self._unflushed = 0
        self._last_flush = time.monotonic()
        self._start_ns = 2**63 - 1
        self._end_ns = 0

    @property
    def counts(self) -> dict[str, int]:
        """Messages written per topic."""
        return {topic: ch.count for topic, ch in self._channels.items()}

    def open(self) -> BagWriter:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if not self.single_file:
            try:
                self.path.mkdir()
            except FileExistsError:
                raise BagWriteError(f"{self.path} exists already; refusing to overwrite it") from None
        try:
            self._stream = SealedMcapFile(self.mcap_path)
        except FileExistsError:
            raise BagWriteError(f"{self.mcap_path} exists already; refusing to overwrite it") from None
        self._mcap = self._guard(open_mcap_writer, self._stream, self.compress, self.chunk_size)
        self._last_flush = time.monotonic()
        return self

    def add_topic(self, topic: str, msgtype: str, qos: QosProfile = VOLATILE) -> None:
        """Declare a topic (done implicitly by :meth:`write` for volatile topics)."""
        if topic in self._channels:
            if self._channels[topic].msgtype != msgtype:
                raise BagWriteError(
                    f"topic {topic!r} already holds {self._channels[topic].msgtype}, not {msgtype}"
                )
            return
        if msgtype not in self.typestore.fielddefs:
            raise BagWriteError(f"unknown message type {msgtype!r} for topic {topic!r}")
        mcap, _ = self._check_open()
        if msgtype not in self._schemas:
            msgdef, _ = self.typestore.generate_msgdef(msgtype, ros_version=2)
            encoding = "ros2idl" if msgdef.startswith("=" * 80 + "\nIDL: ") else "ros2msg"
            self._schemas[msgtype] = mcap.register_schema(msgtype, encoding, msgdef.encode())
        qos_list = dump_qos_v9([_rosbags_qos(qos)])
        channel_id = mcap.register_channel(
            topic, "cdr", self._schemas[msgtype],
            {"offered_qos_profiles": yaml.safe_dump(qos_list, sort_keys=False).strip()},
        )
        self._channels[topic] = _Channel(channel_id, msgtype, qos_list, self.typestore.hash_rihs01(msgtype))

    def write(self, topic: str, msg, stamp_ns: int, msgtype: str | None = None,
              publish_ns: int | None = None) -> None:
        """Write one message: a rosbags dataclass, or raw CDR ``bytes`` with ``msgtype`` given;
        logged at ``stamp_ns``, with ``publish_ns`` (default ``stamp_ns``) as its MCAP publish time
        (a recorder's receive time)."""
        mcap, stream = self._check_open()
        if isinstance(msg, (bytes, bytearray, memoryview)):
            if msgtype is None and topic not in self._channels:
                raise BagWriteError(f"raw data for new topic {topic!r} needs its msgtype")
            raw = bytes(msg)
        else:
            msgtype = msgtype or typename_of(msg)
            raw = bytes(self.typestore.serialize_cdr(msg, msgtype))
        if topic not in self._channels:
            assert msgtype is not None  # raw data for a new topic raised above
            self.add_topic(topic, msgtype)
        channel = self._channels[topic]
        stamp_ns = int(stamp_ns)
        self._guard(mcap.add_message, channel.channel_id, stamp_ns, raw,
                    stamp_ns if publish_ns is None else int(publish_ns))
        channel.count += 1
        self._unflushed += 1
        self._start_ns = min(self._start_ns, stamp_ns)
        self._end_ns = max(self._end_ns, stamp_ns)
        if stream.pending:  # the writer closed a full chunk
            self._guard(stream.flush)
        self.flush_if_due()

    def flush_if_due(self) -> None:
        """Flush when messages have waited ``flush_period_s`` since the last flush (never
        with ``flush_period_s=None``)."""
        if self.flush_period_s is None:
            return
        if self._unflushed and time.monotonic() - self._last_flush >= self.flush_period_s:
            self.flush()

    def flush(self) -> None:
        """Append the open chunk to the file and push it to the disk."""
        mcap, stream = self._check_open()
        self._guard(mcap.flush)
        self._guard(stream.sync)
        self._unflushed = 0
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Write the summary and close; a rosbag2 directory also gets its ``metadata.yaml``.

        After a failed write the file is closed as last flushed, without summary."""
        if self._stream is None:
            return
        stream, self._stream = self._stream, None
        if self._failed:
            stream.abandon()
            return
        info = rosbag2_info(self.mcap_path.name, self._topic_records(), self._start_ns, self._end_ns)
        try:
            assert self._mcap is not None  # open() made it with the stream
            self._mcap.add_metadata("rosbag2", mcap_rosbag2_metadata(info))
            self._mcap.finish()
            stream.close()
        except BaseException:
            stream.abandon()
            raise
        if not self.single_file:
            write_rosbag2_metadata(self.path, info)

    def _topic_records(self) -> list[TopicRecord]:
        return [TopicRecord(topic, ch.msgtype, ch.qos, ch.count, ch.type_hash)
                for topic, ch in self._channels.items()]

    def _check_open(self) -> tuple[McapWriter, SealedMcapFile]:
        """The open writer and its stream; BagWriteError when the bag is closed or failed."""
        if self._stream is None:
            raise BagWriteError("the bag is not open (use it as a context manager)")
        if self._failed:
            raise BagWriteError(f"writing {self.path} failed before; the bag is closed as last flushed")
        assert self._mcap is not None  # open() made it with the stream
        return self._mcap, self._stream

    def _guard(self, func, *args):
        try:
            return func(*args)
        except BagWriteError:
            self._failed = True
            raise

    def __enter__(self) -> BagWriter:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()


@contextmanager
def whole_bag(path: str | Path, **kwargs):
    """A :class:`BagWriter` for generated data, written in the hidden folder ``.NAME.partial``
    and moved to ``path`` when the block completes; if the block raises or is interrupted
    (Ctrl-C), nothing is left at ``path``, so a data set on disk is either complete or absent
    (a cache that checks ``exists()`` never takes a truncated one). A folder left by a killed
    run is replaced. Recorders keep what they have instead: they use :class:`BagWriter` itself.

    Chunks are closed by size only (``flush_period_s=None`` unless given): such a bag is never
    read half-written, so a timed flush would only make its bytes depend on the wall clock."""
    path = Path(path)
    kwargs.setdefault("flush_period_s", None)
    if path.exists():
        raise BagWriteError(f"{path} exists already; refusing to overwrite it")
    staging = path.with_name(f".{path.name}.partial")
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir(parents=True)
    try:
        with BagWriter(staging / path.name, **kwargs) as bag:
            yield bag
        (staging / path.name).rename(path)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
