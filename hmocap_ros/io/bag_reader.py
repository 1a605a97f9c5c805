"""Reading rosbag2 bags (MCAP file, rosbag2 directory, or sqlite3) for offline processing.

:class:`BagReader` yields time-ordered messages, decoded as rosbags dataclasses (the
conversion functions of :mod:`hmocap_ros.io.conversions` accept them like rclpy messages)
or as raw CDR bytes for replay; :meth:`BagReader.frame_sets` groups the images of several
cameras by their ``header.stamp`` with the same :class:`~hmocap_ros.stamp_sync.StampSynchronizer`
the live nodes use. Type definitions come from the bag itself, so bags of other tools
read as long as they are rosbag2 bags. A bag whose recording did not close (no MCAP summary)
is read up to its last complete record, with a warning that names ``hmocap repair``.

Camera images may be raw (``/<camera>/image_raw``, sensor_msgs/Image) or image_transport's
``compressed`` (``/<camera>/image_raw/compressed``, sensor_msgs/CompressedImage): decoded reads
(:meth:`BagReader.messages` without ``raw``, :meth:`BagReader.frame_sets`) give a compressed topic
under its image topic's name when the bag has no raw one, and ``topics(compressed_as_raw=True)``
lists it there, so a reader asks for ``/cam_1/image_raw`` and decodes what it gets with
:mod:`hmocap_ros.io.image_codec`.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader
from rosbags.interfaces import ConnectionExtRosbag2, QosDurability

from .image_codec import COMPRESSED_SUFFIX
from .msg_factory import stamp_to_ns
from .summaryless_mcap import summaryless_view
from .typestore import hmocap_typestore

_log = logging.getLogger(__name__)


class BagReadError(RuntimeError):
    """A bag could not be opened or read; the message starts with the bag's path."""


def _reason(err: Exception) -> str:
    return (str(err) or type(err).__name__).rstrip(".")


def unreadable(path: Path, reason: str) -> BagReadError:
    """The error for a file or folder that is not a bag or is damaged."""
    return BagReadError(f"{path}: not a readable bag ({reason})")


def _damage(f, offset: int, err: Exception) -> str:
    """Where and why an MCAP file cannot be read, for a record starting at ``offset`` whose
    parsing raised ``err``: e.g. "chunk record at byte 43: decompression error"."""
    from mcap.opcode import Opcode

    if offset == 0:
        return f"the file start: {_reason(err)}"
    size = f.seek(0, 2)
    f.seek(offset)
    head = f.read(9)
    if not head:
        return f"byte {offset}: {_reason(err)}"
    try:
        name = Opcode(head[0]).name.lower().replace("_", " ") + " record"
    except ValueError:
        name = f"record of unknown opcode 0x{head[0]:02x}"
    if len(head) < 9 or offset + 9 + int.from_bytes(head[1:], "little") > size:
        return f"{name} at byte {offset}: the file ends inside it"
    return f"{name} at byte {offset}: {_reason(err)}"


def scan_mcap(path: Path) -> None:
    """Read every record of one MCAP file from magic to magic, decompressing the chunks and
    checking the chunk and data-section CRCs where the file has them; raise
    :class:`BagReadError` naming the first record that cannot be read and its byte offset."""
    from mcap.stream_reader import StreamReader

    with path.open("rb") as f:
        records = StreamReader(f, validate_crcs=True).records
        while True:
            offset = f.tell()
            try:
                next(records)
            except StopIteration:
                return
            # Damaged bytes surface as whatever the parser or the decompressor trips on.
            except Exception as err:
                raise unreadable(path, _damage(f, offset, err)) from err


@dataclass(frozen=True)
class TopicInfo:
    """What a bag holds on one topic."""

    topic: str
    msgtype: str
    count: int
    latched: bool


@dataclass(frozen=True)
class BagMessage:
    """One message of a bag: ``log_time_ns`` is the recording time, ``msg`` decoded or raw."""

    topic: str
    msgtype: str
    log_time_ns: int
    msg: Any  # a rosbags message of the type ``msgtype``, or its CDR bytes when read raw


