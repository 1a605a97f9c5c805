"""The interactive trainer (thesis sec. 3.4.1) and its simulated user, closed loop."""

from __future__ import annotations

import numpy as np
import pytest

from hmocap_ros.gestures.forest_file import load_forest
from hmocap_ros.gestures.params import OnlineParams
from hmocap_ros.gestures.trainer import Trainer, TrainerParams, blend_threshold, moving_average

NS = 1_000_000_000
SMALL = OnlineParams(n_trees=3, max_depth=6, n_tests=8, n_thresholds=2, alpha=20.0)


def _params(**kw) -> TrainerParams:
    base = dict(rounds=2, do_gesture_s=1.0, update_positive_s=2.0, release_s=0.5, do_negatives_s=1.5,
                testing_s=1.0, online=SMALL)
    base.update(kw)
    return TrainerParams(**base)


def _frame(rng: np.random.Generator, h: int = 48, w: int = 64, present: float = 0.7) -> np.ndarray:
    """A wall at 3 m with a 'hand' block at 2 m at the box centre (metres) in a fraction ``present``
    of the frames (at random): the wall behind the box shows now and then, as when a user moves."""
    d = np.full((h, w), 3.0, np.float32) + rng.normal(0, 0.003, (h, w)).astype(np.float32)
    if rng.random() < present:
        d[int(0.45 * h) - 4:int(0.45 * h) + 4, w // 2 - 4:w // 2 + 4] = 2.0
    return d


def _arrays(trainer: Trainer) -> list:
    f = trainer.online.to_forest()
    out = [np.asarray(f.class_names)]
    for t in f.trees:
        out += [t.feature, t.threshold, t.left, t.right, t.counts, t.depth]
        if t.pending is not None:
            out += [t.pending.node, t.pending.feature, t.pending.threshold, t.pending.counts]
    return out


def _same(a: list, b: list) -> bool:
    return len(a) == len(b) and all(x.shape == y.shape and np.array_equal(x, y) for x, y in zip(a, b))


def test_threshold_formula_hand_computed():
    # th+ frames 0.5, 0.8 ; th- frames 0.2, 0.1 ; sigma 0.9, rho 0.8
    pos = moving_average(moving_average(None, 0.5, 0.9), 0.8, 0.9)
    neg = moving_average(moving_average(None, 0.2, 0.9), 0.1, 0.9)
    assert pos == pytest.approx(0.9 * 0.8 + 0.1 * 0.5)  # 0.77
    assert neg == pytest.approx(0.9 * 0.1 + 0.1 * 0.2)  # 0.11
    assert blend_threshold(pos, neg, 0.8) == pytest.approx(0.8 * 0.77 + 0.2 * 0.11)  # 0.638
    assert blend_threshold(pos, None, 0.8) is None


def test_states_and_durations_follow_the_stamps():
    rng = np.random.default_rng(0)
    tr = Trainer(None, _params(), np.random.default_rng(1), focal_px=100.0)
    t0 = 5 * NS
    tr.start("wave", t0)
    seen = []
    for k in range(0, 115):  # 10 fps for 11.4 s
        s = tr.on_frame(_frame(rng), t0 + k * NS // 10)
        seen.append((k, s.state, s.round, round(s.seconds_left, 3), s.samples))
    states = [x[1] for x in seen]
    # one round: do_gesture 1 s, update_positive 2 s, release 0.5 s, do_negatives 1.5 s -> 5 s
    expect = (["do_gesture"] * 10 + ["update_positive"] * 20 + ["release"] * 5 + ["do_negatives"] * 15) * 2
    expect += ["testing"] * 10 + ["done"] * 5
    assert states == expect
    assert [x[2] for x in seen[:50]] == [1] * 50 and [x[2] for x in seen[50:100]] == [2] * 50
    assert seen[0][3] == pytest.approx(1.0) and seen[13][3] == pytest.approx(1.7)
    assert all(x[4] > 0 for x in seen if x[1] == "update_positive")
    assert all(x[4] == 0 for x in seen if x[1] in ("do_gesture", "release", "testing", "done"))
    assert tr.threshold is not None and tr.thresholds["wave"] == pytest.approx(tr.threshold)
    with pytest.raises(ValueError, match="already knows"):
        tr.start("wave", t0 + 20 * NS)


def test_cancel_mid_round_restores_the_forest():
    rng = np.random.default_rng(0)
    tr = Trainer(None, _params(), np.random.default_rng(2), focal_px=100.0)
    t0 = 0
    tr.start("wave", t0)
    before = None
    for k in range(0, 80):
        s = tr.on_frame(_frame(rng), t0 + k * NS // 10)
        if s.round == 2 and before is None:  # first frame of the second round (do_gesture: no learning)
            before = _arrays(tr)
    assert tr.state == "update_positive" and tr.round == 2
    assert not _same(before, _arrays(tr))  # the second round learnt something
    tr.cancel()
    assert tr.state == "idle" and _same(before, _arrays(tr))
    # cancel in the first round of a new gesture: its class goes away again
    known = _arrays(tr)
    tr.start("point", 10 * NS)
    for k in range(15):
        tr.on_frame(_frame(rng), 10 * NS + k * NS // 10)
    assert tr.online.class_names[-1] == "point"
    tr.cancel()
    assert _same(known, _arrays(tr))


def test_save_load_resume_continues(tmp_path):
    rng = np.random.default_rng(0)
    p = _params(rounds=1)
    tr = Trainer(None, p, np.random.default_rng(3), focal_px=100.0)
    tr.start("wave", 0)
    for k in range(70):
        tr.on_frame(_frame(rng), k * NS // 10)
    assert tr.state == "done"
    path = tr.save(tmp_path / "room.forest.npz")
    assert not [q for q in tmp_path.iterdir() if q.name.endswith(".tmp")]
    stored = load_forest(path)
    assert stored.kind == "online" and stored.class_names == ("background", "wave")
    assert stored.meta["gesture_thresholds"]["wave"] == pytest.approx(tr.thresholds["wave"])
    again = Trainer(path, p, np.random.default_rng(4))  # focal from the file
    assert again.focal_px == 100.0 and _same(_arrays(tr), _arrays(again))
    seen0 = again.online.seen.copy()
    again.start("wave", 100 * NS, extend=True)
    for k in range(40):
        again.on_frame(_frame(rng), 100 * NS + k * NS // 10)
    assert again.online.seen[1] > seen0[1] and again.online.seen[0] > seen0[0]
    with pytest.raises(ValueError, match="fx"):
        Trainer(path, p, np.random.default_rng(4), focal_px=200.0)


def _found(trainer: Trainer, name: str, frames: list, box, focal_px: float) -> list:
    """Score of ``name``'s best detection near the box in each of ``frames`` (a fresh detector on
    the trainer's forest as it stands; 0 = none)."""
    from hmocap_ros.gestures.detection import GestureDetector
    from hmocap_ros.gestures.params import DetectorParams

    det = GestureDetector(trainer.forest(), DetectorParams(min_score=0.0, min_volume=0.0), focal_px=focal_px)
    tol = 2.5 * box[2]
    out = []
    for depth, stamp in frames:
        near = [d.score for d in det.update(depth, stamp)
                if d.name == name and abs(d.u - box[0]) <= tol and abs(d.v - box[1]) <= tol]
        out.append(max(near, default=0.0))
    return out[2:]  # the smoothing (eq. 3.4) settles


def test_closed_loop_teaches_a_second_gesture_and_keeps_the_first(tmp_path):
    """tee is taught, then pause in the same forest; the same frames of tee held where it was
    taught are scored before and after (a spot the session never used would test how far one
    short round generalises, not what the second gesture does to the first)."""
    from hmocap_sim.gesture_teacher import GestureTeacher, run_session

    p = _params(rounds=1, do_gesture_s=0.4, update_positive_s=1.5, release_s=0.3, do_negatives_s=1.5,
                testing_s=0.3, online=OnlineParams(n_trees=5, max_depth=12, n_tests=16, n_thresholds=4, alpha=40.0))
    teacher = GestureTeacher(seed=1)
    tr = Trainer(None, p, np.random.default_rng(0), focal_px=teacher.focal_px)
    tr.start("tee", teacher.next_stamp)
    run_session(tr, teacher, 4.1)
    assert tr.state == "done" and "tee" in tr.thresholds
    box = tr.box(teacher.camera.width, teacher.camera.height)
    tee_frames = teacher.holding("tee", box, 8)
    before = _found(tr, "tee", tee_frames, box, teacher.focal_px)
    path = tr.save(tmp_path / "room.forest.npz")

    second = Trainer(path, p, np.random.default_rng(1))
    second.start("pause", teacher.next_stamp)
    assert second.rehearsed == ("tee",)
    statuses = run_session(second, teacher, p.session_s(1) + 0.1)
    assert second.state == "done" and set(second.thresholds) == {"tee", "pause"}
    assert any(s.samples > 0 for s in statuses if s.state == "do_negatives")
    pause = _found(second, "pause", teacher.holding("pause", box, 8), box, teacher.focal_px)
    after = _found(second, "tee", tee_frames, box, teacher.focal_px)
    th = second.thresholds
    assert sum(s >= th["pause"] for s in pause) >= 4, (pause, th)
    assert sum(s >= th["tee"] for s in before) >= 4, (before, th)
    assert sum(s >= th["tee"] for s in after) >= sum(s >= th["tee"] for s in before) - 1, (before, after, th)
    assert np.mean(after) >= np.mean(before) - 0.1, (before, after)


def test_recording_keeps_the_learnt_frames_and_their_annotation(tmp_path):
    from hmocap_ros.eval.gesture_eval import read_gesture_bag
    from hmocap_sim.gesture_teacher import write_recording_bag

    rng = np.random.default_rng(0)
    tr = Trainer(None, _params(rounds=1), np.random.default_rng(1), focal_px=100.0, record=True)
    tr.start("wave", 0)
    frames = [_frame(rng) for _ in range(70)]
    for k, d in enumerate(frames):
        tr.on_frame(d, k * NS // 10)
    # update_positive 20 frames (10..29) at the box centre, do_negatives 15 frames (35..49) as background
    rec = tr.recording
    assert [f.gesture for f in rec] == ["wave"] * 20 + [""] * 15
    assert [f.stamp_ns for f in rec] == [k * NS // 10 for k in list(range(10, 30)) + list(range(35, 50))]
    assert (rec[0].u, rec[0].v) == pytest.approx(tr.box(64, 48)[:2])
    assert rec[0].depth_mm.dtype == np.uint16
    assert np.array_equal(rec[3].depth_mm, np.rint(frames[13] * 1000).astype(np.uint16))

    from hmocap_ros.geometry.pinhole_camera import PinholeCamera

    camera = PinholeCamera.from_camera_info({"width": 64, "height": 48,
                                             "K": [[100.0, 0, 32], [0, 100.0, 24], [0, 0, 1]],
                                             "D": [0.0] * 5, "distortion_model": "plumb_bob", "frame_id": "depth"},
                                            name="depth")
    assert write_recording_bag(tmp_path / "session.mcap", rec, camera) == 35
    data = read_gesture_bag(tmp_path / "session.mcap")
    assert data.focal_px == 100.0 and data.depth.shape == (35, 48, 64)
    assert data.class_names[9] == "wave"  # after the simulator's eight gestures
    assert data.labels[0] == (9, pytest.approx(32.0), pytest.approx(0.45 * 48)) and data.labels[20] is None
    assert np.array_equal(data.depth[3], rec[3].depth_mm)


def test_rehearse_shows_each_known_gesture_in_turn():
    rng = np.random.default_rng(0)
    p = _params(rounds=1, rehearse_s=0.6)
    tr = Trainer(None, p, np.random.default_rng(1), focal_px=100.0)
    tr.start("wave", 0)
    for k in range(70):
        tr.on_frame(_frame(rng), k * NS // 10)
    tr.start("point", 100 * NS)
    assert tr.rehearsed == ("wave",) and p.round_s(1) == pytest.approx(5.6)
    seen = [tr.on_frame(_frame(rng), 100 * NS + k * NS // 10) for k in range(45)]
    rehearsing = [s for s in seen if s.state == "rehearse"]
    # do_gesture 1 s, update_positive 2 s, release 0.5 s, then 0.6 s of 'wave': its first third is not learnt
    assert [s.state for s in seen[34:42]] == ["release"] + ["rehearse"] * 6 + ["do_negatives"]
    assert {s.rehearsed for s in rehearsing} == {"wave"} and "Show 'wave'" in rehearsing[0].instruction
    assert [s.samples > 0 for s in rehearsing] == [False, False, True, True, True, True]
    assert rehearsing[0].progress == pytest.approx(3.5 / p.session_s(1))


class ScriptedDetector:
    """Stands in for a trainer's detector: each frame's density grid (and, when given, its votes
    and grid depths) comes from ``script(k)`` for the k-th frame instead of the forest."""

    def __init__(self, real, script):
        self.active_params = real.params.for_focal(real.focal_px)
        self.grid_offset = self.active_params.stride // 2
        self.script, self.k = script, 0
        self.density = self.class_map = self.grid_depth = None

    def update(self, depth, stamp_ns):
        self.density, self.class_map, self.grid_depth = self.script(self.k, depth)
        self.k += 1
        return []

    def set_forest(self, forest):
        pass


def _ema(values, sigma):
    out = None
    for v in values:
        out = v if out is None else sigma * v + (1 - sigma) * out
    return out


def test_threshold_follows_the_scripted_densities():
    """th+ and th- are the moving averages (sigma) of the density maxima in the box on the
    update_positive frames and over the frame on the do_negatives frames, th = rho th+ + (1 - rho)
    th- (sec. 3.4.1): densities scripted frame by frame, every value hand-followed."""
    rng = np.random.default_rng(0)
    values = np.random.default_rng(7).uniform(0.05, 0.95, 101)
    p = _params(rho=0.7, sigma=0.9, testing_s=0.0)
    tr = Trainer(None, p, np.random.default_rng(1), focal_px=100.0)
    tr.start("wave", 0)
    gh, gw = 48, 64  # stride 1 at fx 100

    def script(k, depth):
        return np.full((gh, gw, 1), values[k], np.float32), None, None

    tr.detector = ScriptedDetector(tr.detector, script)
    states = [tr.on_frame(_frame(rng), k * NS // 10).state for k in range(101)]
    pos = [v for v, s in zip(values, states) if s == "update_positive"]
    neg = [v for v, s in zip(values, states) if s == "do_negatives"]
    assert len(pos) == 40 and len(neg) == 30
    assert tr.th_pos == pytest.approx(_ema(pos, 0.9), abs=1e-6)
    assert tr.th_neg == pytest.approx(_ema(neg, 0.9), abs=1e-6)
    assert tr.thresholds["wave"] == pytest.approx(0.7 * _ema(pos, 0.9) + 0.3 * _ema(neg, 0.9), abs=1e-6)
    assert tr.online.meta["gesture_threshold_parts"]["wave"] == pytest.approx([_ema(pos, 0.9), _ema(neg, 0.9)])


def test_negatives_are_mined_where_the_forest_fires():
    """A false positive planted in the do_negatives frames (votes for the gesture on a block far
    from the box): the negatives are drawn around it (sec. 3.3.2), round(N_neg max p) of them."""
    rng = np.random.default_rng(0)
    p = _params(rounds=1, testing_s=0.0)
    tr = Trainer(None, p, np.random.default_rng(1), focal_px=100.0)
    tr.start("wave", 0)
    spot = (10, 38)  # column, row: far from the box at (32, 21.6)

    def script(k, depth):
        votes = np.zeros(depth.shape, np.int8)
        votes[spot[1] - 2:spot[1] + 3, spot[0] - 2:spot[0] + 3] = 1
        return np.zeros(depth.shape + (1,), np.float32), votes, depth.astype(np.float32)

    def planted(r):
        d = _frame(r)
        d[spot[1] - 3:spot[1] + 4, spot[0] - 3:spot[0] + 4] = 2.5
        return d

    tr.detector = ScriptedDetector(tr.detector, script)
    drawn = []
    real_update = tr.online.update

    def spy(frames, s_frame, s_x, s_y, s_label, r):
        if tr.state == "do_negatives":
            drawn.append((np.asarray(s_x), np.asarray(s_y)))
        return real_update(frames, s_frame, s_x, s_y, s_label, r)

    tr.online.update = spy
    for k in range(50):
        tr.on_frame(planted(rng), k * NS // 10)
    assert len(drawn) == 15
    half = tr.online.params.hard_half_size_px_m / 2.5
    box_half = tr.patches.box_half_size_px_m / 2.0  # the hand block at 2 m; at 3 m (the wall) smaller
    on_hand = []
    for xs, ys in drawn:
        mined = (np.abs(xs - spot[0]) <= half + 1) & (np.abs(ys - spot[1]) <= half + 1)
        in_box = (np.abs(xs - 32) <= box_half + 1) & (np.abs(ys - 0.45 * 48) <= box_half + 1)
        assert mined.sum() >= 40  # the square holds 7 x 7 pixels, fewer than the count asks
        assert np.all(mined | in_box), (xs, ys)  # the rest: the box's negatives (a near miss shown there)
        on_hand.append(int(in_box.sum()))
    assert min(on_hand) > 0


def test_stamps_that_start_over_continue_the_session():
    """A camera whose stamps start over mid-session: the states go on where they were (the
    session lasts as many frames as without the restart)."""
    rng = np.random.default_rng(0)
    frames = [_frame(rng) for _ in range(115)]

    def run(restart_at):
        tr = Trainer(None, _params(), np.random.default_rng(1), focal_px=100.0)
        tr.start("wave", 50 * NS)
        out = []
        for k, d in enumerate(frames):
            stamp = 50 * NS + k * NS // 10 if k < restart_at else (k - restart_at) * NS // 10
            s = tr.on_frame(d, stamp)
            out.append((s.state, s.round, round(s.seconds_left, 3)))
        return out, tr

    plain, _ = run(len(frames))
    restarted, tr = run(22)  # in the first update_positive
    assert restarted == plain and tr.restarts == 1 and tr.state == "done" and "wave" in tr.thresholds


def test_an_empty_session_teaches_nothing(tmp_path):
    """Nothing moves in view (nobody in the room): the session ends undone, the forest as it was."""
    rng = np.random.default_rng(0)
    tr = Trainer(None, _params(rounds=1), np.random.default_rng(1), focal_px=100.0)
    tr.start("wave", 0)
    statuses = [tr.on_frame(_frame(rng, present=1.0), k * NS // 10) for k in range(70)]
    assert statuses[-1].state == "done" and not tr.taught and tr.online is None
    assert "nothing moved in view" in statuses[-1].instruction
    tr.start("wave", 10 * NS)
    for k in range(70):  # the user in view, moving: taught
        tr.on_frame(_frame(rng), 10 * NS + k * NS // 10)
    assert tr.taught and "wave" in tr.thresholds
    path = tr.save(tmp_path / "room.forest.npz")
    known = Trainer(path, _params(rounds=1), np.random.default_rng(2))
    before = _arrays(known)
    known.start("wave", 20 * NS, extend=True)
    for k in range(70):
        known.on_frame(_frame(rng, present=1.0), 20 * NS + k * NS // 10)
    assert not known.taught and _same(before, _arrays(known))
