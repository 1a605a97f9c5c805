"""One intake for every live node: frame sets taken by a worker thread as they complete.

A live node (``body_tracker``, ``extremity_detection``) offers each camera frame to a
:class:`FrameSetIntake` from its subscription callbacks. The intake groups the frames into sets
(:class:`~hmocap_ros.stamp_sync.StampSynchronizer`), queues the sets (:class:`~hmocap_ros.
frame_sets.FrameSetQueue`: the newest, or every one in order) and hands them to the node's
``work`` function in a worker thread of its own, woken by the set's arrival: no timer polls,
and the node's callbacks keep receiving while the worker works. A set with a view missing goes
out ``max_wait_ns`` after its newest view arrived (the worker wakes for that only while frames
wait in the synchroniser).

A *companion* is one message per frame set that comes from another stage, later than the
set's own frames: the extremity node's keypoints for the tracker's masks. While a companion is
expected (:attr:`FrameSetIntake.companion_expected`, the node says so), a complete set is held
by its stamp for ``hold_ns`` until its companion comes, however late; the companion's arrival
queues the set with it, and the held sets older than it were never answered by the other stage
(they count as skipped). A companion that comes before its set waits for it the same way. While
none is expected, sets go to the worker with ``None`` as companion. So a companion is never
"late": only the cameras' own stamps going back start the stream over.

Stamps going back by more than :data:`~hmocap_ros.stamp_sync.TIME_JUMP_BACK_NS` (a bag replayed
again, a camera restarted) start the stream over: the waiting sets are dropped and
``on_start_over(jump_ns)`` runs in the worker thread before its next set, so that what the
worker owns (a tracker, a detector's crops) is reset in the thread that uses it. No rclpy here.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Hashable, Sequence
from typing import Any

from hmocap_ros.frame_sets import FrameSetQueue, PickedSet
from hmocap_ros.stamp_sync import TIME_JUMP_BACK_NS, StampSynchronizer

__all__ = ["HOLD_NS", "FrameSetIntake", "StageHandoff"]

log = logging.getLogger(__name__)

#: How long (ns of stamps) a complete set waits for its companion, and a companion for its set:
#: longer than the keypoint stage's latency on a loaded machine.
HOLD_NS = 3_000_000_000


class FrameSetIntake:
    """Frame sets of ``keys`` handed to ``work(picked)`` in a worker thread (module docstring).

    keys: the cameras (a set's keys); slop_ns, min_keys, max_wait_ns, queue_size: the
    synchroniser's (a set has at least ``min_keys`` views; one with a view missing goes out
    ``max_wait_ns`` after its newest view arrived); latest_only: the newest set when the worker
    falls behind (the others counted as skipped) or every set in order; companion: the key under
    which a set's companion is handed to ``work`` (None: sets have none); on_start_over: called
    in the worker with how far the stamps went back; on_error: called in the worker with an
    exception ``work`` raised (the worker goes on; default: logged); clock: monotonic ns.
    """

    def __init__(self, keys: Sequence[Hashable], work: Callable[[PickedSet], None], *,
                 slop_ns: int, min_keys: int, max_wait_ns: int, queue_size: int = 10,
                 latest_only: bool = True, companion: Hashable | None = None,
                 on_start_over: Callable[[int], None] | None = None,
                 on_error: Callable[[Exception], None] | None = None, hold_ns: int = HOLD_NS,
                 clock: Callable[[], int] = time.monotonic_ns, name: str = "frame_sets") -> None:
        if max_wait_ns <= 0:
            raise ValueError(f"max_wait_ns must be > 0, got {max_wait_ns}")
        self.sync = StampSynchronizer(list(keys), slop_ns=slop_ns, queue_size=max(1, queue_size),
                                      allow_partial=True, min_keys=min_keys, max_delay_ns=max_wait_ns,
                                      max_wait_ns=max_wait_ns, max_jump_back_ns=TIME_JUMP_BACK_NS)
        self.queue = FrameSetQueue(latest_only)
        self.work = work
        self.companion = companion
        self.on_start_over = on_start_over
        self.on_error = on_error or (lambda err: log.error("frame set work failed", exc_info=err))
        self.hold_ns = int(hold_ns)
        self.clock = clock
        #: whether sets wait for their companion (the node sets it: the other stage is there)
        self.companion_expected = False
        self.skipped_unanswered = 0  # held sets the companion's stage never answered
        self._held: dict[int, dict] = {}        # stamp -> items waiting for the companion
        self._companions: dict[int, Any] = {}   # stamp -> companion waiting for its set
        self._start_over: int | None = None     # a jump (ns) the worker has yet to act on
        self._idle_since_ns = clock()
        self._busy = False
        self._closed = False
        self._cond = threading.Condition()
        self._poll_s = max_wait_ns / 4e9
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ producers (any thread)

    def add(self, key: Hashable, stamp_ns: int, item: Any) -> None:
        """One camera frame (``item``) of ``key`` with its header stamp."""
        with self._cond:
            resets = self.sync.resets
            sets = self.sync.add(key, int(stamp_ns), item, now_ns=self.clock())
            if self.sync.resets != resets:
                self._forget(self.sync.last_jump_ns)
            self._take_in(sets)
            self._cond.notify()

    def add_companion(self, stamp_ns: int, item: Any) -> None:
        """The companion of the set of ``stamp_ns`` (module docstring)."""
        stamp_ns = int(stamp_ns)
        with self._cond:
            held = self._match(self._held, stamp_ns)
            if held is None:
                self._companions[stamp_ns] = item
                self._prune(self._companions, stamp_ns)
                return
            items = self._held.pop(held)
            self._answer(held, items, item)
            self._cond.notify()

    def close(self, timeout: float = 5.0) -> None:
        """Stop the worker once its current set is done."""
        with self._cond:
            self._closed = True
            self._cond.notify()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout)

    @property
    def idle(self) -> bool:
        """Whether the worker is waiting (nothing queued, nothing in hand)."""
        with self._cond:
            return not self._busy and not len(self.queue)

    # ------------------------------------------------------------------ internals (lock held)

    def _take_in(self, sets) -> None:
        now = self.clock()
        for synced in sets:
            items = dict(synced.items)
            if self.companion is None:
                self.queue.put(synced.stamp_ns, items, now)
                continue
            waiting = self._match(self._companions, synced.stamp_ns)
            if waiting is not None:
                self._answer(synced.stamp_ns, items, self._companions.pop(waiting))
            elif self.companion_expected:
                self._held[synced.stamp_ns] = items
                self.queue.period.add(synced.stamp_ns)  # its stamp still measures the period
                self._prune(self._held, synced.stamp_ns)
            else:
                self._held.clear()  # their companions' stage is gone: none will come
                items[self.companion] = None
                self.queue.put(synced.stamp_ns, items, now)

    def _answer(self, stamp_ns: int, items: dict, companion: Any) -> None:
        """Queue a held set with its companion; the held sets before it were never answered."""
        items[self.companion] = companion
        older = [t for t in self._held if t < stamp_ns]
        for t in older:
            del self._held[t]
        self.skipped_unanswered += len(older)
        self.queue.put(stamp_ns, items, self.clock())

    def _match(self, waiting: dict, stamp_ns: int) -> int | None:
        """The stamp in ``waiting`` within the synchroniser's slop of ``stamp_ns`` (nearest)."""
        near = [t for t in waiting if abs(t - stamp_ns) <= self.sync.slop_ns]
        return min(near, key=lambda t: abs(t - stamp_ns)) if near else None

    def _prune(self, waiting: dict, newest_ns: int) -> None:
        for t in [t for t in waiting if t < newest_ns - self.hold_ns]:
            del waiting[t]

    def _forget(self, jump_ns: int) -> None:
        self.queue = FrameSetQueue(self.queue.latest_only)
        self._held.clear()
        self._companions.clear()
        self._start_over = jump_ns

    # ------------------------------------------------------------------ the worker

    def _next(self) -> tuple[PickedSet | None, int | None]:
        """Wait for a set (or a start-over, or close); (set, jump) with the lock released."""
        with self._cond:
            while True:
                if self._closed:
                    return None, None
                if self._start_over is not None:
                    jump, self._start_over = self._start_over, None
                    return None, jump
                if len(self.queue):
                    picked = self.queue.take(self._idle_since_ns, self.clock())
                    if picked is not None:
                        self._busy = True
                        return picked, None
                # a set with a view missing goes out max_wait after its newest view: wake for
                # it only while frames wait in the synchroniser
                self._cond.wait(self._poll_s if self.sync.pending else None)
                if self.sync.pending:
                    self._take_in(self.sync.poll(self.clock()))

    def _run(self) -> None:
        while True:
            picked, jump = self._next()
            if picked is None and jump is None:
                return
            try:
                if jump is not None:
                    if self.on_start_over is not None:
                        self.on_start_over(jump)
                else:
                    assert picked is not None
                    self.work(picked)
            except Exception as err:  # a bug in one set must not stop the intake
                self.on_error(err)
            finally:
                with self._cond:
                    self._busy = False
                    self._idle_since_ns = self.clock()


