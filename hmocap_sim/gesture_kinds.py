"""The non-gesture pose kinds the simulator renders (everyday motions and near misses); the
gesture names and class ids are :mod:`hmocap_ros.gestures.classes`.

The table of the classes (pose, reference point) is in :mod:`hmocap_sim.gesture_set`;
the builders of each kind are in :mod:`hmocap_sim.gesture_specs`,
:mod:`hmocap_sim.gesture_negatives` and :mod:`hmocap_sim.gesture_near_misses`.
"""
from __future__ import annotations

#: Non-gesture pose kinds (background class): motion, idle and near misses.
NEGATIVE_KINDS = ("idle", "walk", "random_arms", "fold_arms", "chin", "phone", "point",
                  "scratch_head", "hips", "clasp", "wave_side")


#: Relative frequency of each negative kind in a generated set.
NEGATIVE_WEIGHTS = {"idle": 2.0, "walk": 1.5, "random_arms": 2.0, "fold_arms": 1.0, "chin": 1.0,
                    "phone": 1.0, "point": 1.0, "scratch_head": 0.7, "hips": 0.8, "clasp": 0.8,
                    "wave_side": 0.8}


#: Near misses (background class): each gesture done slightly wrong, the poses a detector must
#: refuse. kind -> the gesture it misses (the builders and what is wrong in
#: :mod:`hmocap_sim.gesture_near_misses`).
NEAR_MISSES = {
    "tee_apart": "tee", "tee_fist": "tee",
    "pause_curled": "pause", "pause_one_bent": "pause", "pause_together": "pause", "pause_tilted": "pause",
    "pause_sideways": "pause", "pause_half": "pause",
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
