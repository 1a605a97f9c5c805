"""Names and class ids of the gestures of thesis ch. 3 (fig. 3.4) and of the gestures to teach.

Class 0 is the background; the gesture of class id ``c`` is ``ALL_GESTURES[c - 1]``. The
evaluator and the simulator name classes from this table.
"""
from __future__ import annotations

#: The six gesture classes of the thesis (fig. 3.4), in class-id order (ids 1..6): those of the
#: default bags and of the shipped forest.
GESTURE_CLASSES = ("tee", "pause", "silence", "cross", "ok", "volume_up")
#: Gestures to teach a room (ids 7, 8): rendered only when asked for (``hmocap sim gestures
#: --gestures``, the simulated teacher), never in a default bag, so the shipped forest has never
#: seen them.
NEW_GESTURES = ("thumbs_up", "raised_fist")
#: Every gesture class: ``class_id = ALL_GESTURES.index(name) + 1``.
ALL_GESTURES = GESTURE_CLASSES + NEW_GESTURES

#: Where each gesture's annotated point is (the simulator's table is :mod:`hmocap_sim.gesture_set`).
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


def class_id(name: str) -> int:
    """1-based class id of a gesture name (0 is background)."""
    return ALL_GESTURES.index(name) + 1
