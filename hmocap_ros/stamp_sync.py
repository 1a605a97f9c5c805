"""Synchronise frames of N cameras by their header stamps (stands in for message_filters).

:class:`StampSynchronizer` groups frames that arrive one by one (any order, any key) into sets
with one frame per key, the way ``message_filters`` ``TimeSynchronizer`` (exact stamps) and
``ApproximateTimeSynchronizer`` (stamps within a slop) do; the live node feeds it from its
subscription callbacks and :func:`synchronize` runs it over a recorded, time-ordered stream.
Pure Python, no rclpy; stamps are integer nanoseconds.

Algorithm (``slop_ns = 0`` is the exact policy as a special case)
---------------------------------------------------------------
Each key keeps a sorted queue of pending frames and a watermark, its newest stamp so far;
frames of one key are assumed to arrive mostly in stamp order (cameras publish in order; the
keys may interleave arbitrarily). A *complete set* takes one frame per key; its *spread* is
``max - min`` of its stamps and its stamp is the earliest stamp (``min``).

1. Nothing can be decided until every key has a pending frame. Then the *pivot*
   ``P = max_k head_k`` is the earliest possible end (latest stamp) of any complete set, so a
   frame older than ``P - slop`` can never be in one: it expires (see 4).
2. Candidates: for every pending stamp ``E`` in ``[P, P + slop]``, the set ending at ``E`` takes
   from each key its latest frame at or before ``E`` (the choice that minimises the spread of a
   set ending there). The candidate with the smallest spread ``<= slop`` wins (ties: earliest
   ``E``), as in ApproximateTime, which prefers the tightest set.
3. The winner ``C`` (end ``E``, spread ``d``) is emitted once no frame yet to come can change the
   choice: for every key the next frame's stamp is known to exceed ``P + slop`` or to be at least
   ``E + d`` (a set tighter than ``C`` that shares a frame with it lies within ``E + d``). The
   next frame of a key is later than its watermark, and by ``min_period_ns`` at least if given;
   with identical stamps this holds at once, with jittered ones after one more frame per key
   (one frame of latency, like ApproximateTime) unless ``min_period_ns`` says otherwise. Frames
   older than the chosen one of each key expire. If there is no candidate and the window is
   final, the pivot frame expires.
4. Expired frames are never part of a complete set. With ``allow_partial`` they are grouped
   greedily (oldest first, one per key, within ``slop`` of the group's first frame) and each group
   with at least ``min_keys`` frames is emitted as an incomplete set, in stamp order with the
   complete ones; otherwise they are dropped and counted.

Sets are emitted in strictly increasing stamp order and no frame is emitted twice; a frame older
than the last emitted set, or not newer than the last emitted frame of its key, is dropped as
late; a repeated (key, stamp) is ignored as a duplicate. Memory is bounded: a key holding more than
``queue_size`` frames expires its oldest, at most ``queue_size`` frames per key wait in the
expired pool (older groups are resolved first), and with ``max_delay_ns`` a frame that far behind
the newest stamp seen expires too. :meth:`StampSynchronizer.flush` ends the stream.

Giving up on a missing view
---------------------------
A camera that stopped publishing leaves its sets incomplete; two bounds let them out as partial
sets (with ``allow_partial``):

* by stamp, ``max_delay_ns``: a frame expires once ``min_keys`` keys have a frame that much
  newer (one camera whose queued frames arrive ahead of the others' after a stall does not
  expire theirs). This needs no clock (offline streams), but the sets of the last
  ``max_delay_ns`` of a stream wait for :meth:`~StampSynchronizer.flush`.
* by arrival time, ``max_wait_ns``: ``add`` takes the arrival time of each frame (``now_ns``,
  any monotonic clock in nanoseconds) and :meth:`~StampSynchronizer.poll`, called periodically
  with the same clock, expires the frames of every group whose newest view arrived
  ``max_wait_ns`` or longer ago (a group: queued frames of different keys within ``slop`` of each
  other). Expired groups are emitted as in 4 once no queued frame can still join them; a key
  without queued frames is then not waited for. A missing view therefore costs at most
  ``max_wait_ns`` plus the polling period after the last view of its set arrived, also at the end
  of a stream and on a live stream with a dead camera. A view arriving after its set has gone
  out is dropped as ``late``.

Time going back
---------------
A stream whose stamps jump back (a bag replayed again or in a loop, a camera driver restarted
with a reset clock) would leave every later frame ``late`` for good. With ``max_jump_back_ns``
a frame whose stamp lies more than that before the newest stamp seen starts the stream over:
the pending frames are dropped (reason ``time_jump``), the history is forgotten as by
:meth:`~StampSynchronizer.reset` (the counters are kept), the frame is taken as the first of
the new stream, and :attr:`~StampSynchronizer.resets` and ``last_jump_ns`` tell the caller, who
resets what else follows the stream (a tracker's motion model) and logs it.

Typical use (live node: one ``add`` per image callback, ``poll`` on a timer; offline:
:func:`synchronize`)::

    sync = StampSynchronizer(rig.names, slop_ns=5_000_000, allow_partial=True, min_keys=3,
                             max_wait_ns=200_000_000)
    for stamp_ns, images in sync.add("cam_2", stamp_ns, image, now_ns=time.monotonic_ns()):
        tracker.step(stamp_ns, images)
    for stamp_ns, images in sync.poll(time.monotonic_ns()):  # on a timer
        tracker.step(stamp_ns, images)
"""