class BagReader:
    """Context manager over one bag (``.mcap`` file or rosbag2 directory)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        if not self.path.exists():
            raise BagReadError(f"{self.path}: does not exist")
        self.summaryless = summaryless_view(self.path)
        if self.summaryless is not None:
            _log.warning("%s", self.repair_hint())
        elif self.path.is_dir() and not (self.path / "metadata.yaml").is_file():
            raise unreadable(self.path, "a folder without metadata.yaml")
        try:
            # rosbags reads an MCAP file through exists(), is_dir(), suffix and open() only, all SealedMcap has
            self._reader = AnyReader([self.summaryless or self.path],  # type: ignore[list-item]
                                     default_typestore=hmocap_typestore())
        except Exception as err:  # rosbags raises several error types for what is not a bag
            raise unreadable(self.path, _reason(err)) from err

    def repair_hint(self) -> str:
        """For a bag that did not close: what is read of it, and the command that makes it whole."""
        if self.summaryless is None:
            return ""
        cut = self.summaryless.dropped_bytes
        return (f"{self.path}: the recording did not close (no MCAP summary); read up to its last "
                f"complete record{f', {cut} bytes of a cut record left out' if cut else ''}; "
                f"`hmocap repair {self.path}` rewrites it whole")

    def open(self) -> BagReader:
        try:
            self._reader.open()
        except Exception as err:  # rosbags raises several error types for a damaged file
            hint = self.repair_hint()
            raise unreadable(self.path, _reason(err) + (f"; {hint}" if hint else "")) from err
        return self

    def close(self) -> None:
        self._reader.close()

    def __enter__(self) -> BagReader:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def start_ns(self) -> int:
        return self._reader.start_time

    @property
    def end_ns(self) -> int:
        return self._reader.end_time

    def topics(self, compressed_as_raw: bool = False) -> dict[str, TopicInfo]:
        """Topics of the bag with type, message count and whether they were latched; with
        ``compressed_as_raw`` each compressed image topic also under its image topic's name
        (:meth:`compressed_topics`), as decoded reads give it."""
        out = self._stored_topics()
        if compressed_as_raw:
            out.update({raw: replace(out[topic], topic=raw) for raw, topic in self.compressed_topics().items()})
        return out

    def compressed_topics(self) -> dict[str, str]:
        """Image topic -> its image_transport compressed topic, for each ``<topic>/compressed``
        of type sensor_msgs/CompressedImage whose ``<topic>`` the bag does not hold."""
        stored = {c.topic: c.msgtype for c in self._reader.connections}
        return {topic[:-len(COMPRESSED_SUFFIX)]: topic for topic, msgtype in stored.items()
                if topic.endswith(COMPRESSED_SUFFIX) and msgtype == "sensor_msgs/msg/CompressedImage"
                and topic[:-len(COMPRESSED_SUFFIX)] not in stored}

    def _stored_topics(self) -> dict[str, TopicInfo]:
        out = {}
        for topic, info in self._reader.topics.items():
            latched = any(
                isinstance(c.ext, ConnectionExtRosbag2)
                and any(q.durability == QosDurability.TRANSIENT_LOCAL for q in c.ext.offered_qos_profiles)
                for c in info.connections
            )
            out[topic] = TopicInfo(topic, info.msgtype or "", info.msgcount, latched)
        return out

    def check_topics(self, topics: Iterable[str], compressed_as_raw: bool = False) -> None:
        """Raise :class:`BagReadError` naming those of ``topics`` that the bag does not hold
        (with ``compressed_as_raw``: nor as a compressed image topic)."""
        available = {c.topic for c in self._reader.connections}
        if compressed_as_raw:
            available |= set(self.compressed_topics())
        missing = sorted(set(topics) - available)
        if missing:
            raise BagReadError(f"{self.path}: no topic {', '.join(missing)} in the bag "
                               f"(it has {', '.join(sorted(available)) or 'none'})")

    def messages(self, topics: Iterable[str] | None = None, raw: bool = False) -> Iterator[BagMessage]:
        """Messages in recording-time order, optionally only of ``topics``; decoded unless ``raw``.
        Decoded, an image topic the bag holds only compressed comes from its compressed topic,
        under the name asked for (module docstring)."""
        wanted = None if topics is None else set(topics)
        names: dict[str, str] = {}  # stored topic -> the name it is given
        if wanted is not None:
            self.check_topics(wanted, compressed_as_raw=not raw)
            if not raw:
                names = {stored: topic for topic, stored in self.compressed_topics().items()
                         if topic in wanted and stored not in wanted}
                wanted |= set(names)
        connections = [c for c in self._reader.connections if wanted is None or c.topic in wanted]
        if not connections:
            return
        n = 0
        try:
            for conn, log_ns, data in self._reader.messages(connections=connections):
                msg = data if raw else self._reader.deserialize(data, conn.msgtype)
                yield BagMessage(names.get(conn.topic, conn.topic), conn.msgtype, log_ns, msg)
                n += 1
        except Exception as err:  # rosbags raises several error types for a damaged file
            raise unreadable(self.path, f"message {n + 1} in time order: {_reason(err)}") from err

    def verify(self) -> None:
        """Read the whole bag: every record of its MCAP files (:func:`scan_mcap`), then every
        message, whose count per topic must match the bag's summary. Raises
        :class:`BagReadError` naming the first part that cannot be read."""
        files = [self.path] if self.path.is_file() else sorted(self.path.glob("*.mcap"))
        for path in files:
            if path.suffix == ".mcap":
                scan_mcap(path)
        counts = Counter(m.topic for m in self.messages(raw=True))
        for topic, info in sorted(self.topics().items()):
            if counts[topic] != info.count:
                raise unreadable(self.path, f"{counts[topic]} of the {info.count} messages on {topic} read")

    def first(self, topic: str):
        """The first decoded message on ``topic`` (e.g. the latched ``camera_rig``), or None."""
        for item in self.messages([topic]):
            return item.msg
        return None

    def frame_sets(
        self,
        topics: Sequence[str],
        slop_ns: int = 0,
        allow_partial: bool = False,
        min_topics: int | None = None,
    ) -> Iterator[tuple[int, dict[str, Any]]]:
        """Synchronised sets ``(stamp_ns, {topic: msg})`` over ``topics`` by ``header.stamp``.

        Exact stamps when ``slop_ns`` is 0, else approximate matching within the slop.
        With ``allow_partial``, sets missing some topics (a dropped camera) are yielded
        too when at least ``min_topics`` are present.
        """
        from hmocap_ros.stamp_sync import synchronize

        stream = ((m.topic, stamp_to_ns(m.msg.header.stamp), m.msg) for m in self.messages(topics))
        yield from synchronize(
            stream, list(topics), slop_ns=slop_ns, allow_partial=allow_partial, min_keys=min_topics
        )
