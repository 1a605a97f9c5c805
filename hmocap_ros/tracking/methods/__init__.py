"""The tracking methods of thesis ch. 2, registered by name in :data:`METHODS`.

Each is an object implementing :class:`~.protocol.TrackingMethod` (one file each in this
folder): it builds its layer schedule and says what it needs, so that the tracker, the node and
the evaluator ask it instead of comparing names:

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

A new method is one file here with its class and one line in :data:`METHODS`
(docs/development.md, "Adding a tracking method").
"""
from __future__ import annotations

from hmocap_ros.tracking.methods.apf import AnnealedMethod
from hmocap_ros.tracking.methods.dd_hpf import DetectorDrivenMethod
from hmocap_ros.tracking.methods.hpf import HierarchicalMethod
from hmocap_ros.tracking.methods.kf_hpf import KeypointFirstMethod
from hmocap_ros.tracking.methods.protocol import TrackingMethod

__all__ = ["METHODS", "TrackingMethod", "get_method", "method_names"]

_HPF_APO_SUMMARY = "hierarchical with approximate partitioning of observations (eq. 2.15)"

#: method name (the ``method`` parameter) -> the method, in the thesis' order
METHODS: dict[str, TrackingMethod] = {m.name: m for m in (
    AnnealedMethod("apf", "APF", "annealed particle filter over all DoFs (alg. 2)", 14, 250),
    HierarchicalMethod("hpf", "HPF", "hierarchical, one layer per body part (sec. 2.4.1)",
                       7, 500),
    HierarchicalMethod("hpf-apo", "HPF+APO", _HPF_APO_SUMMARY, 8, 438, boxed=True),
    DetectorDrivenMethod("dd-hpf", "DD-HPF+", "hpf-apo driven by hand detections: IK "
                         "particles and the refinement layer (sec. 2.5)", 8, 438),
    KeypointFirstMethod("kf-hpf", "KF-HPF", "the body fitted to the labelled keypoints, the "
                        "layered filter around it where they leave it uncertain", 8, 438),
)}


def method_names() -> tuple[str, ...]:
    """The registered method names, in the thesis' order."""
    return tuple(METHODS)


def get_method(method: str | TrackingMethod) -> TrackingMethod:
    """The registered method of that name (a method object passes through); ValueError
    otherwise."""
    if not isinstance(method, str):
        return method
    try:
        return METHODS[method]
    except KeyError:
        raise ValueError(f"method must be one of {method_names()}, got {method!r}") from None
