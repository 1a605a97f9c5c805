"""Reading rosbag2 bags (MCAP file, rosbag2 directory, or sqlite3) for offline processing.

:class:`BagReader` yields time-ordered messages, decoded as rosbags dataclasses (the
conversion functions of :mod:`hmocap_ros.io.conversions` accept them like rclpy messages)
or as raw CDR bytes for replay; :meth:`BagReader.frame_sets` groups the images of several
cameras by their ``header.stamp`` with the same :class:`~hmocap_ros.stamp_sync.StampSynchronizer`
the live nodes use. Type definitions come from the bag itself, so bags of other tools
read as long as they are rosbag2 bags.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosDurability

from .msg_factory import stamp_to_ns
from .typestore import hmocap_typestore


class BagReadError(RuntimeError):
    """A bag could not be opened or read."""


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
    msg: object


class BagReader:
    """Context manager over one bag (``.mcap`` file or rosbag2 directory)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        if not self.path.exists():
            raise BagReadError(f"bag {self.path} does not exist")
        self._reader = AnyReader([self.path], default_typestore=hmocap_typestore())

    def open(self) -> BagReader:
        try:
            self._reader.open()
        except Exception as err:  # rosbags raises several error types for a bad file
            raise BagReadError(f"cannot read bag {self.path}: {err}") from err
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

    def topics(self) -> dict[str, TopicInfo]:
        """Topics of the bag with type, message count and whether they were latched."""
        out = {}
        for topic, info in self._reader.topics.items():
            latched = any(
                getattr(c.ext, "offered_qos_profiles", None)
                and any(q.durability == QosDurability.TRANSIENT_LOCAL for q in c.ext.offered_qos_profiles)
                for c in info.connections
            )
            out[topic] = TopicInfo(topic, info.msgtype or "", info.msgcount, latched)
        return out

    def messages(self, topics: Iterable[str] | None = None, raw: bool = False) -> Iterator[BagMessage]:
        """Messages in recording-time order, optionally only of ``topics``; decoded unless ``raw``."""
        wanted = None if topics is None else set(topics)
        connections = [c for c in self._reader.connections if wanted is None or c.topic in wanted]
        if wanted is not None:
            missing = wanted - {c.topic for c in connections}
            if missing:
                raise BagReadError(f"bag {self.path} has no topic(s) {sorted(missing)}")
        if not connections:
            return
        try:
            for conn, log_ns, data in self._reader.messages(connections=connections):
                msg = data if raw else self._reader.deserialize(data, conn.msgtype)
                yield BagMessage(conn.topic, conn.msgtype, log_ns, msg)
        except Exception as err:
            if isinstance(err, BagReadError):
                raise
            raise BagReadError(f"bag {self.path} is corrupt or truncated: {err}") from err

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
    ) -> Iterator[tuple[int, dict[str, object]]]:
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
