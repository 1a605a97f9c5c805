"""Names and class ids of the gestures of thesis ch. 3, the gestures to teach, and the
non-gesture pose kinds (everyday motions and near misses).

The table of the classes (pose, reference point) is in :mod:`hmocap_ros.sim.gesture_set`;
the builders of each kind are in :mod:`hmocap_ros.sim.gesture_specs`,
:mod:`hmocap_ros.sim.gesture_negatives` and :mod:`hmocap_ros.sim.gesture_near_misses`.
"""
from __future__ import annotations

#: The six gesture classes of the thesis (fig. 3.4), in class-id order (ids 1..6): those of the
#: default bags and of the shipped forest.
GESTURE_CLASSES = ("tee", "pause", "silence", "cross", "ok", "volume_up")
#: Gestures to teach a room (ids 7, 8): rendered only when asked for (``hmocap sim gestures
#: --gestures``, the simulated teacher), never in a default bag, so the shipped forest has never
#: seen them.
NEW_GESTURES = ("thumbs_up", "raised_fist")
#: Every gesture the simulator renders: ``class_id = ALL_GESTURES.index(name) + 1``.
ALL_GESTURES = GESTURE_CLASSES + NEW_GESTURES

#: Where each gesture's annotated point is (the table of :mod:`hmocap_ros.sim.gesture_set`).
REFERENCE_POINTS = {
    "tee": "contact point of the two hands (middle fingertip of the vertical hand)",
    "pause": "palm centre of the raised hand",
    "silence": "index finger on the lips (the mouth point, on the finger)",
    "cross": "crossing point of the two forearms (midpoint of their axes' closest approach)",
    "ok": "palm centre of the ok hand",
    "volume_up": "palm centre of the hand cupped at the ear",
    "thumbs_up": "palm centre of the fist whose thumb points up",
    "raised_fist": "palm centre of the fist raised above the shoulder",
}

#: Non-gesture pose kinds (background class): motion, idle and near misses.
NEGATIVE_KINDS = ("idle", "walk", "random_arms", "fold_arms", "chin", "phone", "point",
                  "scratch_head", "hips", "clasp", "wave_side")


#: Relative frequency of each negative kind in a generated set.
NEGATIVE_WEIGHTS = {"idle": 2.0, "walk": 1.5, "random_arms": 2.0, "fold_arms": 1.0, "chin": 1.0,
                    "phone": 1.0, "point": 1.0, "scratch_head": 0.7, "hips": 0.8, "clasp": 0.8,
                    "wave_side": 0.8}


#: Near misses (background class): each gesture done slightly wrong, the poses a detector must
#: refuse. kind -> the gesture it misses (the builders and what is wrong in
#: :mod:`hmocap_ros.sim.gesture_near_misses`).
NEAR_MISSES = {
    "tee_apart": "tee", "tee_fist": "tee",
    "pause_curled": "pause", "pause_sideways": "pause", "pause_half": "pause",
    "silence_cheek": "silence", "silence_bent": "silence",
    "cross_apart": "cross", "cross_one": "cross",
    "ok_open": "ok", "ok_closed": "ok",
    "volume_low": "volume_up", "volume_flat": "volume_up",
    "thumbs_sideways": "thumbs_up", "thumbs_tucked": "thumbs_up",
    "raised_fist_half": "raised_fist", "raised_open": "raised_fist",
}
NEAR_MISS_KINDS = tuple(NEAR_MISSES)


def near_misses_of(gestures) -> tuple:
    """The near-miss kinds of ``gestures``, in :data:`NEAR_MISS_KINDS` order."""
    wanted = set(gestures)
    return tuple(k for k, g in NEAR_MISSES.items() if g in wanted)


def class_id(name: str) -> int:
    """1-based class id of a gesture name (0 is background)."""
    return ALL_GESTURES.index(name) + 1
