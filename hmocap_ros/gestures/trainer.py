"""The interactive gesture trainer (thesis sec. 3.4.1, fig. 3.10 and 3.11) as a library state machine.

A user stands in front of a depth camera and follows instructions; every depth frame goes
through :meth:`Trainer.on_frame`, which learns from it according to the state and returns a
:class:`TrainerStatus` (what a display shows, fig. 3.11). States, per round:

1. ``do_gesture``: the user is asked to do the gesture centred in the box (no learning);
2. ``update_positive``: the user keeps it in the box with small pose variations; positive
   patches around the box centre update the online forest (sec. 3.3.1,
   :func:`~hmocap_ros.gestures.patches.collect_samples` with the box centre as the annotated
   point, so the frame's other pixels are its negatives, as offline);
3. ``release``: the user releases the gesture (no learning);
4. ``rehearse`` (when the forest knows other gestures): the user shows each of them in the
   box in turn, ``rehearse_s`` each, and their patches update the forest as positives of their
   own class (the first third of each slot, getting into the gesture, is not learnt);
5. ``do_negatives``: the user moves and does other gestures; negatives are mined on the fly
   where the forest as it stands fires (sec. 3.3.2,
   :func:`~hmocap_ros.gestures.hard_negatives.frame_negatives`);

repeated ``rounds`` times, then ``testing`` (the forest only detects), then ``done``. The
machine is driven by the frames' stamps (integer nanoseconds): a state lasts its duration
(:class:`TrainerParams`) from the stamp it began at; a state's end is the next one's start, so
a late or dropped frame never stretches the session. ``idle`` (before :meth:`Trainer.start`
and after :meth:`Trainer.cancel`) and ``done`` only detect.

**Automatic threshold** (sec. 3.4.1, "Obtaining the threshold"): on each ``update_positive``
frame ``th+_i`` is the detector's score (smoothed density p', eq. 3.4) of the taught gesture
at its maximum inside the box; on each ``do_negatives`` frame ``th-_i`` is its maximum over the
whole frame. Each is an exponential moving average ``th^_i = sigma th_i + (1 - sigma) th^_{i-1}``
(sigma = 0.9) and the threshold is ``th = rho th^+ + (1 - rho) th^-`` (:func:`blend_threshold`).
It is kept per gesture in the forest file (``meta["gesture_thresholds"]``).

Design choices where the thesis is vague:

- **The box** is a fixed region of the image, centred at ``box_u, box_v`` (fractions of the
  width and height) with half side ``box_half_size_px`` (pixels at the reference focal
  length); the variety between rounds (distance, place, background) comes from the user
  moving, as the thesis asks, not from a moving box.
- **Moving averages start** at the first value (``th^_0 = th_0``); the threshold is ``None``
  until both averages have a value and is then the detector's threshold for that gesture.
- **Several gestures in one forest**: teaching a gesture the forest does not know adds its
  class (:func:`add_class`): every node and every candidate test of the open leaves gets a
  zero count for it, so what the forest knows stays and the trees keep growing. Teaching a
  gesture it knows (``extend=True``) continues it. A user must not do the forest's other
  gestures while asked for negatives: they would be learnt as background (the instruction
  says so). The known gestures' patches are not relearnt by default; what they keep is what
  the leaves hold. A leaf that splits hands its children the statistics of the samples it saw
  itself (alg. 6), not those its parent handed it, so every split made on the new gesture's
  session drops old evidence in that part of the tree (the background's as much as the known
  gestures'). The thesis' *do negative examples* asks the user for "other gestures that
  should be distinguished"; the known ones can be shown in a ``rehearse`` state of each round
  and learnt as themselves (``rehearse_s`` > 0). It is off by default: its time is taken from
  the negatives, so it costs the new gesture's accuracy, and the session grows with every
  known gesture (docs/gestures_interactive.md, "Several gestures in one forest").
- **The online forest of a new forest** (:class:`SessionOnlineParams`) splits a leaf after
  ``alpha`` = 100 samples instead of the 300 of the offline-bag online training: a session is
  one pass over a few hundred frames, and with 300 the trees of a 1-minute session stay
  shallow (sec. 3.3.1: "if alpha is too large ... the trees not grown to its maximum depth";
  docs/gestures_interactive.md, "What a session's AP depends on").
- **Recording** (``record=True``): the frames the trainer learns from are kept with their
  annotation (the box centre in ``update_positive`` and ``rehearse``, background in
  ``do_negatives``), as the thesis' loop records them for the offline comparison of
  sec. 3.4.2 (:attr:`Trainer.recording`, written as a bag by
  :func:`~hmocap_sim.gesture_teacher.write_recording_bag`).
- **Cancel** puts back the forest as it was when the round began (a copy taken at each
  round's start; for the first round, before the class was added) and the averages with it.
- **Camera**: the forest learns in the pixels of the camera it sees (its tests are
  pixel*metres at that focal length, ``meta["training"]["focal_px"]``); a forest grown at one
  focal length is not taught with another camera.
- **Stamps that start over** (a camera or a replay restarting) continue the session: the
  states' clock is shifted so that the frame follows the last one by one frame period
  (``restarts`` counts them); the detector's smoothing restarts as in the node.
- **An empty session** (nothing moved in view: nobody in the room, :mod:`~hmocap_ros.gestures.scene_motion`)
  is undone at its end: the forest and the averages go back to what they were before the
  session, no threshold is kept, ``taught`` is false and ``done``'s instruction says why.
- **The negative phase asks for near misses** (``do_negatives``' instruction: the gesture done
  wrong, a finger bent, the hand turned, the arm half raised): the thesis asks for "other
  gestures that should be distinguished"; the near misses of the taught gesture are the
  poses its detector most needs to refuse, and on-the-fly mining learns them where the forest
  fires on them. Besides, each ``do_negatives`` frame gives ``patches.n_near_miss`` negatives
  in the box, on the surface at its centre (:func:`~hmocap_ros.gestures.patches.hand_negatives`):
  a near miss shown in the box is learnt where the gesture's positives were taken, whether or
  not the forest fires on it yet (the located negatives of offline training).
- **The threshold's parts** th+ and th- are kept beside it (``meta["gesture_threshold_parts"]``)
  so that another rho can be applied to a taught forest (``hmocap bench iml`` measures each).
- **An offline forest** (e.g. the shipped one) is taught a gesture by continuing it online
  (:meth:`~hmocap_ros.gestures.online_forest.OnlineForest.from_offline`): its leaves open to
  split statistics when the taught gesture's samples reach them.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from hmocap_ros.gestures.depth_features import depth_to_metres
from hmocap_ros.gestures.detection import Detection, GestureDetector
from hmocap_ros.gestures.forest_file import load_forest, save_forest
from hmocap_ros.gestures.hard_negatives import (
    frame_negatives,
    hard_negative_pixels,
    negative_counts,
    random_negative_pixels,
    vote_density,
)
from hmocap_ros.gestures.online_forest import OnlineForest
from hmocap_ros.gestures.params import (
    REFERENCE_FOCAL_PX,
    DetectorParams,
    FeatureParams,
    OnlineParams,
    OnlineTrainParams,
    PatchParams,
)
from hmocap_ros.gestures.patches import collect_samples, hand_negatives
from hmocap_ros.gestures.scene_motion import SceneMotion
from hmocap_ros.gestures.trees import Forest, PendingTests, Tree
from hmocap_ros.params import group, param

__all__ = ["LEARNING_STATES", "STATES", "RecordedFrame", "SessionOnlineParams", "Trainer", "TrainerParams",
           "TrainerStatus", "add_class", "blend_threshold", "moving_average"]

#: States of the trainer (sec. 3.4.1, fig. 3.10), in the order of a session.
STATES = ("idle", "do_gesture", "update_positive", "release", "rehearse", "do_negatives", "testing", "done")
#: States in which frames update the forest.
LEARNING_STATES = ("update_positive", "rehearse", "do_negatives")
_ROUND = ("do_gesture", "update_positive", "release", "rehearse", "do_negatives")

INSTRUCTIONS = {
    "idle": "Waiting for a gesture to teach.",
    "do_gesture": "Do the gesture '{g}' with its centre in the box.",
    "update_positive": "Keep '{g}' in the box and vary your pose a little.",
    "release": "Release the gesture and wait.",
    "rehearse": "Show '{r}' (a gesture the room knows) in the box.",
    "do_negatives": "Move around and do other things: '{g}' done wrong in the box (a finger bent, the hand "
                    "turned, the arm half raised), other poses; not '{g}', nor the room's other gestures.",
    "testing": "Testing: do '{g}' anywhere and check that it is found.",
    "done": "'{g}' is taught.",
}
#: The instruction of ``done`` after a session that saw nobody in the box (module docstring).
NOBODY = "'{g}' was not taught: nothing moved in view; the forest is as it was before the session."


@dataclass(frozen=True)
class SessionOnlineParams(OnlineParams):
    """The online forest a teaching session grows (sec. 3.3.1, alg. 6): :class:`OnlineParams`
    with a lower ``alpha`` (module docstring, "The online forest of a new forest")."""

    alpha: float = param(
        100.0, "alpha: a leaf splits only after it has seen more than this many samples (>= 0, "
               "Poisson-weighted, its own samples, not those handed down); lower than offline-bag "
               "online training because a session is one pass over a few hundred frames.")


@dataclass(frozen=True)
class RecordedFrame:
    """A frame the trainer learnt from (``record=True``): ``depth_mm`` uint16 millimetres (0 =
    invalid), its stamp, and its annotation: ``gesture`` (the class name, "" = background) at
    pixel ``(u, v)`` (the box centre)."""

    depth_mm: np.ndarray
    stamp_ns: int
    gesture: str
    u: float
    v: float


@dataclass(frozen=True)
class TrainerParams:
    """The interactive trainer (thesis sec. 3.4.1). Pixel sizes are given for a camera of focal
    length 525 px and scaled to the camera's."""

    rounds: int = param(3, "Rounds of do_gesture, update_positive, release, do_negatives (>= 1).")
    do_gesture_s: float = param(3.0, "Seconds (> 0) the user has to bring the gesture into the box.")
    update_positive_s: float = param(6.0, "Seconds (> 0) of learning the gesture held in the box.")
    release_s: float = param(2.0, "Seconds (> 0) to release the gesture.")
    do_negatives_s: float = param(10.0, "Seconds (> 0) of learning negatives mined on the fly.")
    testing_s: float = param(10.0, "Seconds (>= 0) of testing after the last round (detection only).")
    rehearse_s: float = param(
        0.0, "Seconds (>= 0) per gesture the forest already knows in the rehearse state of each round: "
             "the user shows each of them in the box in turn and they are learnt as themselves, so "
             "teaching one more gesture keeps the others (0 = no rehearsal).")
    box_u: float = param(0.5, "Box centre column as a fraction of the image width, in (0, 1).")
    box_v: float = param(0.45, "Box centre row as a fraction of the image height, in (0, 1).")
    box_half_size_px: float = param(
        24.0, "Half side of the box in pixels at the reference focal length (> 0): the region where "
              "the user is asked to hold the gesture and where th+ is read.")
    motion_fraction: float = param(
        0.01, "The scene moved between two frames 0.25 s apart when more than this fraction (in (0, 1)) "
              "of the pixels changed depth by more than 5 cm (and 3 % of the depth).")
    min_moving: float = param(
        0.05, "A session in which the scene moved in fewer than this fraction (in [0, 1]) of its 0.25-s "
              "steps saw nobody: it is undone and teaches nothing.")
    sigma: float = param(0.9, "Weight sigma in (0, 1] of the newest value in the moving averages of th+ and th-.")
    rho: float = param(
        0.8, "Threshold th = rho th+ + (1 - rho) th-, rho in [0, 1]: higher = fewer false "
             "positives (0.8 for a low false positive rate, sec. 3.4.1).")
    features: FeatureParams = group(FeatureParams, "Tests of a new forest (eq. 3.6).")
    patches: PatchParams = group(PatchParams, "Positive patches around the box centre (sec. 3.2.3).")
    online: OnlineParams = group(SessionOnlineParams, "Online forest of a new forest and its negatives (sec. 3.3).")
    detector: DetectorParams = group(DetectorParams, "The on-the-fly detector (sec. 3.2.4).")

    def __post_init__(self):
        checks = [(self.rounds >= 1, "rounds must be >= 1"),
                  (min(self.do_gesture_s, self.update_positive_s, self.release_s, self.do_negatives_s) > 0,
                   "the round's durations must be > 0"),
                  (self.testing_s >= 0 and self.rehearse_s >= 0, "testing_s and rehearse_s must be >= 0"),
                  (0 < self.box_u < 1 and 0 < self.box_v < 1, "box_u and box_v must be in (0, 1)"),
                  (self.box_half_size_px > 0, "box_half_size_px must be > 0"),
                  (0 < self.motion_fraction < 1 and 0 <= self.min_moving <= 1,
                   "need motion_fraction in (0, 1) and min_moving in [0, 1]"),
                  (0 < self.sigma <= 1, "sigma must be in (0, 1]"),
                  (0 <= self.rho <= 1, "rho must be in [0, 1]")]
        for ok, message in checks:
            if not ok:
                raise ValueError(f"TrainerParams: {message}")

    def round_s(self, n_rehearsed: int = 0) -> float:
        """Seconds of one round (do_gesture + update_positive + release + rehearse of
        ``n_rehearsed`` known gestures + do_negatives)."""
        return sum(self.duration_s(s, n_rehearsed) for s in _ROUND)

    def session_s(self, n_rehearsed: int = 0) -> float:
        """Seconds of a whole session: ``rounds`` rounds and the testing phase."""
        return self.rounds * self.round_s(n_rehearsed) + self.testing_s

    def progress(self, state: str, round_: int, seconds_left: float, n_rehearsed: int = 0) -> float:
        """Fraction in [0, 1] of the session elapsed in ``state`` of round ``round_`` with
        ``seconds_left`` (0 when idle, 1 when done)."""
        if state == "idle":
            return 0.0
        total = self.session_s(n_rehearsed)
        if state == "done" or total <= 0:
            return 1.0
        if state == "testing":
            before = self.rounds * self.round_s(n_rehearsed)
        else:
            before = (round_ - 1) * self.round_s(n_rehearsed) + sum(
                self.duration_s(s, n_rehearsed) for s in _ROUND[:_ROUND.index(state)])
        elapsed = before + self.duration_s(state, n_rehearsed) - seconds_left
        return float(min(1.0, max(0.0, elapsed / total)))

    def duration_s(self, state: str, n_rehearsed: int = 0) -> float:
        """Seconds ``state`` lasts (inf for idle and done); rehearse lasts ``rehearse_s`` per
        rehearsed gesture."""
        return {"do_gesture": self.do_gesture_s, "update_positive": self.update_positive_s,
                "release": self.release_s, "rehearse": self.rehearse_s * n_rehearsed,
                "do_negatives": self.do_negatives_s, "testing": self.testing_s}.get(state, float("inf"))


