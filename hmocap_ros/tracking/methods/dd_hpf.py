"""DD-HPF+: hpf-apo driven by detections (thesis sec. 2.5): IK particles from the detected
hands, the joints' detection terms and the refinement layer (eq. 2.20-2.21)."""
from __future__ import annotations

from dataclasses import dataclass

from hmocap_ros.tracking.detector_driven import DetectorDriven
from hmocap_ros.tracking.methods.hpf import HierarchicalMethod

__all__ = ["DetectorDrivenMethod"]


@dataclass(frozen=True)
class DetectorDrivenMethod(HierarchicalMethod):
    """The boxed hierarchical schedule whose detections drive propagation through a
    :class:`~hmocap_ros.tracking.detector_driven.DetectorDriven`; without detections a
    frame runs as the boxed schedule."""

    boxed: bool = True
    uses_detector: bool = True

    def detection_driver(self, model, layer_blocks: tuple) -> DetectorDriven:
        return DetectorDriven(model, layer_blocks)
