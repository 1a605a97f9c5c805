"""Whether anybody moved in view during a teaching session (the check behind "an empty
session": a camera looking at an empty room teaches nothing).

:class:`SceneMotion` compares the frames of the session ``interval_s`` (0.25 s) apart by their
stamps, whatever the frame rate, on a coarse grid (every ``step``-th pixel): a pixel changed
when both frames have a valid depth there and they differ by more than ``max(5 cm, 3 % of the
depth)`` (well above a Kinect-like camera's noise); a comparison *moved* when more than
``changed_fraction`` of the grid pixels valid in both frames changed. A session in which fewer
than ``min_moving`` of the comparisons moved saw nobody.

Design choice (not in the thesis): presence is read from motion over the whole session, not
from the box: a user holding a gesture still changes as few pixels from frame to frame as the
camera's noise (docs/gestures_interactive.md, "gesture_trainer"), but every round has a user walking to a
new spot, releasing the gesture and moving around for negatives (a few % of the pixels in
each of those frames), while an empty room only shows the sensor's noise.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SceneMotion"]


class SceneMotion:
    """Frame-to-frame change of one session (module docstring); ``background_m``: the depth
    invalid pixels read (never a valid depth)."""

    def __init__(self, background_m: float, changed_fraction: float = 0.01, min_moving: float = 0.05,
                 step: int = 4, interval_s: float = 0.25):
        self.background = np.float32(background_m)
        self.changed_fraction = float(changed_fraction)
        self.min_moving = float(min_moving)
        self.step = int(step)
        self.interval_ns = int(round(interval_s * 1e9))
        self._reference: np.ndarray | None = None
        self._reference_stamp = 0
        self.frames = 0
        self.moving = 0

    def see(self, metres: np.ndarray, stamp_ns: int) -> bool:
        """Take the next frame of the session (float32 metres, its stamp); returns whether it was
        compared with the frame ``interval_s`` before and moved."""
        grid = metres[::self.step, ::self.step]
        stamp_ns = int(stamp_ns)
        prev = self._reference
        if prev is None or prev.shape != grid.shape or stamp_ns < self._reference_stamp:
            self._reference, self._reference_stamp = grid.copy(), stamp_ns
            return False
        if stamp_ns - self._reference_stamp < self.interval_ns:
            return False
        self._reference, self._reference_stamp = grid.copy(), stamp_ns
        self.frames += 1
        valid = (grid < self.background) & (prev < self.background)
        n = int(np.count_nonzero(valid))
        if n == 0:
            return False
        changed = valid & (np.abs(grid - prev) > np.maximum(np.float32(0.05), np.float32(0.03) * grid))
        moved = np.count_nonzero(changed) > self.changed_fraction * n
        self.moving += int(moved)
        return bool(moved)

    @property
    def somebody(self) -> bool:
        """Whether the session saw somebody (at least ``min_moving`` of its comparisons moved)."""
        return self.frames > 0 and self.moving >= self.min_moving * self.frames
