"""KF-HPF: the body fitted to the labelled keypoints is the filter's centre, a boxed layer
only for the blocks they leave uncertain (:mod:`hmocap_ros.tracking.keypoint_first`)."""
from __future__ import annotations

from dataclasses import dataclass

from hmocap_ros.tracking.methods.hpf import HierarchicalMethod

__all__ = ["KeypointFirstMethod"]


@dataclass(frozen=True)
class KeypointFirstMethod(HierarchicalMethod):
    """Keypoint-first tracking; its schedule is hpf-apo's, which a frame set without
    keypoints runs."""

    boxed: bool = True
    uses_detector: bool = True
    keypoint_first: bool = True
