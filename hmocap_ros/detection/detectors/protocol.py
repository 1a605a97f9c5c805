"""What the extremity pipeline and the tracker ask an extremity detector:
:class:`ExtremityDetector`."""
from __future__ import annotations

from typing import Protocol, Sequence, runtime_checkable

import numpy as np

from hmocap_ros.detection.detections import Detections

__all__ = ["ExtremityDetector"]


@runtime_checkable
class ExtremityDetector(Protocol):
    """One rig's extremity detector (thesis sec. 2.5 admits any part detector).

    Built as ``cls(cameras, params, model_path)`` from the registry
    (:data:`hmocap_ros.detection.detectors.DETECTORS`): ``params`` the
    :class:`~hmocap_ros.detection.extremity_pipeline.ExtremityDetectionParams` (each detector
    reads its own group), ``model_path`` a network file or None.

    name: the ``detector`` parameter's value, written into its :class:`Detections`.
    description: one line for the docs. labelled: its detections carry the labels of one
    person's joints (``left_wrist``, ``head``, ...); else they are unlabelled candidates that
    each tracker assigns to its own body (eq. 2.19) and that every person's tracker receives.
    """

    name: str
    description: str
    labelled: bool

    def __init__(self, cameras: Sequence, params, model_path=None) -> None:
        """The detector of the rig ``cameras`` (see above)."""

    def detect(self, images: Sequence[np.ndarray | None], masks: Sequence[np.ndarray | None],
               previous: dict | None, stamp_ns: int | None = None,
               previous_stamp_ns: int | None = None) -> Detections:
        """The detections of one frame set: per camera an RGB image (H, W, 3) uint8 and a
        foreground mask (H, W) at the rig's resolution, either None where missing (the
        pipeline checked their sizes); ``previous`` the last skeleton, label -> (3,) room
        position, or None; ``stamp_ns`` and ``previous_stamp_ns`` the frame set's and the
        skeleton's stamps (None: unknown), for a detector that carries work between sets (a
        detector without these two parameters is called without them)."""

    def reset(self) -> None:
        """Forget what was carried from frame set to frame set (a recording that starts
        over)."""

    def close(self) -> None:
        """Release threads or files."""
