"""Header stamps of serialized ROS 2 messages, read from their CDR bytes without decoding them,
and the log times a recording gives its messages by them (:class:`LogTimes`).

A message whose first field is a ``std_msgs/Header`` holds its stamp right after the 4 bytes
of CDR encapsulation (``int32 sec``, ``uint32 nanosec``); a message whose first field is a
sequence of such messages (``tf2_msgs/TFMessage``, ``visualization_msgs/MarkerArray``) holds
the first element's stamp after the sequence's ``uint32`` length. Field layouts come as
``{name: type}`` in field order, as rclpy's ``get_fields_and_field_types()`` gives them
(``std_msgs/Header``, ``sequence<geometry_msgs/TransformStamped>``).
"""

from __future__ import annotations

import re
import struct
from collections import deque
from collections.abc import Callable, Mapping

__all__ = ["HEADER_TYPE", "LOG_TIMES", "LogTimes", "stamp_ns", "stamp_offset"]

HEADER_TYPE = "std_msgs/Header"
#: How a recording logs its messages (``hmocap record --log-time``): with the input of their
#: header stamp (:class:`LogTimes`), or when they arrived.
LOG_TIMES = ("input", "receive")
_SEQUENCE = re.compile(r"^sequence<([^,>]+)(?:,\s*\d+)?>$")


def _first_type(fields: Mapping[str, str]) -> str | None:
    return next(iter(fields.values()), None)


def stamp_offset(typename: str, fields_of: Callable[[str], Mapping[str, str]]) -> int | None:
    """Where the stamp of ``typename`` lies in its CDR data (after the encapsulation): 0 when its
    first field is a Header, 4 when it is a sequence of messages whose first field is a Header
    (the first element's), None for a message without one. ``fields_of`` gives a type's fields
    (``pkg/msg/Name`` or ``pkg/Name``) in order."""
    first = _first_type(fields_of(typename))
    if first is None:
        return None
    if first == HEADER_TYPE:
        return 0
    element = _SEQUENCE.match(first)
    if element and "/" in element.group(1) and _first_type(fields_of(element.group(1))) == HEADER_TYPE:
        return 4
    return None


def stamp_ns(cdr: bytes, offset: int | None) -> int | None:
    """The stamp (ns) at ``offset`` (:func:`stamp_offset`) of serialized ``cdr``; None when the type
    has none, a sequence is empty, the stamp is zero (never set) or the bytes are too short."""
    if offset is None or len(cdr) < 4 + offset + 8:
        return None
    endian = "<" if cdr[1] & 1 else ">"
    if offset == 4 and struct.unpack_from(endian + "I", cdr, 4)[0] == 0:
        return None
    sec, nanosec = struct.unpack_from(endian + "iI", cdr, 4 + offset)
    stamp = sec * 1_000_000_000 + nanosec
    return stamp if stamp > 0 else None


class LogTimes:
    """The log time of each message of a recording, so that viewers show every output with the
    input it was computed from: a message whose header stamp is that of a message recorded before
    is logged at that message's log time (a skeleton with the images of its frame set, however
    late the tracker published it); the first message of a stamp, and a message without one, at
    its receive time. One clock for the whole bag, the recorder's: inputs replayed from an old
    bag, latched messages and nodes' periodic diagnostics (stamped with the time they are sent)
    keep their order. A stamp is remembered for ``keep_ns`` of receive time. With
    ``by_stamp=False`` every message keeps its receive time."""

    def __init__(self, by_stamp: bool = True, keep_ns: int = 300_000_000_000):
        self.by_stamp = by_stamp
        self.keep_ns = keep_ns
        self._first: dict[int, int] = {}
        self._arrivals: deque[tuple[int, int]] = deque()  # (receive time, stamp), oldest first

    def log_time(self, stamp: int | None, receive_ns: int) -> int:
        """The log time of a message with header ``stamp`` (None: none) received at ``receive_ns``."""
        if not self.by_stamp or stamp is None:
            return receive_ns
        while self._arrivals and receive_ns - self._arrivals[0][0] > self.keep_ns:
            self._first.pop(self._arrivals.popleft()[1], None)
        first = self._first.get(stamp)
        if first is None:
            self._first[stamp] = first = receive_ns
            self._arrivals.append((receive_ns, stamp))
        return first