class StageHandoff:
    """The second stage of a two-stage pipeline in a thread of its own: ``put(item)`` hands an
    item to ``work(item)`` and returns once the worker has taken it. The first stage (an
    intake's worker) works on the next frame set while this one works on the last, each on a
    core of its own where their libraries release the GIL (OpenCV, LiteRT, numba); with
    :meth:`wait_until_due` it starts the next set only when this stage is about to be free, so
    the set it takes is the newest and waits no longer than it must. Nothing is done that the
    second stage does not take, and items keep their order. on_error: called in the worker with
    an exception ``work`` raised (default: logged)."""

    def __init__(self, work: Callable[[Any], None], *,
                 on_error: Callable[[Exception], None] | None = None, name: str = "stage") -> None:
        self.work = work
        self.on_error = on_error or (lambda err: log.error("stage work failed", exc_info=err))
        self._item: Any = None
        self._waiting = False
        self._busy = False
        self._started = 0.0
        #: exponential moving average of the seconds ``work`` takes per item
        self.work_s = 0.0
        self._closed = False
        self._cond = threading.Condition()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def put(self, item: Any) -> bool:
        """Hand ``item`` to the worker and wait until it took it; False when closed."""
        with self._cond:
            while self._waiting and not self._closed:
                self._cond.wait()
            if self._closed:
                return False
            self._item, self._waiting = item, True
            self._cond.notify_all()
            while self._waiting and not self._closed:
                self._cond.wait()
            return not self._closed

    def wait_until_due(self, lead_s: float) -> None:
        """Wait until the worker's item is expected to be done within ``lead_s`` seconds (by
        :attr:`work_s`), or the worker is idle: the first stage then starts on the newest set
        ``lead_s`` (its own time per item) before the worker is free."""
        with self._cond:
            while self._busy and not self._closed:
                left = self.work_s - (time.monotonic() - self._started) - lead_s
                if left <= 0:
                    return
                self._cond.wait(left)

    def drain(self) -> None:
        """Wait until the worker has done every item handed to it."""
        with self._cond:
            while (self._waiting or self._busy) and not self._closed:
                self._cond.wait()

    def close(self, timeout: float = 5.0) -> None:
        """Stop the worker once its current item is done (an item waiting is dropped)."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout)

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._waiting and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
                item, self._item, self._waiting, self._busy = self._item, None, False, True
                self._started = time.monotonic()
                self._cond.notify_all()
            try:
                self.work(item)
            except Exception as err:  # a bug in one item must not stop the stage
                self.on_error(err)
            finally:
                with self._cond:
                    took = time.monotonic() - self._started
                    self.work_s = took if self.work_s == 0.0 else 0.8 * self.work_s + 0.2 * took
                    self._busy = False
                    self._cond.notify_all()
