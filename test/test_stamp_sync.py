"""Tests of hmocap_ros.stamp_sync: exact and approximate multi-camera stamp synchronisation."""

import numpy as np
import pytest

from hmocap_ros.stamp_sync import StampSynchronizer, SyncedSet, synchronize

KEYS = ("cam_1", "cam_2", "cam_3")
PERIOD = 33_333_333  # 30 fps
MS = 1_000_000


def frames(stamps_by_key):
    """(key, stamp, item) tuples, item = (key, stamp) so outputs can be checked."""
    return [(k, s, (k, s)) for k, stamps in stamps_by_key.items() for s in stamps]


def time_ordered(stream):
    return sorted(stream, key=lambda f: (f[1], KEYS.index(f[0])))


def feed(sync, stream):
    out = []
    for key, stamp, item in stream:
        out.extend(sync.add(key, stamp, item))
    return out


def check_invariants(sets, slop, keys=KEYS):
    """Stamps strictly increase, no frame is emitted twice, spreads are within the slop."""
    stamps = [s.stamp_ns for s in sets]
    assert all(a < b for a, b in zip(stamps, stamps[1:])), stamps
    seen = set()
    for s in sets:
        assert set(s.items) <= set(keys)
        member_stamps = [item[1] for item in s.items.values()]
        assert s.stamp_ns == min(member_stamps)
        assert max(member_stamps) - min(member_stamps) <= slop
        for key, item in s.items.items():
            assert item[0] == key and item not in seen
            seen.add(item)


def test_exact_in_order():
    stamps = [i * PERIOD for i in range(5)]
    sync = StampSynchronizer(KEYS)
    out = feed(sync, time_ordered(frames({k: stamps for k in KEYS})))
    assert [s.stamp_ns for s in out] == stamps
    assert all(isinstance(s, SyncedSet) and s.items == {k: (k, s.stamp_ns) for k in KEYS} for s in out)
    assert list(out[0].items) == list(KEYS)  # output order follows keys
    stats = sync.stats
    assert stats.received == 15 and stats.complete_sets == 5 and stats.dropped_total == 0 and stats.pending == 0


def test_exact_out_of_order_arrival():
    # Cameras interleave arbitrarily: cam_3 lags three frames behind, cam_2 arrives first.
    stamps = [i * PERIOD for i in range(6)]
    stream = (frames({"cam_2": stamps}) + frames({"cam_1": stamps[:3]}) + frames({"cam_3": stamps})
              + frames({"cam_1": stamps[3:]}))
    sync = StampSynchronizer(KEYS)
    out = feed(sync, stream)
    assert [s.stamp_ns for s in out] == stamps
    assert all(len(s.items) == 3 for s in out)
    assert sync.stats.dropped_total == 0


def test_exact_missing_frame_is_dropped():
    stamps = [i * PERIOD for i in range(5)]
    stream = time_ordered(frames({"cam_1": stamps, "cam_2": stamps[:2] + stamps[3:], "cam_3": stamps}))
    sync = StampSynchronizer(KEYS)
    out = feed(sync, stream)
    assert [s.stamp_ns for s in out] == [stamps[i] for i in (0, 1, 3, 4)]
    stats = sync.stats
    assert stats.dropped == {"cam_1": 1, "cam_2": 0, "cam_3": 1}
    assert stats.drop_reasons == {"unmatched": 2}
    assert stats.pending == 0


def test_exact_missing_frame_partial_set():
    stamps = [i * PERIOD for i in range(5)]
    stream = time_ordered(frames({"cam_1": stamps, "cam_2": stamps[:2] + stamps[3:], "cam_3": stamps}))
    sync = StampSynchronizer(KEYS, allow_partial=True, min_keys=2)
    out = feed(sync, stream)
    assert [s.stamp_ns for s in out] == stamps
    assert set(out[2].items) == {"cam_1", "cam_3"}
    assert all(len(s.items) == 3 for i, s in enumerate(out) if i != 2)
    assert sync.stats.partial_sets == 1 and sync.stats.complete_sets == 4 and sync.stats.dropped_total == 0
    # With min_keys=3 the lone pair is not enough.
    sync = StampSynchronizer(KEYS, allow_partial=True, min_keys=3)
    assert len(feed(sync, stream)) == 4 and sync.stats.dropped_total == 2