@dataclass(frozen=True)
class TrainerStatus:
    """What the trainer shows after a frame (fig. 3.11): ``box`` = (u, v, half side) pixels;
    ``detection`` the taught gesture's detection (or the best one) if any; ``samples`` how many
    patches the frame taught; ``progress`` the fraction of the session (rounds and testing)
    elapsed, in [0, 1]; ``rehearsed`` the known gesture the user is asked to show (rehearse)."""

    state: str
    gesture: str
    round: int
    rounds: int
    seconds_left: float
    threshold: float | None
    instruction: str
    box: tuple
    detection: Detection | None
    detections: tuple
    stamp_ns: int
    known_gestures: tuple
    samples: int = 0
    progress: float = 0.0
    rehearsed: str = ""


def moving_average(previous: float | None, value: float, sigma: float) -> float:
    """``sigma value + (1 - sigma) previous`` (sec. 3.4.1); the first value starts it."""
    return float(value) if previous is None else float(sigma) * float(value) + (1.0 - float(sigma)) * previous


def blend_threshold(th_pos: float | None, th_neg: float | None, rho: float) -> float | None:
    """``th = rho th+ + (1 - rho) th-`` (sec. 3.4.1); None until both are known."""
    if th_pos is None or th_neg is None:
        return None
    return float(rho) * th_pos + (1.0 - float(rho)) * th_neg


