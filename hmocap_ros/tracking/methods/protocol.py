"""What the body tracker asks a tracking method: :class:`TrackingMethod`.

A method is an object with these members, registered by name in
:data:`hmocap_ros.tracking.methods.METHODS`. The tracker asks it for its layer schedule
(alg. 5: which DoFs each layer filters, with how many particles, and whether a layer weighs
inside its parts' observation boxes, eq. 2.15, or over the whole images, eq. 2.8), whether it
takes the extremity detector's detections, and what makes them drive propagation (sec. 2.5).
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["TrackingMethod"]


@runtime_checkable
class TrackingMethod(Protocol):
    """One layered-filter method.

    name: the parameter value (``method``); label: the thesis' name, for tables; summary:
    one line for ``--help`` and the docs. layers, particles: the default budget of one
    sweep (layers x particles weight evaluations per frame, :attr:`evaluations`).
    uses_detector: the tracker takes the extremity detector's 3D detections (the node
    subscribes to them, the evaluator runs the detector). keypoint_first: the filter is
    centred on the body fitted to the labelled keypoints and filters only what they leave
    uncertain (:mod:`hmocap_ros.tracking.keypoint_first`); the tracker starts from the
    keypoints. The members are read-only (the registered methods are frozen dataclasses).
    """

    @property
    def name(self) -> str: ...

    @property
    def label(self) -> str: ...

    @property
    def summary(self) -> str: ...

    @property
    def layers(self) -> int: ...

    @property
    def particles(self) -> int: ...

    @property
    def uses_detector(self) -> bool: ...

    @property
    def keypoint_first(self) -> bool: ...

    @property
    def evaluations(self) -> int:
        """Weight evaluations per frame of the default budget."""

    def layer_particles(self, sweeps: int) -> int:
        """Particles per layer of the default budget when the schedule makes ``sweeps``
        passes over the body's blocks (the same evaluations per frame)."""

    def schedule(self, skel, n_particles: int, n_layers: int | None, sigma0: np.ndarray,
                 kernel, *, survival_rate: float, apf_alpha: float, refine_nu: float,
                 sweeps: int):
        """The :class:`~hmocap_ros.tracking.body_layers.BodySchedule` of this method:
        ``sigma0`` the per-DoF inter-frame std, ``kernel`` the diffusion kernel within the
        joint limits; ``n_layers`` None gives the method's own."""

    def detection_driver(self, model, layer_blocks: tuple):
        """What makes the detections drive propagation (IK particles, detection terms of
        the layers; :class:`~hmocap_ros.tracking.detector_driven.DetectorDriven`), or None
        when this method's filter does not take them that way."""
