"""The live nodes' intake (hmocap_ros.frame_intake): frame sets handed to a worker thread as they
complete, newest first, with late companions (keypoints) paired by stamp."""

import threading
import time

import pytest

from hmocap_ros.frame_intake import FrameSetIntake, StageHandoff

MS = 1_000_000
PERIOD = 40 * MS
T0 = 1_000_000_000_000
CAMS = ("cam_1", "cam_2")


class Recorder:
    """``work`` for an intake: notes each set (and the worker thread), optionally blocking."""

    def __init__(self):
        self.sets = []
        self.threads = set()
        self.gate = threading.Event()
        self.gate.set()
        self.arrived = threading.Condition()

    def __call__(self, picked):
        self.threads.add(threading.get_ident())
        self.gate.wait(10)
        with self.arrived:
            self.sets.append(picked)
            self.arrived.notify_all()

    def wait_for(self, n, timeout=10.0):
        end = time.monotonic() + timeout
        with self.arrived:
            while len(self.sets) < n and time.monotonic() < end:
                self.arrived.wait(0.05)
        return len(self.sets) >= n


def intake(work, **kwargs):
    defaults = dict(slop_ns=5 * MS, min_keys=1, max_wait_ns=100 * MS)
    return FrameSetIntake(CAMS, work, **{**defaults, **kwargs})


def add_set(intake_, k, cams=CAMS):
    for cam in cams:
        intake_.add(cam, T0 + k * PERIOD, (cam, k))


def test_a_complete_set_is_worked_on_at_once_in_a_thread_of_its_own():
    rec = Recorder()
    it = intake(rec)
    try:
        start = time.monotonic()
        add_set(it, 0)
        assert rec.wait_for(1)
        assert time.monotonic() - start < 5.0
        assert rec.sets[0].stamp_ns == T0 and rec.sets[0].items == {"cam_1": ("cam_1", 0), "cam_2": ("cam_2", 0)}
        assert rec.threads and threading.get_ident() not in rec.threads
    finally:
        it.close()


def test_a_busy_worker_takes_the_newest_set_and_counts_the_ones_it_skipped():
    rec = Recorder()
    it = intake(rec)
    try:
        rec.gate.clear()
        add_set(it, 0)
        time.sleep(0.2)  # the worker holds set 0
        for k in range(1, 6):
            add_set(it, k)
        rec.gate.set()
        assert rec.wait_for(2)
        time.sleep(0.2)
        assert [p.stamp_ns for p in rec.sets] == [T0, T0 + 5 * PERIOD]
        assert rec.sets[1].skipped == 4
    finally:
        it.close()


def test_every_set_in_order_when_not_latest_only():
    rec = Recorder()
    it = intake(rec, latest_only=False)
    try:
        rec.gate.clear()
        for k in range(4):
            add_set(it, k)
        rec.gate.set()
        assert rec.wait_for(4)
        assert [p.stamp_ns for p in rec.sets] == [T0 + k * PERIOD for k in range(4)]
    finally:
        it.close()


def test_a_set_waits_for_its_companion_however_late_it_comes():
    rec = Recorder()
    it = intake(rec, companion="extremities")
    it.companion_expected = True
    try:
        for k in range(30):  # 1.2 s of sets before the first companion comes
            add_set(it, k)
        time.sleep(0.2)
        assert not rec.sets  # held, not tracked without their keypoints
        it.add_companion(T0 + 2 * PERIOD + 1 * MS, "kp2")  # within the slop of set 2
        assert rec.wait_for(1)
        assert rec.sets[0].stamp_ns == T0 + 2 * PERIOD
        assert rec.sets[0].items["extremities"] == "kp2"
        it.add_companion(T0 + 25 * PERIOD, "kp25")
        assert rec.wait_for(2)
        # sets 3..24 were never answered: skipped by the stage before, counted
        assert rec.sets[1].stamp_ns == T0 + 25 * PERIOD and rec.sets[1].skipped == 22
        assert it.skipped_unanswered == 2 + 22
    finally:
        it.close()


def test_a_companion_before_its_set_waits_for_it():
    rec = Recorder()
    it = intake(rec, companion="extremities")
    it.companion_expected = True
    try:
        it.add_companion(T0, "kp0")
        add_set(it, 0)
        assert rec.wait_for(1)
        assert rec.sets[0].items["extremities"] == "kp0"
    finally:
        it.close()


