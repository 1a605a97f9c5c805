"""Frame sets of live camera images for a calibration: images of the cameras grouped by
stamp, at most one set per ``min_interval_ns``, and when the collection has enough.

:class:`FrameSetCollector` takes images as they arrive (any order, any camera) and groups
them with the nodes' :class:`~hmocap_ros.stamp_sync.StampSynchronizer` (one image of every
camera, stamps within ``slop_ns``); of the complete sets it hands out those at least
``min_interval_ns`` after the last one handed out. ``hmocap calibrate --live`` feeds the sets
to a :class:`~hmocap_ros.calibration.session.CalibrationSession`; nothing here imports rclpy.
"""

from __future__ import annotations

import numpy as np

from hmocap_ros.stamp_sync import StampSynchronizer

__all__ = ["FrameSetCollector", "enough_views"]


class FrameSetCollector:
    """Groups ``(camera, stamp_ns, image)`` of cameras ``0 .. n_cameras - 1`` into complete
    frame sets, at most one per ``min_interval_ns``."""

    def __init__(self, n_cameras: int, slop_ns: int = 10_000_000, min_interval_ns: int = 0,
                 queue_size: int = 30):
        self.n_cameras = int(n_cameras)
        self.min_interval_ns = int(min_interval_ns)
        self._sync = StampSynchronizer(range(self.n_cameras), slop_ns=slop_ns, queue_size=queue_size)
        self._last_ns: int | None = None  # stamp of the last set handed out
        self.n_complete = 0  # sets completed
        self.n_skipped = 0  # complete sets left out by min_interval_ns

    @property
    def n_dropped(self) -> int:
        """Images in no complete set (a camera missed that frame, or they came late)."""
        return self._sync.stats.dropped_total

    def add(self, camera: int, stamp_ns: int, image) -> list:
        """Take one image; returns the frame sets it completes that are to be used,
        ``[(stamp_ns, [image per camera])]``."""
        if not 0 <= camera < self.n_cameras:
            raise ValueError(f"camera {camera} out of range 0..{self.n_cameras - 1}")
        out = []
        for synced in self._sync.add(camera, int(stamp_ns), image):
            self.n_complete += 1
            if self._last_ns is not None and synced.stamp_ns < self._last_ns + self.min_interval_ns:
                self.n_skipped += 1
                continue
            self._last_ns = synced.stamp_ns
            out.append((synced.stamp_ns, [synced.items[k] for k in range(self.n_cameras)]))
        return out


def enough_views(board_seen: np.ndarray, min_views: int) -> bool:
    """Whether every camera has seen the board in ``min_views`` images (``min_views`` 0: never)."""
    return min_views > 0 and len(board_seen) > 0 and int(np.min(board_seen)) >= min_views