def test_duplicates_and_late_frames():
    sync = StampSynchronizer(("a", "b"))
    assert sync.add("a", 10, "a10") == []
    assert sync.add("a", 10, "a10 again") == []  # pending duplicate
    out = sync.add("b", 10, "b10")
    assert out == [SyncedSet(10, {"a": "a10", "b": "b10"})]
    assert sync.add("b", 10, "b10 again") == []  # duplicate of an emitted frame
    assert sync.add("a", 5, "a5") == []  # older than the last set: late
    assert sync.add("a", 20, "a20") == [] and sync.add("b", 20, "b20") == [SyncedSet(20, {"a": "a20", "b": "b20"})]
    assert sync.stats.drop_reasons == {"duplicate": 2, "late": 1}
    assert sync.stats.dropped == {"a": 2, "b": 1}
    with pytest.raises(KeyError):
        sync.add("c", 30, None)


def test_approximate_jitter_within_slop():
    rng = np.random.default_rng(0)
    n = 40
    nominal = np.arange(n) * PERIOD
    stamps = {k: (nominal + rng.integers(-2 * MS, 2 * MS, n)).tolist() for k in KEYS}
    stream = time_ordered(frames(stamps))
    sync = StampSynchronizer(KEYS, slop_ns=5 * MS)
    out = feed(sync, stream)
    assert len(out) == n - 1  # the last one waits for a later frame that never comes
    out += sync.flush()
    assert len(out) == n
    for i, s in enumerate(out):
        assert s.items == {k: (k, stamps[k][i]) for k in KEYS}
    check_invariants(out, 5 * MS)
    # Knowing the frame period, sets come out as soon as they are complete.
    sync = StampSynchronizer(KEYS, slop_ns=5 * MS, min_period_ns=PERIOD // 2)
    emitted_after = []
    for index, (key, stamp, item) in enumerate(stream):
        emitted_after += [index] * len(sync.add(key, stamp, item))
    assert len(emitted_after) == n
    # Each set is out by the time its last frame arrived (stream is time ordered: index 3i + 2).
    assert all(index <= 3 * i + 2 for i, index in enumerate(emitted_after))


def test_approximate_jitter_outside_slop_drops_the_set():
    stamps = {k: [i * PERIOD for i in range(5)] for k in KEYS}
    stamps["cam_2"][2] += 12 * MS  # beyond the 5 ms slop
    sync = StampSynchronizer(KEYS, slop_ns=5 * MS)
    out = feed(sync, time_ordered(frames(stamps))) + sync.flush()
    assert [s.stamp_ns for s in out] == [i * PERIOD for i in (0, 1, 3, 4)]
    assert sync.stats.dropped == {"cam_1": 1, "cam_2": 1, "cam_3": 1}
    # Within a 15 ms slop the same frames form a set, stamped by its earliest frame.
    sync = StampSynchronizer(KEYS, slop_ns=15 * MS)
    out = feed(sync, time_ordered(frames(stamps))) + sync.flush()
    assert len(out) == 5 and out[2].stamp_ns == 2 * PERIOD and out[2].items["cam_2"] == ("cam_2", 2 * PERIOD + 12 * MS)


def test_approximate_prefers_tightest_set():
    sync = StampSynchronizer(("a", "b"), slop_ns=10)
    assert sync.add("a", 0, "a0") == [] and sync.add("a", 9, "a9") == []
    assert sync.add("b", 10, "b10") == []  # {a9, b10} wins over {a0, b10}; an a10 could still beat it
    assert sync.add("a", 20, "a20") == [SyncedSet(9, {"a": "a9", "b": "b10"})]  # now nothing can
    assert sync.add("b", 30, "b30") == []  # spread 10 <= slop, but b21..b29 or a21..a29 could be tighter
    assert sync.flush() == [SyncedSet(20, {"a": "a20", "b": "b30"})]
    assert sync.stats.drop_reasons == {"unmatched": 1}  # a0


def test_approximate_waits_for_a_tighter_set():
    # {a0, b6} would do with slop 10, but a5 arrives later and pairs more tightly with b6.
    sync = StampSynchronizer(("a", "b"), slop_ns=10)
    out = feed(sync, [("a", 0, "a0"), ("b", 6, "b6"), ("a", 5, "a5"), ("b", 40, "b40"), ("a", 41, "a41")])
    assert out == [SyncedSet(5, {"a": "a5", "b": "b6"})]
    assert sync.flush() == [SyncedSet(40, {"a": "a41", "b": "b40"})]


def test_dead_camera_partial_sets_with_max_delay():
    stamps = [i * PERIOD for i in range(30)]
    stream = time_ordered(frames({"cam_1": stamps, "cam_2": stamps, "cam_3": stamps[:10]}))  # cam_3 dies
    sync = StampSynchronizer(KEYS, allow_partial=True, min_keys=2, max_delay_ns=3 * PERIOD)
    emitted = {}
    for index, (key, stamp, item) in enumerate(stream):
        for s in sync.add(key, stamp, item):
            emitted[s.stamp_ns] = (index, s)
    assert sorted(emitted) == stamps[:-4]  # frames within max_delay of the newest wait
    for stamp, (index, s) in emitted.items():
        assert len(s.items) == (3 if stamp < 10 * PERIOD else 2)
        # A partial set is out at most max_delay (plus one frame) after its stamp.
        assert stream[index][1] - stamp <= 4 * PERIOD
    final = sync.flush()
    assert [s.stamp_ns for s in final] == stamps[-4:]
    assert sync.stats.partial_sets == 20 and sync.stats.complete_sets == 10 and sync.stats.pending == 0


def test_bounded_memory_without_partial():
    sync = StampSynchronizer(KEYS, queue_size=5)
    for i in range(200):  # cam_3 never publishes
        for key in KEYS[:2]:
            assert sync.add(key, i * PERIOD, None) == []
        assert sync.pending <= 5 * 2 + 5 * 3 + 2
    stats = sync.stats
    assert stats.drop_reasons["overflow"] > 300 and stats.received == 400
    assert sync.flush() == []
    assert sync.stats.dropped_total == 400


def test_bounded_memory_dead_camera_partial_without_delay():
    sync = StampSynchronizer(KEYS, queue_size=4, allow_partial=True, min_keys=2)
    out = []
    for i in range(100):
        for key in KEYS[:2]:
            out += sync.add(key, i * PERIOD, (key, i * PERIOD))
        assert sync.pending <= 4 * 2 + 4 * 3 + 2
    out += sync.flush()
    assert [s.stamp_ns for s in out] == [i * PERIOD for i in range(100)]
    assert all(set(s.items) == {"cam_1", "cam_2"} for s in out)


@pytest.mark.parametrize("seed", range(5))
def test_random_streams_invariants_and_determinism(seed):
    """Jitter, drops, duplicates and shuffled arrival: the invariants always hold."""
    rng = np.random.default_rng(seed)
    n, slop = 60, 4 * MS
    nominal = np.arange(n) * PERIOD
    stream = []
    kept = {}
    for k in KEYS:
        stamps = nominal + rng.integers(-MS, MS, n)
        keep = rng.random(n) > 0.1
        kept[k] = keep
        stream += [(k, int(s), (k, int(s))) for s in stamps[keep]]
    stream = time_ordered(stream)
    # Duplicates and local reordering across cameras (arrival delays up to one frame).
    stream += [stream[i] for i in rng.choice(len(stream), 10, replace=False)]
    arrival = np.array([f[1] for f in stream]) + rng.integers(0, PERIOD, len(stream))
    stream = [stream[i] for i in np.argsort(arrival, kind="stable")]
    for partial in (False, True):
        options = dict(slop_ns=slop, allow_partial=partial, min_keys=2, queue_size=8)
        first = list(synchronize(stream, KEYS, **options))
        second = list(synchronize(stream, KEYS, **options))
        assert first == second
        check_invariants(first, slop)
        complete = [s for s in first if len(s.items) == 3]
        expected = int(np.sum(kept["cam_1"] & kept["cam_2"] & kept["cam_3"]))
        assert len(complete) == expected
        if partial:
            pairs = int(np.sum((kept["cam_1"].astype(int) + kept["cam_2"] + kept["cam_3"]) == 2))
            assert len(first) == expected + pairs


def test_poll_lets_out_the_end_of_a_stream_with_a_dead_camera():
    # Real-time arrival (arrival = stamp + 2 ms); cam_3 dies after 10 frames. The stamp bound
    # alone keeps the last max_delay of the stream; poll lets it out max_wait after arrival.
    stamps = [i * PERIOD for i in range(30)]
    stream = time_ordered(frames({"cam_1": stamps, "cam_2": stamps, "cam_3": stamps[:10]}))
    wait = 100 * MS
    sync = StampSynchronizer(KEYS, allow_partial=True, min_keys=2, max_delay_ns=3 * PERIOD, max_wait_ns=wait)
    out = []
    for key, stamp, item in stream:
        out += sync.add(key, stamp, item, now_ns=stamp + 2 * MS)
        out += sync.poll(stamp + 2 * MS)
    assert len(out) < 30
    last_arrival = stamps[-1] + 2 * MS
    out += sync.poll(last_arrival + wait - 1)
    assert out[-1].stamp_ns == stamps[-2]  # the last set's views have not waited max_wait yet
    out += sync.poll(last_arrival + wait)
    check_invariants(out, 0)
    assert [s.stamp_ns for s in out] == stamps
    assert [len(s.items) for s in out] == [3] * 10 + [2] * 20
    assert sync.pending == 0 and sync.stats.dropped_total == 0
    assert sync.flush() == []


def test_poll_bounds_the_delay_of_a_live_stream_with_a_dead_camera():
    # No stamp bound: every set after cam_3 died goes out by poll, within max_wait plus one
    # polling period of the arrival of its last view.
    wait, tick = 80 * MS, 20 * MS
    stamps = [i * PERIOD for i in range(40)]
    arrivals = sorted((s + 3 * MS, k, s) for k in KEYS for s in stamps if k != "cam_3" or s < 10 * PERIOD)
    sync = StampSynchronizer(KEYS, allow_partial=True, min_keys=2, max_wait_ns=wait)
    out_at = {}
    now, i = 0, 0
    while i < len(arrivals) or sync.pending:
        now += tick
        while i < len(arrivals) and arrivals[i][0] <= now:
            arrival, key, stamp = arrivals[i]
            out_at.update((s.stamp_ns, (now, s)) for s in sync.add(key, stamp, (key, stamp), now_ns=arrival))
            i += 1
        out_at.update((s.stamp_ns, (now, s)) for s in sync.poll(now))
    assert sorted(out_at) == stamps
    check_invariants([s for _, s in sorted(out_at.values(), key=lambda v: v[1].stamp_ns)], 0)
    for stamp, (when, s) in out_at.items():
        assert len(s.items) == (3 if stamp < 10 * PERIOD else 2)
        if stamp >= 10 * PERIOD:
            assert when - (stamp + 3 * MS) <= wait + tick


def test_poll_waits_from_the_newest_view_and_drops_views_after_it():
    sync = StampSynchronizer(KEYS, allow_partial=True, min_keys=1, max_wait_ns=100 * MS)
    assert sync.add("cam_1", 0, "a0", now_ns=0) == []
    assert sync.add("cam_2", 0, "b0", now_ns=80 * MS) == []
    assert sync.poll(150 * MS) == []                                # cam_2 arrived 70 ms ago
    assert sync.add("cam_3", 0, "c0", now_ns=160 * MS) == [SyncedSet(0, {"cam_1": "a0", "cam_2": "b0", "cam_3": "c0"})]
    assert sync.add("cam_1", PERIOD, "a1", now_ns=200 * MS) == []
    assert sync.poll(299 * MS) == []
    assert sync.poll(300 * MS) == [SyncedSet(PERIOD, {"cam_1": "a1"})]
    assert sync.add("cam_2", PERIOD, "b1", now_ns=310 * MS) == []   # its set has gone out
    assert sync.stats.drop_reasons == {"late": 1}
    assert sync.stats.complete_sets == 1 and sync.stats.partial_sets == 1 and sync.pending == 0


def test_poll_below_min_keys_drops_as_timeout():
    sync = StampSynchronizer(KEYS, allow_partial=True, min_keys=2, max_wait_ns=10 * MS)
    sync.add("cam_1", 0, "a", now_ns=0)
    assert sync.poll(10 * MS) == []
    assert sync.pending == 0 and sync.stats.drop_reasons == {"timeout": 1}


def test_poll_needs_max_wait_and_arrival_times():
    with pytest.raises(ValueError):
        StampSynchronizer(KEYS).poll(0)
    with pytest.raises(ValueError):
        StampSynchronizer(KEYS, max_wait_ns=-1)
    sync = StampSynchronizer(KEYS, allow_partial=True, min_keys=1, max_wait_ns=MS)
    sync.add("cam_1", 0, "a")  # no arrival time: poll never gives up on its set
    assert sync.poll(10**12) == [] and sync.pending == 1
    assert sync.flush() == [SyncedSet(0, {"cam_1": "a"})]


@pytest.mark.parametrize("seed", range(3))
def test_random_streams_with_poll_invariants(seed):
    """Jittered stamps, lost frames, random arrival delays and polls: every frame is emitted or
    counted as dropped, sets keep the invariants, and views that arrive in time are never split."""
    rng = np.random.default_rng(seed)
    n, slop, wait = 50, 4 * MS, 60 * MS
    arrivals = []
    for k in KEYS:
        stamps = np.arange(n) * PERIOD + rng.integers(-MS, MS, n)
        keep = rng.random(n) > 0.15
        delay = rng.integers(0, 30 * MS, n)  # always within max_wait of the set's first view
        arrivals += [(int(s + d), k, int(s)) for s, d, ok in zip(stamps, delay, keep) if ok]
    arrivals.sort()
    sync = StampSynchronizer(KEYS, slop_ns=slop, allow_partial=True, min_keys=1, max_wait_ns=wait)
    out = []
    for arrival, key, stamp in arrivals:
        out += sync.poll(arrival)
        out += sync.add(key, stamp, (key, stamp), now_ns=arrival)
    out += sync.poll(arrivals[-1][0] + wait)
    assert sync.pending == 0
    check_invariants(out, slop)
    stats = sync.stats
    assert sum(len(s.items) for s in out) + stats.dropped_total == len(arrivals)
    assert stats.dropped_total == 0  # every view arrived within max_wait of its set's others
    by_index = {}
    for _, key, stamp in arrivals:
        by_index.setdefault(round(stamp / PERIOD), set()).add(key)
    assert sorted(len(s.items) for s in out) == sorted(len(v) for v in by_index.values())


def test_synchronize_skips_other_keys_and_flushes():
    stream = [("cam_1", 0, "a"), ("imu", 0, "x"), ("cam_2", 0, "b"), ("cam_1", 10, "c")]
    out = list(synchronize(stream, ("cam_1", "cam_2"), allow_partial=True, min_keys=1))
    assert out == [SyncedSet(0, {"cam_1": "a", "cam_2": "b"}), SyncedSet(10, {"cam_1": "c"})]


def test_invalid_arguments():
    with pytest.raises(ValueError):
        StampSynchronizer([])
    with pytest.raises(ValueError):
        StampSynchronizer(["a", "a"])
    with pytest.raises(ValueError):
        StampSynchronizer(["a"], slop_ns=-1)
    with pytest.raises(ValueError):
        StampSynchronizer(["a", "b"], min_keys=3)
    with pytest.raises(TypeError):
        StampSynchronizer(["a"]).add("a", 1.5, None)  # stamps are integer nanoseconds


def test_stamps_going_back_start_the_stream_over():
    # A bag replayed in a loop: after the last frame set the stamps start again 1 s earlier.
    sync = StampSynchronizer(["a", "b"], max_jump_back_ns=500_000_000)
    first = [s for t in range(5) for key in "ab" for s in sync.add(key, 1_000_000_000 + t * 40_000_000, t)]
    assert [s.stamp_ns for s in first] == [1_000_000_000 + t * 40_000_000 for t in range(5)]
    assert sync.add("a", 1_200_000_000, 5) == []  # waits for b
    again = [s for t in range(3) for key in "ab" for s in sync.add(key, t * 40_000_000, t)]
    assert [s.stamp_ns for s in again] == [0, 40_000_000, 80_000_000]
    assert sync.resets == 1 and sync.last_jump_ns == 1_200_000_000
    stats = sync.stats
    assert stats.resets == 1 and stats.drop_reasons == {"time_jump": 1}  # the frame that waited
    # a frame a little older than the last set is late, not a new stream
    assert sync.add("a", 10_000_000, 9) == [] and sync.resets == 1
    assert sync.stats.drop_reasons["late"] == 1
    # without max_jump_back_ns, everything after the jump is late
    plain = StampSynchronizer(["a", "b"])
    for t in range(5):
        for key in "ab":
            plain.add(key, 1_000_000_000 + t * 40_000_000, t)
    assert [s for t in range(3) for key in "ab" for s in plain.add(key, t * 40_000_000, t)] == []
    with pytest.raises(ValueError):
        StampSynchronizer(["a"], max_jump_back_ns=0)


def test_a_camera_ahead_after_a_stall_does_not_expire_the_others_frames():
    # After a stall the queued frames come round robin; cam_4 missed frames 12-19, so its queue
    # runs ahead of the others'. Every frame set still goes out, those of the gap without cam_4.
    keys = ["cam_1", "cam_2", "cam_3", "cam_4"]
    sync = StampSynchronizer(keys, slop_ns=5 * MS, queue_size=100, allow_partial=True, min_keys=2,
                             max_delay_ns=150 * MS, max_wait_ns=150 * MS, max_jump_back_ns=500 * MS)
    queues = {k: [f for f in range(9, 28) if not (k == "cam_4" and 12 <= f < 20)] for k in keys}
    out = [s for f in range(9) for k in keys for s in sync.add(k, f * 40 * MS, f, now_ns=f)]
    now = 100
    while any(queues.values()):
        for k in keys:
            if queues[k]:
                f = queues[k].pop(0)
                now += 1
                out += sync.add(k, f * 40 * MS, f, now_ns=now)
    assert [s.stamp_ns // (40 * MS) for s in out] == list(range(28))
    assert [len(s.items) for s in out] == [4] * 12 + [3] * 8 + [4] * 8
    assert sync.stats.dropped_total == 0 and sync.resets == 0