def test_without_an_expected_companion_sets_go_on_with_none_and_held_ones_are_let_go():
    rec = Recorder()
    it = intake(rec, companion="extremities")
    it.companion_expected = True
    try:
        add_set(it, 0)
        it.companion_expected = False  # the keypoint stage is gone
        add_set(it, 1)
        assert rec.wait_for(1)
        assert rec.sets[0].stamp_ns == T0 + PERIOD and rec.sets[0].items["extremities"] is None
        assert not it._held  # set 0 waits for nothing that will come
    finally:
        it.close()


def test_a_set_with_a_view_missing_goes_out_after_the_wait():
    rec = Recorder()
    it = intake(rec, max_wait_ns=100 * MS)
    try:
        start = time.monotonic()
        add_set(it, 0, cams=("cam_1",))
        assert rec.wait_for(1, timeout=5.0)
        waited = time.monotonic() - start
        assert 0.09 <= waited < 5.0
        assert set(rec.sets[0].items) == {"cam_1"}
    finally:
        it.close()


def test_stamps_going_back_start_over_in_the_worker_before_the_next_set():
    rec = Recorder()
    jumps = []
    it = intake(rec, on_start_over=lambda jump: jumps.append((jump, threading.get_ident())))
    try:
        for k in range(30):
            add_set(it, k)
        assert rec.wait_for(1)
        time.sleep(0.2)
        n = len(rec.sets)
        add_set(it, 0)  # 1.16 s back: a bag replayed again
        assert rec.wait_for(n + 1)
        assert len(jumps) == 1 and jumps[0][0] == 29 * PERIOD
        assert jumps[0][1] in rec.threads
        assert rec.sets[-1].stamp_ns == T0
    finally:
        it.close()


def test_an_error_in_the_work_is_reported_and_the_worker_goes_on():
    errors = []
    rec = Recorder()

    def work(picked):
        if picked.stamp_ns == T0:
            raise RuntimeError("bad set")
        rec(picked)

    it = intake(work, on_error=errors.append)
    try:
        add_set(it, 0)
        time.sleep(0.2)
        add_set(it, 1)
        assert rec.wait_for(1)
        assert [str(e) for e in errors] == ["bad set"]
        assert rec.sets[0].stamp_ns == T0 + PERIOD
    finally:
        it.close()


def test_close_stops_the_worker_and_bad_arguments_are_refused():
    it = intake(Recorder())
    it.close()
    assert not it._thread.is_alive()
    with pytest.raises(ValueError, match="max_wait_ns"):
        intake(Recorder(), max_wait_ns=0)


def test_a_stage_handoff_keeps_the_order_and_lets_the_first_stage_run_one_item_ahead():
    """The second stage works on the items in the order given; put returns once the worker
    took the item (so the first stage is at most one item ahead); an error in one item is
    reported and the stage goes on; drain waits for everything handed over."""
    done, errors = [], []
    release = threading.Event()

    def work(item):
        if item == 0:
            release.wait(5)
        if item == 3:
            raise RuntimeError("bad item")
        done.append(item)

    stage = StageHandoff(work, on_error=errors.append)
    try:
        assert stage.put(0)  # taken at once
        second = threading.Thread(target=stage.put, args=(1,))
        second.start()
        second.join(0.3)
        assert second.is_alive() and done == []  # blocked: the worker is on 0
        release.set()
        second.join(5)
        assert not second.is_alive()
        for item in (3, 4):
            stage.put(item)
        stage.drain()
        assert done == [0, 1, 4] and [str(e) for e in errors] == ["bad item"]
    finally:
        stage.close()
    assert not stage.put(5)  # closed


def test_the_first_stage_waits_until_the_second_is_about_to_be_free():
    """wait_until_due(lead) returns no sooner than the worker's item is expected to end
    ``lead`` seconds later (its time per item, a moving average), at once when it is idle."""
    stage = StageHandoff(lambda item: time.sleep(0.2))
    try:
        for item in range(3):
            stage.put(item)
        stage.drain()
        assert 0.19 <= stage.work_s < 2.0
        t0 = time.monotonic()
        stage.wait_until_due(0.05)  # idle
        assert time.monotonic() - t0 < 0.05
        stage.put(3)
        t0 = time.monotonic()
        stage.wait_until_due(0.05)
        assert time.monotonic() - t0 >= 0.1
    finally:
        stage.close()
