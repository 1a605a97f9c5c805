"""Names and class ids of the gestures of thesis ch. 3 and of the non-gesture pose kinds.

The table of the six classes (pose, reference point) is in :mod:`hmocap_ros.sim.gesture_set`;
the builders of each kind are in :mod:`hmocap_ros.sim.gesture_specs` and
:mod:`hmocap_ros.sim.gesture_negatives`.
"""
from __future__ import annotations

#: Gesture classes in class-id order: ``class_id = GESTURE_CLASSES.index(name) + 1``.
GESTURE_CLASSES = ("tee", "pause", "silence", "cross", "ok", "volume_up")

#: Where each gesture's annotated point is (the table of :mod:`hmocap_ros.sim.gesture_set`).
REFERENCE_POINTS = {
    "tee": "contact point of the two hands (middle fingertip of the vertical hand)",
    "pause": "palm centre of the raised hand",
    "silence": "index finger on the lips (the mouth point, on the finger)",
    "cross": "crossing point of the two forearms (midpoint of their axes' closest approach)",
    "ok": "palm centre of the ok hand",
    "volume_up": "palm centre of the hand cupped at the ear",
}

#: Non-gesture pose kinds (background class): motion, idle and near misses.
NEGATIVE_KINDS = ("idle", "walk", "random_arms", "fold_arms", "chin", "phone", "point",
                  "scratch_head", "hips", "clasp", "wave_side")


#: Relative frequency of each negative kind in a generated set.
NEGATIVE_WEIGHTS = {"idle": 2.0, "walk": 1.5, "random_arms": 2.0, "fold_arms": 1.0, "chin": 1.0,
                    "phone": 1.0, "point": 1.0, "scratch_head": 0.7, "hips": 0.8, "clasp": 0.8,
                    "wave_side": 0.8}


def class_id(name: str) -> int:
    """1-based class id of a gesture name (0 is background)."""
    return GESTURE_CLASSES.index(name) + 1
