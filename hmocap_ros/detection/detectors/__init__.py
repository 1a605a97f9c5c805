"""The extremity detectors, registered by name in :data:`DETECTORS`.

Each is a class implementing :class:`~.protocol.ExtremityDetector` (one file each in this
folder); the ``detector`` parameter names one. The pipeline
(:class:`~hmocap_ros.detection.extremity_pipeline.ExtremityPipeline`) builds it and calls
its ``detect``; the tracker asks :func:`carries_labels` of the detections it receives. A new
detector is one file here with its class and one line in :data:`DETECTORS`
(docs/development.md, "Adding an extremity detector").
"""
from __future__ import annotations

from hmocap_ros.detection.detections import Detections
from hmocap_ros.detection.detectors.keypoints import KeypointsDetector
from hmocap_ros.detection.detectors.protocol import ExtremityDetector
from hmocap_ros.detection.detectors.skin import SkinDetector

__all__ = ["DETECTORS", "ExtremityDetector", "carries_labels", "detector_names",
           "get_detector"]

#: detector name (the ``detector`` parameter) -> its class
DETECTORS: dict[str, type[ExtremityDetector]] = {cls.name: cls for cls in (
    SkinDetector,
    KeypointsDetector,
)}


def detector_names() -> tuple[str, ...]:
    """The registered detector names."""
    return tuple(DETECTORS)


def get_detector(name: str) -> type[ExtremityDetector]:
    """The registered detector class of that name; ValueError otherwise."""
    try:
        return DETECTORS[name]
    except KeyError:
        raise ValueError(f"detector must be one of {detector_names()}, got {name!r}") from None


def carries_labels(detections: Detections) -> bool:
    """Whether ``detections`` carry one person's joint labels (its detector's ``labelled``);
    detections of a detector this process does not know (another node's) are taken as
    labelled, as every detector but the skin one makes them."""
    cls = DETECTORS.get(detections.detector)
    return True if cls is None else bool(cls.labelled)
