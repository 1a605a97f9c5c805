"""The fields every registered tracking method shares (:class:`LayeredMethod`)."""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["LayeredMethod"]


@dataclass(frozen=True)
class LayeredMethod:
    """Name, label, summary and default budget of a method
    (:class:`~.protocol.TrackingMethod`); a subclass adds its :meth:`schedule`. By default
    the method takes no detections, and its particles per layer do not depend on sweeps."""

    name: str
    label: str
    summary: str
    layers: int
    particles: int
    uses_detector: bool = False
    keypoint_first: bool = False

    @property
    def evaluations(self) -> int:
        return self.layers * self.particles

    def layer_particles(self, sweeps: int) -> int:
        return self.particles

    def detection_driver(self, model, layer_blocks: tuple):
        return None
