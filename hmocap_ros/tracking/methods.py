"""The tracking methods of thesis ch. 2 as strategy objects in one registry.

Each :class:`TrackingMethod` says what its layer schedule is built from and what it needs,
so that the tracker, the node and the evaluator ask it instead of comparing names:

==========  =========  ==============================================  =======================
name        label      layers (one sweep; :mod:`.body_layers`)         needs
==========  =========  ==============================================  =======================
apf         APF        14 annealing layers over all DoFs (alg. 2)      silhouettes
hpf         HPF        7 layers along the kinematic tree (sec. 2.4.1)  silhouettes
hpf-apo     HPF+APO    the 7 layers weighed in their parts' boxes      silhouettes
                       (eq. 2.15) plus a whole-body final layer
dd-hpf      DD-HPF+    hpf-apo with IK particles from detected hands,  silhouettes and
                       joint terms and the refinement layer            3D detections
                       (eq. 2.20-2.21)
kf-hpf      KF-HPF     the body fitted to the labelled keypoints is    silhouettes and
                       the filter's centre; a boxed layer only for     labelled 3D keypoints
                       the blocks they leave uncertain
                       (:mod:`.keypoint_first`)
==========  =========  ==============================================  =======================

The thesis' four run at about 3,500 weight evaluations per frame by default, the budget of
its comparison (sec. 2.4.2: APF 14 x 250 against HPF 7 x 500); ``kf-hpf`` spends that
budget's layers only on the blocks its keypoints leave uncertain, and runs ``hpf-apo``'s
schedule on a frame set without keypoints.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["METHODS", "TrackingMethod", "get_method", "method_names"]


@dataclass(frozen=True)
class TrackingMethod:
    """One layered-filter method.

    name: the parameter value (``method``); label: the thesis' name, for tables.
    hierarchical: layers along the kinematic tree (alg. 3, sec. 2.4.1) rather than annealing
        layers over all DoFs (alg. 2).
    boxed: each hierarchical layer weighs inside the observation boxes of its body parts
        (approximate partitioning of observations, eq. 2.15).
    uses_detector: the tracker takes the extremity detector's 3D detections, draws IK
        particles for the arms, weighs labelled joints in every layer and makes the final
        layer the refinement layer (sec. 2.5); without detections it runs as its boxed
        schedule.
    keypoint_first: the filter is centred on the body fitted to the labelled keypoints and
        filters only what they leave uncertain (:mod:`.keypoint_first`); the tracker starts
        from the keypoints, without the silhouette start-up.
    layers, particles: the default budget of one sweep (layers x particles weight
        evaluations per frame).
    """

    name: str
    label: str
    hierarchical: bool
    boxed: bool
    uses_detector: bool
    layers: int
    particles: int
    summary: str
    keypoint_first: bool = False

    @property
    def evaluations(self) -> int:
        return self.layers * self.particles


METHODS: dict[str, TrackingMethod] = {m.name: m for m in (
    TrackingMethod("apf", "APF", hierarchical=False, boxed=False, uses_detector=False,
                   layers=14, particles=250,
                   summary="annealed particle filter over all DoFs (alg. 2)"),
    TrackingMethod("hpf", "HPF", hierarchical=True, boxed=False, uses_detector=False,
                   layers=7, particles=500,
                   summary="hierarchical, one layer per body part (sec. 2.4.1)"),
    TrackingMethod("hpf-apo", "HPF+APO", hierarchical=True, boxed=True, uses_detector=False,
                   layers=8, particles=438,
                   summary="hierarchical with approximate partitioning of observations "
                           "(eq. 2.15)"),
    TrackingMethod("dd-hpf", "DD-HPF+", hierarchical=True, boxed=True, uses_detector=True,
                   layers=8, particles=438,
                   summary="hpf-apo driven by hand detections: IK particles and the "
                           "refinement layer (sec. 2.5)"),
    TrackingMethod("kf-hpf", "KF-HPF", hierarchical=True, boxed=True, uses_detector=True,
                   layers=8, particles=438, keypoint_first=True,
                   summary="the body fitted to the labelled keypoints, the layered filter "
                           "around it where they leave it uncertain"),
)}


def method_names() -> tuple[str, ...]:
    """The registered method names, in the thesis' order."""
    return tuple(METHODS)


def get_method(method: str | TrackingMethod) -> TrackingMethod:
    """The registered method of that name (a method passes through); ValueError otherwise."""
    if isinstance(method, TrackingMethod):
        return method
    try:
        return METHODS[method]
    except KeyError:
        raise ValueError(f"method must be one of {method_names()}, got {method!r}") from None