from __future__ import annotations

import bisect
import dataclasses
import operator
from collections import Counter
from dataclasses import dataclass
from typing import Any, Hashable, Iterable, Iterator, NamedTuple, Sequence

__all__ = ["SyncedSet", "SyncStats", "StampSynchronizer", "TIME_JUMP_BACK_NS", "synchronize"]

_INF = float("inf")
#: The nodes' ``max_jump_back_ns``: stamps half a second before the newest seen mean the
#: stream's time went back (a frame that late would be dropped anyway; a bag looped goes back
#: by its whole length).
TIME_JUMP_BACK_NS = 500_000_000


class SyncedSet(NamedTuple):
    """A synchronised set: its stamp (the earliest member's, ns) and ``{key: item}``.

    A complete set has every key; a partial one (``allow_partial``) only those present.
    """

    stamp_ns: int
    items: dict


@dataclass(frozen=True)
class SyncStats:
    """Counters for diagnostics (a snapshot, see :attr:`StampSynchronizer.stats`).

    ``dropped`` counts frames never emitted, per key; ``drop_reasons`` per reason:
    ``late`` (older than what was already emitted), ``duplicate`` (key and stamp seen before),
    ``unmatched`` (no complete set and no partial set was allowed/big enough),
    ``overflow`` (pushed out of a full queue), ``timeout`` (older than ``max_delay_ns``, or its
    group waited ``max_wait_ns``), ``time_jump`` (pending when the stamps went back, see
    ``max_jump_back_ns``). ``resets``: times the stamps went back and the stream started over.
    """

    received: int
    complete_sets: int
    partial_sets: int
    pending: int
    dropped: dict
    drop_reasons: dict
    resets: int = 0

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())


@dataclass(frozen=True)
class _Frame:
    stamp: int
    key: Hashable
    item: Any
    reason: str = "unmatched"  # why it expired, for the counters if it is dropped
    arrival: float = _INF  # arrival clock (ns) when added; inf: unknown, never waited out