def add_class(forest: OnlineForest, name: str) -> OnlineForest:
    """``forest`` with one more class ``name`` (last): every node's and open candidate test's
    statistics get a zero count for it (nothing learnt is lost; module docstring)."""
    f = forest.to_forest()

    def pad(a: np.ndarray) -> np.ndarray:
        return np.concatenate([a, np.zeros(a.shape[:-1] + (1,), a.dtype)], axis=-1)

    trees = []
    for t in f.trees:
        tree = Tree(t.feature, t.threshold, t.left, t.right, pad(t.counts), t.depth)
        p = t.pending
        tree.pending = None if p is None else PendingTests(p.node, p.feature, p.threshold, pad(p.counts))
        trees.append(tree)
    meta = copy.deepcopy(f.meta)
    meta["online"]["seen"] = list(meta["online"]["seen"]) + [0]
    grown = Forest(trees, f.class_names + (str(name),), f.features, "online", meta)
    return OnlineForest.from_forest(grown, forest.params)


class Trainer:
    """The interactive trainer (module docstring).

    ``forest_or_path``: an :class:`OnlineForest`, an online :class:`Forest`, the path of a forest
    file (kept growing where it stopped), an offline :class:`Forest` (continued online,
    :meth:`OnlineForest.from_offline`: e.g. the shipped forest taught one more gesture), or
    None / a path that does not exist (a new forest
    from ``params.features`` and ``params.online`` at the first :meth:`start`). ``focal_px``: the
    camera's focal length; None = the forest's training focal length (required for a new forest).
    ``record``: keep the frames learnt from with their annotation in :attr:`recording` (module
    docstring, "Recording").
    """

    def __init__(self, forest_or_path, params: TrainerParams | None = None,
                 rng: np.random.Generator | None = None, focal_px: float | None = None, record: bool = False):
        self.params = params if params is not None else TrainerParams()
        self.rng = rng if rng is not None else np.random.default_rng(0)
        forest = forest_or_path
        if isinstance(forest, (str, Path)):
            forest = load_forest(forest) if Path(forest).exists() else None
        if forest is not None and not isinstance(forest, (Forest, OnlineForest)):
            raise TypeError("forest_or_path must be an OnlineForest, a Forest, a path or None")
        trained = None
        if forest is not None:
            trained = forest.meta.get("training", {}).get("focal_px")
        if focal_px is None and not trained:
            raise ValueError("the camera's focal length is needed (focal_px) for a forest without one")
        if focal_px is not None and trained and abs(float(trained) - float(focal_px)) > 1e-6 * float(focal_px):
            raise ValueError(f"the forest was grown at fx {trained:g} px, the camera has {focal_px:g} px")
        focal = focal_px if focal_px is not None else trained
        assert focal is not None  # a forest without a focal length raised above
        self.focal_px = float(focal)
        scaled = OnlineTrainParams(features=self.params.features, patches=self.params.patches,
                                   online=self.params.online).for_focal(self.focal_px)
        if isinstance(forest, Forest):
            forest = (OnlineForest.from_offline(forest, scaled.online) if forest.kind == "offline"
                      else OnlineForest.from_forest(forest))
        self.online: OnlineForest | None = forest
        self._new_params = scaled
        self.patches = scaled.patches
        self.state = "idle"
        self.gesture = ""
        self.round = 0
        self._state_start: int | None = None
        self._rehearsed: tuple = ()
        self._snapshot: tuple[OnlineForest | None, float | None, float | None] | None = None
        self.th_pos: float | None = None
        self.th_neg: float | None = None
        self.detector: GestureDetector | None = None
        self.taught = False
        self.restarts = 0
        self._last_stamp: int | None = None
        self._period = 0
        self._session_snapshot: tuple[OnlineForest | None, float | None, float | None] | None = None
        self._presence: SceneMotion | None = None
        self.record = bool(record)
        self.recording: list[RecordedFrame] = []
        if self.online is not None:
            self._refresh_detector()

    # ------------------------------------------------------------------ the forest

    @property
    def thresholds(self) -> dict:
        """Detection threshold per gesture name (``meta["gesture_thresholds"]``)."""
        return dict(self.online.meta.get("gesture_thresholds", {})) if self.online is not None else {}

    @property
    def threshold(self) -> float | None:
        return blend_threshold(self.th_pos, self.th_neg, self.params.rho)

    def _refresh_detector(self) -> None:
        assert self.online is not None  # called only once there is a forest
        forest = self.online.to_forest()
        if self.detector is None:
            det = replace(self.params.detector, min_score=0.0)
            self.detector = GestureDetector(forest, det, focal_px=self.focal_px)
        else:
            self.detector.set_forest(forest)

    def forest(self) -> Forest:
        """The forest as it stands (kind online), with the thresholds and the generator's state."""
        assert self.online is not None, "no forest yet: start teaching a gesture first"
        f = self.online.to_forest()
        f.meta["online"]["rng_state"] = self.rng.bit_generator.state
        return f

    def save(self, path) -> Path:
        """Write the forest to ``path`` atomically (temporary file + ``os.replace``,
        :func:`~hmocap_ros.gestures.forest_file.save_forest`)."""
        if self.online is None:
            raise ValueError("no forest yet: start teaching a gesture first")
        return save_forest(self.forest(), path)

    # ------------------------------------------------------------------ the session

    def start(self, gesture_name: str, stamp_ns: int | None, extend: bool = False) -> None:
        """Begin teaching ``gesture_name`` at ``stamp_ns`` (first round, ``do_gesture``; None = at
        the next frame's stamp, when no frame has come yet). A gesture the forest knows needs
        ``extend=True`` (keep teaching it); a new one adds its class."""
        name = str(gesture_name).strip()
        if not name or name == "background":
            raise ValueError(f"not a gesture name: {gesture_name!r}")
        if self.state not in ("idle", "done"):
            raise ValueError(f"already teaching '{self.gesture}' (state {self.state}); cancel first")
        known = self.online.class_names if self.online is not None else ()
        if name in known and not extend:
            raise ValueError(f"the forest already knows '{name}' (extend=True to keep teaching it)")
        self._snapshot = (copy.deepcopy(self.online), self.th_pos, self.th_neg)
        self._session_snapshot = self._snapshot
        self._presence = SceneMotion(self.params.features.background_depth_m, self.params.motion_fraction,
                                     self.params.min_moving)
        self.taught = False
        if self.online is None:
            p = self._new_params
            meta = {"training": {"method": "interactive", "focal_px": self.focal_px}}
            self.online = OnlineForest(("background", name), p.features, p.online, self.rng, meta)
        elif name not in known:
            self.online = add_class(self.online, name)
        self._refresh_detector()
        self.gesture = name
        self._rehearsed = tuple(c for c in self.online.class_names[1:] if c != name)
        self.th_pos = self.th_neg = None
        self.round = 1
        self._last_stamp, self._period = (None if stamp_ns is None else int(stamp_ns)), 0
        self._enter("do_gesture", None if stamp_ns is None else int(stamp_ns))

    def cancel(self) -> None:
        """Stop the session; the forest is put back as it was when the current round began."""
        if self.state in LEARNING_STATES + ("do_gesture", "release") and self._snapshot is not None:
            forest, self.th_pos, self.th_neg = self._snapshot
            self.online = forest
            if self.online is not None:
                self._refresh_detector()
            else:
                self.detector = None
        self.state = "idle"
        self.round = 0
        self._state_start = None

    def _enter(self, state: str, stamp_ns: int | None) -> None:
        self.state = state
        self._state_start = stamp_ns

    def _advance(self, stamp_ns: int) -> None:
        """Move through the states whose time is over at ``stamp_ns`` (module docstring)."""
        if self._state_start is None and self.state not in ("idle", "done"):
            self._state_start = stamp_ns  # started before any frame: the session begins now
        while self.state not in ("idle", "done"):
            assert self._state_start is not None  # set just above, and by every _enter below
            end = self._state_start + int(round(self._duration(self.state) * 1e9))
            if stamp_ns < end:
                return
            if self.state == "do_negatives" and self.round < self.params.rounds:
                self.round += 1
                self._snapshot = (copy.deepcopy(self.online), self.th_pos, self.th_neg)
                nxt = "do_gesture"
            elif self.state == "do_negatives":
                nxt = "testing"
            elif self.state == "testing":
                nxt = "done"
            else:
                nxt = _ROUND[_ROUND.index(self.state) + 1]
            if self.state == "do_negatives" and nxt == "testing" and not self._finish_session():
                nxt = "done"
            self._enter(nxt, end)

    @property
    def rehearsed(self) -> tuple:
        """The known gestures rehearsed in each round of the session (all but the taught one)."""
        return self._rehearsed

    def _duration(self, state: str) -> float:
        return self.params.duration_s(state, len(self._rehearsed))

    def rehearsed_now(self, stamp_ns: int) -> tuple[str, bool]:
        """In ``rehearse``: the known gesture to show at ``stamp_ns`` and whether its frames are
        learnt (not in the first third of its slot, while the user gets into it)."""
        if self.state != "rehearse" or not self._rehearsed or self.params.rehearse_s <= 0:
            return "", False
        assert self._state_start is not None  # _advance has started the state
        t = (stamp_ns - self._state_start) * 1e-9
        slot = min(int(t // self.params.rehearse_s), len(self._rehearsed) - 1)
        return self._rehearsed[slot], t - slot * self.params.rehearse_s >= self.params.rehearse_s / 3.0

    def _finish_session(self) -> bool:
        """End of the last round: keep the threshold (and its parts th+, th-), or, when the
        session saw nobody in the box, put the forest back as it was before the session.
        Returns whether the gesture was taught."""
        assert self._presence is not None and self._session_snapshot is not None  # set by start()
        if not self._presence.somebody:
            forest, self.th_pos, self.th_neg = self._session_snapshot
            self.online = forest
            if self.online is not None:
                self._refresh_detector()
            else:
                self.detector = None
            return False
        th = self.threshold
        assert self.online is not None  # start() made or kept one
        if th is not None:
            self.online.meta.setdefault("gesture_thresholds", {})[self.gesture] = th
            self.online.meta.setdefault("gesture_threshold_parts", {})[self.gesture] = [self.th_pos, self.th_neg]
        self.taught = True
        return True

    def box(self, width: int, height: int) -> tuple:
        """(u, v, half side) of the box in pixels for an image ``width`` x ``height``."""
        half = self.params.box_half_size_px * self.focal_px / REFERENCE_FOCAL_PX
        return (self.params.box_u * width, self.params.box_v * height, half)

    def on_frame(self, depth_m: np.ndarray, stamp_ns: int) -> TrainerStatus:
        """Process one depth frame (metres, or REP 118 raw units per ``params.detector``) taken at
        ``stamp_ns``: advance the states, learn per the state, detect; returns the status."""
        stamp_ns = int(stamp_ns)
        depth = np.asarray(depth_m)
        if depth.ndim != 2:
            raise ValueError(f"depth must be a 2-D image, got shape {depth.shape}")
        self._follow_stamps(stamp_ns)
        self._advance(stamp_ns)
        h, w = depth.shape
        box = self.box(w, h)
        if self.online is None:
            return self._status(stamp_ns, box, (), 0)
        cls = self.online.class_names.index(self.gesture) if self.gesture in self.online.class_names else 0
        assert self.detector is not None  # made with the forest (_refresh_detector)
        detections = tuple(self.detector.update(depth, stamp_ns))
        samples = 0
        in_session = self.state not in ("idle", "done")
        if in_session:
            bg = np.float32(self.online.features.background_depth_m)
            metres = depth_to_metres(depth, self.params.detector.depth_format, float(bg))
            assert self._presence is not None  # set by start()
            self._presence.see(metres, stamp_ns)
        if self.state in LEARNING_STATES:
            dens = self.detector.density[:, :, cls - 1] if self.detector.density is not None else None
            shown, learn = self.rehearsed_now(stamp_ns)
            if self.state == "update_positive" or learn:
                if dens is not None and dens.size and not shown:
                    self.th_pos = moving_average(self.th_pos, self._box_max(dens, box), self.params.sigma)
                c = self.online.class_names.index(shown) if shown else cls
                s = collect_samples(metres[None], [(c, int(round(box[0])), int(round(box[1])))], self.patches,
                                    self.online.features, self.rng, len(self.online.class_names))
                xs, ys, labels = s.x, s.y, s.label
            elif self.state == "rehearse":
                xs = ys = labels = np.zeros(0, np.int32)
            else:
                if dens is not None and dens.size:
                    self.th_neg = moving_average(self.th_neg, float(dens.max()), self.params.sigma)
                xs, ys = self._negatives(metres)
                hx, hy = hand_negatives(metres, int(round(box[0])), int(round(box[1])), self.patches,
                                        float(self.online.features.background_depth_m), self.rng)
                xs, ys = np.concatenate([xs, hx]), np.concatenate([ys, hy])
                labels = np.zeros(xs.size, np.int32)
            if self.record and (self.state == "do_negatives" or labels.size):
                name = "" if self.state == "do_negatives" else self.online.class_names[int(labels.max())]
                self._keep(metres, stamp_ns, name, box)
            if labels.size:
                self.online.update(metres[None], np.zeros(labels.size, np.int32), xs, ys, labels, self.rng)
                self._refresh_detector()
            samples = int(labels.size)
        return self._status(stamp_ns, box, self._shown(detections, cls), samples)

    def _follow_stamps(self, stamp_ns: int) -> None:
        """Stamps that go back in time (a camera or a replay that starts over) continue the
        session: the states' clock is shifted so that the frame comes one frame period after
        the last one (``restarts`` counts them)."""
        if self._last_stamp is not None and stamp_ns < self._last_stamp:
            shift = stamp_ns - self._last_stamp - self._period
            if self._state_start is not None:
                self._state_start += shift
            self.restarts += 1
        elif self._last_stamp is not None and stamp_ns > self._last_stamp:
            self._period = stamp_ns - self._last_stamp
        self._last_stamp = stamp_ns

    def _keep(self, metres: np.ndarray, stamp_ns: int, gesture: str, box: tuple) -> None:
        """Append the frame to :attr:`recording` as uint16 millimetres (invalid = 0)."""
        assert self.online is not None  # frames are kept only while teaching
        bg = np.float32(self.online.features.background_depth_m)
        mm = np.where(metres < bg, np.rint(metres * 1000.0), 0.0)
        self.recording.append(RecordedFrame(np.clip(mm, 0, 65535).astype(np.uint16), int(stamp_ns), gesture,
                                            float(box[0]), float(box[1])))

    def _negatives(self, metres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Negatives of a ``do_negatives`` frame (sec. 3.3.2). The detector has just voted on this
        frame with this forest: at the same grid step its votes are those
        :func:`~hmocap_ros.gestures.hard_negatives.frame_negatives` would compute, and are used
        as they are (one forest evaluation per frame instead of two)."""
        assert self.online is not None and self.detector is not None  # called while teaching
        op, det = self.online.params, self.detector
        if det.class_map is None or det.active_params.stride != op.stride:
            xs, ys, _ = frame_negatives(self.online.flat(), metres, op, self.rng)
            return xs, ys
        bg = self.online.features.background_depth_m
        density = vote_density(det.class_map, len(self.online.class_names) - 1, op.parzen_sigma_px / op.stride)
        counts = negative_counts(density, op.n_frame_negatives)
        if op.negatives == "hard":
            assert det.grid_depth is not None  # voted together with class_map
            return hard_negative_pixels(density, det.grid_depth, metres, op.stride, counts,
                                        op.hard_half_size_px_m, bg, self.rng)
        return random_negative_pixels(metres, int(counts.sum()), bg, self.rng)

    def _box_max(self, dens: np.ndarray, box: tuple) -> float:
        """Maximum of a density grid (gh, gw) over the grid cells inside the box."""
        assert self.detector is not None  # the density comes from it
        p = self.detector.active_params
        off, s = self.detector.grid_offset, p.stride
        u, v, half = box
        gx0, gx1 = int(np.ceil((u - half - off) / s)), int(np.floor((u + half - off) / s)) + 1
        gy0, gy1 = int(np.ceil((v - half - off) / s)), int(np.floor((v + half - off) / s)) + 1
        win = dens[max(gy0, 0):max(gy1, 0), max(gx0, 0):max(gx1, 0)]
        return float(win.max()) if win.size else 0.0

    def _shown(self, detections: tuple, cls: int) -> tuple:
        """The detections kept by each gesture's threshold (the learnt one, else the detector's
        ``min_score``; the taught gesture's running threshold while it is taught)."""
        ths = self.thresholds
        if self.gesture and self.threshold is not None and self.state != "idle":
            ths[self.gesture] = self.threshold
        floor = self.params.detector.min_score
        return tuple(d for d in detections if d.score >= ths.get(d.name, floor))

    def _status(self, stamp_ns: int, box: tuple, detections: tuple, samples: int) -> TrainerStatus:
        left = 0.0
        if self._state_start is not None and self.state not in ("idle", "done"):
            left = max(0.0, self._duration(self.state) - (stamp_ns - self._state_start) * 1e-9)
        mine = [d for d in detections if d.name == self.gesture]
        detection = mine[0] if mine else (detections[0] if detections else None)
        known = tuple(self.online.class_names[1:]) if self.online is not None else ()
        shown = self.rehearsed_now(stamp_ns)[0]
        text = NOBODY if self.state == "done" and self._presence is not None and not self.taught \
            else INSTRUCTIONS[self.state]
        return TrainerStatus(self.state, self.gesture, self.round, self.params.rounds, left, self.threshold,
                             text.format(g=self.gesture, r=shown), box, detection, detections,
                             stamp_ns, known, samples,
                             self.params.progress(self.state, self.round, left, len(self._rehearsed)), shown)

    def status(self, stamp_ns: int = 0, width: int = 640, height: int = 480) -> TrainerStatus:
        """The status without a frame (e.g. before the first one)."""
        return self._status(int(stamp_ns), self.box(width, height), (), 0)
