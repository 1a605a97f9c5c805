"""Frame sets waiting for a node slower than its cameras: newest first, with what was skipped.

A live node's :class:`~hmocap_ros.frame_intake.FrameSetIntake` puts the complete frame sets of
its stamp synchroniser into a :class:`FrameSetQueue`, and its worker takes one whenever it is
idle: the newest (``latest_only``, a live room: the latency stays bounded and the sets in
between are counted as skipped) or the oldest (a bag replayed slowly, where every frame must be
processed). :class:`FramePeriod` measures the stream's frame period from its stamps, so that
frames DDS dropped count as skipped too. No rclpy here.
"""

from __future__ import annotations

import bisect
import dataclasses

import numpy as np

__all__ = ["FramePeriod", "FrameSetQueue", "PickedSet"]


class FramePeriod:
    """A stream's frame period from its stamps: the median difference of consecutive distinct
    stamps among the :attr:`WINDOW` newest seen (a few frames dropped here and there do not
    move a median). A stamp older than every one kept (a stream that started again) starts
    the window anew. A median under :attr:`MIN_PERIOD_NS` is no camera's frame period
    (stamps that count frames rather than time, as synthetic sequences number them): the
    period is then unknown, and every time counts as one period."""

    #: stamps kept
    WINDOW = 64
    #: shortest frame period taken for one (1 ms: 1,000 frames per second)
    MIN_PERIOD_NS = 1_000_000

    def __init__(self) -> None:
        self._stamps: list[int] = []  # sorted, distinct

    def add(self, stamp_ns: int) -> None:
        stamp_ns = int(stamp_ns)
        stamps = self._stamps
        if stamps and stamp_ns < stamps[0]:
            stamps.clear()
        i = bisect.bisect_left(stamps, stamp_ns)
        if i < len(stamps) and stamps[i] == stamp_ns:
            return
        stamps.insert(i, stamp_ns)
        if len(stamps) > self.WINDOW:
            del stamps[0]

    @property
    def period_ns(self) -> float | None:
        """The median stamp difference (ns), or None before two distinct stamps or when it
        is under :attr:`MIN_PERIOD_NS`."""
        if len(self._stamps) < 2:
            return None
        period = float(np.median(np.diff(self._stamps)))
        return period if period >= self.MIN_PERIOD_NS else None

    def periods(self, dt_ns: int) -> int:
        """Whole frame periods in ``dt_ns`` (rounded, at least 1; 1 while the period is
        unknown or for a time that does not go forward)."""
        period = self.period_ns
        if period is None or period <= 0 or dt_ns <= 0:
            return 1
        return max(1, int(round(dt_ns / period)))


@dataclasses.dataclass(frozen=True, eq=False)
class PickedSet:
    """A frame set taken from a :class:`FrameSetQueue`.

    stamp_ns, items: the set (the synchroniser's); waited_ns: from its completion to its
    take; passed_over: stamps of the complete sets skipped for it (newest-only); missing:
    frame sets that never came complete between the set taken before and this one (stamp
    gaps counted in frame periods).
    """

    stamp_ns: int
    items: dict
    waited_ns: int
    passed_over: tuple = ()
    missing: int = 0

    @property
    def skipped(self) -> int:
        """Frame sets not tracked between the set taken before and this one."""
        return len(self.passed_over) + self.missing


class FrameSetQueue:
    """Complete frame sets waiting for a tracker that may be slower than the cameras.

    ``latest_only``: :meth:`take` gives the newest set and passes over the older ones (a live
    tracker stays at the present, at the cost of the frames in between); otherwise every set,
    oldest first (a bag replayed slowly, where every frame must be tracked).

    Frame sets that never came complete are counted too (``PickedSet.missing``): frames a
    DDS queue of bounded depth dropped while the tracker worked, sets the synchroniser gave
    up on. They show as gaps in the stamps, counted in frame periods (:class:`FramePeriod`,
    fed with every stamp put). A gap before a set that arrived more than two frame periods
    (at least :attr:`IDLE_GAP_NS`) after the tracker last became idle is a pause of the
    stream, not frames lost while it worked, and is not counted.
    """

    #: Shortest time after the tracker became idle from which a set's arrival means the
    #: stream paused (when the frame period is unknown or shorter than half of it).
    IDLE_GAP_NS = 100_000_000

    def __init__(self, latest_only: bool = True):
        self.latest_only = bool(latest_only)
        self.period = FramePeriod()
        self._pending: dict[int, tuple[dict, int]] = {}  # stamp -> (items, arrival)
        self._last: int | None = None                     # stamp of the last set taken

    def __len__(self) -> int:
        return len(self._pending)

    def put(self, stamp_ns: int, items: dict, arrival_ns: int) -> None:
        """A complete (or given up on) frame set, arrived at ``arrival_ns`` (monotonic)."""
        self._pending[int(stamp_ns)] = (items, int(arrival_ns))
        self.period.add(stamp_ns)

    def take(self, idle_since_ns: int, now_ns: int) -> PickedSet | None:
        """The next set to track (None when none waits). ``idle_since_ns``: when the tracker
        last finished a set (monotonic, as the arrival times); ``now_ns``: the time now."""
        if not self._pending:
            return None
        stamps = sorted(self._pending)
        if self._last is not None and stamps[-1] <= self._last:  # the stream started again
            self._last = None
        chosen = stamps[-1] if self.latest_only else stamps[0]
        passed = tuple(t for t in stamps if t < chosen)
        first_arrival = self._pending[stamps[0]][1]
        items, arrival = self._pending.pop(chosen)
        for t in passed:
            del self._pending[t]
        missing = 0
        sequence = list(passed) + [chosen]
        if self._last is not None:
            period = self.period.period_ns or 0.0
            if first_arrival - idle_since_ns <= max(2.0 * period, self.IDLE_GAP_NS):
                sequence.insert(0, self._last)  # else the stream paused while the tracker idled
        for a, b in zip(sequence, sequence[1:]):
            missing += self.period.periods(b - a) - 1
        self._last = chosen
        return PickedSet(chosen, items, max(0, now_ns - arrival), passed, missing)