class StampSynchronizer:
    """Group frames of several keys (cameras) into sets by stamp; see the module docstring.

    Args:
        keys: the keys of a complete set (e.g. camera names), in output order.
        slop_ns: largest allowed spread (max - min stamp) of a set; 0 means identical stamps.
        queue_size: most pending frames per key before the oldest expires.
        allow_partial: emit expired frames as incomplete sets of at least ``min_keys`` keys.
        min_keys: smallest partial set (default: all keys but one, at least 1).
        max_delay_ns: expire frames this much older than the newest stamp seen (None: never).
        max_wait_ns: with :meth:`poll`, expire the frames of a group whose newest view arrived
            this long ago on the arrival clock (None: never).
        min_period_ns: a lower bound on the interval between two frames of one key (0: unknown);
            lets jittered sets out without waiting for the next frame.
        max_jump_back_ns: a frame this much older than the newest stamp seen starts the stream
            over (module docstring, "Time going back"); None: such a frame is dropped as late.
    """

    def __init__(
        self,
        keys: Sequence[Hashable],
        slop_ns: int = 0,
        queue_size: int = 10,
        allow_partial: bool = False,
        min_keys: int | None = None,
        max_delay_ns: int | None = None,
        min_period_ns: int = 0,
        max_wait_ns: int | None = None,
        max_jump_back_ns: int | None = None,
    ) -> None:
        self.keys = tuple(keys)
        if not self.keys:
            raise ValueError("StampSynchronizer needs at least one key")
        if len(set(self.keys)) != len(self.keys):
            raise ValueError(f"duplicate keys: {list(self.keys)}")
        self.slop_ns = operator.index(slop_ns)
        if self.slop_ns < 0:
            raise ValueError(f"slop_ns must be >= 0, got {slop_ns}")
        self.queue_size = operator.index(queue_size)
        if self.queue_size < 1:
            raise ValueError(f"queue_size must be >= 1, got {queue_size}")
        self.allow_partial = bool(allow_partial)
        self.min_keys = max(1, len(self.keys) - 1) if min_keys is None else operator.index(min_keys)
        if not 1 <= self.min_keys <= len(self.keys):
            raise ValueError(f"min_keys must be in [1, {len(self.keys)}], got {min_keys}")
        self.max_delay_ns = None if max_delay_ns is None else operator.index(max_delay_ns)
        if self.max_delay_ns is not None and self.max_delay_ns < 0:
            raise ValueError(f"max_delay_ns must be >= 0, got {max_delay_ns}")
        self.max_wait_ns = None if max_wait_ns is None else operator.index(max_wait_ns)
        if self.max_wait_ns is not None and self.max_wait_ns < 0:
            raise ValueError(f"max_wait_ns must be >= 0, got {max_wait_ns}")
        self.min_period_ns = operator.index(min_period_ns)
        if self.min_period_ns < 0:
            raise ValueError(f"min_period_ns must be >= 0, got {min_period_ns}")
        self.max_jump_back_ns = None if max_jump_back_ns is None else operator.index(max_jump_back_ns)
        if self.max_jump_back_ns is not None and self.max_jump_back_ns <= 0:
            raise ValueError(f"max_jump_back_ns must be > 0, got {max_jump_back_ns}")
        self.reset()

    # ---- public -------------------------------------------------------------------------

    def reset(self) -> None:
        """Forget all pending frames, history and counters."""
        self._forget_stream()
        self._received = 0
        self._complete = 0
        self._partial = 0
        self._dropped: Counter = Counter()
        self._reasons: Counter = Counter()
        self.resets = 0
        self.last_jump_ns = 0  # how far the stamps went back at the last restart

    def _forget_stream(self) -> None:
        """Forget the pending frames and the history of the stream (not the counters)."""
        self._stamps: dict = {k: [] for k in self.keys}  # sorted stamps per key
        self._frames: dict = {k: [] for k in self.keys}  # frames, same order
        self._watermark: dict = {k: -_INF for k in self.keys}
        self._last_resolved: dict = {k: -_INF for k in self.keys}  # newest emitted or dropped
        self._last_set_stamp: float = -_INF
        self._newest: float = -_INF
        self._expired: list[_Frame] = []  # sorted by stamp
        self._seen_expired: set = set()  # (key, stamp) of expired frames, for duplicates

    @property
    def pending(self) -> int:
        """Frames held (queued or expired but not yet resolved)."""
        return sum(len(q) for q in self._stamps.values()) + len(self._expired)

    @property
    def stats(self) -> SyncStats:
        """A snapshot of the counters."""
        return SyncStats(
            received=self._received,
            complete_sets=self._complete,
            partial_sets=self._partial,
            pending=self.pending,
            dropped={k: self._dropped.get(k, 0) for k in self.keys},
            drop_reasons=dict(self._reasons),
            resets=self.resets,
        )

    def add(self, key: Hashable, stamp_ns: int, item: Any, now_ns: int | None = None) -> list[SyncedSet]:
        """Offer one frame; returns the sets completed by it (often none, sometimes several).

        ``now_ns`` is the frame's arrival time on the clock :meth:`poll` is given (None: the
        frame is never given up on by :meth:`poll`).
        """
        if key not in self._stamps:
            raise KeyError(f"unknown key {key!r}; expected one of {list(self.keys)}")
        stamp = operator.index(stamp_ns)
        arrival = _INF if now_ns is None else operator.index(now_ns)
        if self.max_jump_back_ns is not None and stamp < self._stream_stamp() - self.max_jump_back_ns:
            self._start_over(stamp)
        self._received += 1
        stamps = self._stamps[key]
        i = bisect.bisect_left(stamps, stamp)
        if (i < len(stamps) and stamps[i] == stamp) or stamp == self._last_resolved[key] \
                or (key, stamp) in self._seen_expired:
            self._drop(key, "duplicate")
            return []
        if stamp < self._last_resolved[key] or stamp <= self._last_set_stamp:
            self._drop(key, "late")
            return []
        stamps.insert(i, stamp)
        self._frames[key].insert(i, _Frame(stamp, key, item, arrival=arrival))
        self._watermark[key] = max(self._watermark[key], stamp)
        self._newest = max(self._newest, stamp)
        out: list[SyncedSet] = []
        if len(stamps) > self.queue_size:
            self._expire_head(key, "overflow")
        self._process(out, final=False)
        return out

    def poll(self, now_ns: int) -> list[SyncedSet]:
        """Give up on the views missing from sets that waited ``max_wait_ns``; returns the sets out.

        ``now_ns`` is on the clock of ``add``'s ``now_ns``. A queued frame expires when it and
        every queued frame of another key within ``slop_ns`` of it arrived at or before
        ``now_ns - max_wait_ns``; the expired groups then go out as partial sets (or are dropped
        as ``timeout`` below ``min_keys``). Call it periodically, e.g. every ``max_wait_ns / 4``.
        """
        if self.max_wait_ns is None:
            raise ValueError("poll needs max_wait_ns")
        deadline = operator.index(now_ns) - self.max_wait_ns
        for key in self.keys:
            while self._stamps[key] and self._waited_out(self._frames[key][0], deadline):
                self._expire_head(key, "timeout")
        out: list[SyncedSet] = []
        self._process(out, final=False, deadline=deadline)
        return out

    def flush(self) -> list[SyncedSet]:
        """End of stream: emit every set still possible, then resolve all remaining frames."""
        out: list[SyncedSet] = []
        self._process(out, final=True)
        for key in self.keys:
            while self._stamps[key]:
                self._expire_head(key, "unmatched")
        self._emit_expired(out, before=_INF, force=True)
        return out

    # ---- internals ----------------------------------------------------------------------

    def _stream_stamp(self) -> float:
        """How far the stream has come: the newest stamp that ``min_keys`` keys have reached
        (the ``min_keys``-th largest watermark). One camera ahead of the others (its queue
        delivered first after a stall) does not make the others' frames old."""
        return sorted(self._watermark.values(), reverse=True)[self.min_keys - 1]

    def _start_over(self, stamp: int) -> None:
        """The stamps went back (module docstring): drop what is pending, forget the stream."""
        for frame in [f for frames in self._frames.values() for f in frames] + self._expired:
            self._drop(frame.key, "time_jump")
        self.last_jump_ns = int(self._stream_stamp() - stamp)
        self.resets += 1
        self._forget_stream()

    def _drop(self, key, reason: str) -> None:
        self._dropped[key] += 1
        self._reasons[reason] += 1

    def _expire_head(self, key, reason: str) -> None:
        """Move the oldest pending frame of ``key`` to the expired pool."""
        self._stamps[key].pop(0)
        frame = self._frames[key].pop(0)
        bisect.insort(self._expired, dataclasses.replace(frame, reason=reason),
                      key=lambda f: (f.stamp, self.keys.index(f.key)))
        self._seen_expired.add((key, frame.stamp))

    def _waited_out(self, frame: _Frame, deadline: float) -> bool:
        """Whether ``frame`` and the queued frames of other keys within the slop of it all
        arrived at or before ``deadline``."""
        if frame.arrival > deadline:
            return False
        slop = self.slop_ns
        for key in self.keys:
            if key == frame.key:
                continue
            stamps = self._stamps[key]
            lo = bisect.bisect_left(stamps, frame.stamp - slop)
            hi = bisect.bisect_right(stamps, frame.stamp + slop)
            if any(f.arrival > deadline for f in self._frames[key][lo:hi]):
                return False
        return True

    def _next_possible(self, key, final: bool) -> float:
        """Lower bound on the stamp of a frame of ``key`` that has not arrived yet."""
        if final:
            return _INF
        return self._watermark[key] + max(self.min_period_ns, 1)

    def _process(self, out: list, final: bool, deadline: float | None = None) -> None:
        """Emit every set that can be decided now (``final``: no more frames will come;
        ``deadline``: from :meth:`poll`, expired groups whose frames all arrived by then are not
        waited on for keys without queued frames)."""
        slop = self.slop_ns
        while True:
            if self.max_delay_ns is not None:
                limit = self._stream_stamp() - self.max_delay_ns
                for key in self.keys:
                    while self._stamps[key] and self._stamps[key][0] < limit:
                        self._expire_head(key, "timeout")
            if not all(self._stamps[k] for k in self.keys):
                break
            pivot = max(self._stamps[k][0] for k in self.keys)
            for key in self.keys:  # step 1: frames no complete set can use
                while self._stamps[key] and self._stamps[key][0] < pivot - slop:
                    self._expire_head(key, "unmatched")
            if not all(self._stamps[k] for k in self.keys):
                continue
            best = None  # (spread, end, {key: index of its frame})
            ends = sorted({s for k in self.keys for s in self._stamps[k] if s <= pivot + slop})
            for end in ends[ends.index(pivot):]:  # step 2
                chosen = {k: bisect.bisect_right(self._stamps[k], end) - 1 for k in self.keys}
                spread = end - min(self._stamps[k][i] for k, i in chosen.items())
                if spread <= slop and (best is None or spread < best[0]):
                    best = (spread, end, chosen)
            if best is None:
                if all(self._next_possible(k, final) > pivot + slop for k in self.keys):
                    for key in self.keys:
                        if self._stamps[key][0] == pivot:
                            self._expire_head(key, "unmatched")
                    continue
                break
            spread, end, chosen = best
            settled = all(
                (nxt := self._next_possible(k, final)) > pivot + slop or nxt >= end + spread for k in self.keys
            )
            if not settled:  # step 3: a frame yet to come might give a tighter set
                break
            for key, index in chosen.items():
                for _ in range(index):
                    self._expire_head(key, "unmatched")
            members = {k: self._frames[k][0] for k in self.keys}
            stamp = min(f.stamp for f in members.values())
            self._emit_expired(out, before=stamp, force=True)
            for key in self.keys:
                self._stamps[key].pop(0)
                self._frames[key].pop(0)
            self._emit(out, stamp, members, complete=True)
        self._emit_expired(out, before=self._closed_before(final, deadline), force=False, deadline=deadline)
        while len(self._expired) > self.queue_size * len(self.keys):  # bounded memory
            self._emit_expired(out, before=self._expired[0].stamp + self.slop_ns + 1, force=True)

    def _closed_before(self, final: bool, deadline: float | None = None) -> float:
        """No frame that could still expire has a stamp below this (expired groups there are closed).

        With a ``deadline`` (:meth:`poll`), keys without queued frames are not waited for: the
        groups that are emitted must then have arrived by the deadline (see :meth:`_emit_expired`).
        """
        def earliest(key) -> float:
            if self._stamps[key]:
                return self._stamps[key][0]
            return _INF if deadline is not None else self._next_possible(key, final)

        bound = min(earliest(k) for k in self.keys)
        if self.max_delay_ns is not None:
            bound = max(bound, self._stream_stamp() - self.max_delay_ns)
        return bound

    def _emit_expired(self, out: list, before: float, force: bool, deadline: float | None = None) -> None:
        """Group expired frames (step 4) and emit each group as a partial set, or drop it.

        Resolves the groups whose whole window ``[s0, s0 + slop]`` lies below ``before``, or with
        ``force`` every group that starts below ``before`` (from its frames below ``before``).
        With a ``deadline``, only groups whose frames all arrived by then (and the groups before).
        """
        while self._expired:
            s0 = self._expired[0].stamp
            if s0 >= before if force else s0 + self.slop_ns >= before:
                break
            group: dict = {}
            rest: list[_Frame] = []
            for frame in self._expired:
                if frame.stamp <= s0 + self.slop_ns and frame.key not in group and frame.stamp < before:
                    group[frame.key] = frame
                else:
                    rest.append(frame)
            if deadline is not None and any(f.arrival > deadline for f in group.values()):
                break
            self._expired = rest
            for frame in group.values():
                self._seen_expired.discard((frame.key, frame.stamp))
            if self.allow_partial and len(group) >= self.min_keys and s0 > self._last_set_stamp:
                members = {k: group[k] for k in self.keys if k in group}
                self._emit(out, s0, members, complete=len(members) == len(self.keys))
            else:
                for frame in group.values():
                    self._last_resolved[frame.key] = max(self._last_resolved[frame.key], frame.stamp)
                    self._drop(frame.key, frame.reason)

    def _emit(self, out: list, stamp: int, members: dict, complete: bool) -> None:
        self._last_set_stamp = stamp
        for key, frame in members.items():
            self._last_resolved[key] = max(self._last_resolved[key], frame.stamp)
        if complete:
            self._complete += 1
        else:
            self._partial += 1
        out.append(SyncedSet(stamp, {k: f.item for k, f in members.items()}))


def synchronize(
    stream: Iterable[tuple[Hashable, int, Any]],
    keys: Sequence[Hashable],
    slop_ns: int = 0,
    **options,
) -> Iterator[SyncedSet]:
    """Synchronise a time-ordered iterable of ``(key, stamp_ns, item)`` (e.g. a bag's messages).

    Runs one :class:`StampSynchronizer` (``options`` are its keyword arguments) and yields the
    sets as they complete, then those left at the end of the stream. Frames of keys not in
    ``keys`` are skipped.
    """
    sync = StampSynchronizer(keys, slop_ns=slop_ns, **options)
    wanted = set(sync.keys)
    for key, stamp_ns, item in stream:
        if key in wanted:
            yield from sync.add(key, stamp_ns, item)
    yield from sync.flush()
