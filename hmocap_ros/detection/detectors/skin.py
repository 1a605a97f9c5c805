"""The thesis' extremity detector (sec. 2.5.1, eq. 2.16-2.18): skin colour fused on the
carved hull's oriented surface, the candidates labelled against the last skeleton by eq. 2.19."""
from __future__ import annotations

import numpy as np

from hmocap_ros.detection.detections import UNKNOWN, Detections
from hmocap_ros.detection.greedy_assignment import classify
from hmocap_ros.detection.skin import skin_probability
from hmocap_ros.detection.skin_extremities import SkinExtremityDetector

__all__ = ["SKIN_TARGETS", "SkinDetector", "skin_targets"]

#: skin labelling against the last skeleton: label, [Upsilon] (m) eq. 2.19
SKIN_TARGETS = (("left_hand", 0.35), ("right_hand", 0.35), ("head", 0.25))


def skin_targets(previous: dict) -> np.ndarray | None:
    """(3, 3) left hand, right hand, head of the last skeleton for labelling skin candidates:
    a hand 9 cm beyond the wrist along the forearm, the head 10 cm above the head joint."""
    need = ("left_elbow", "left_wrist", "right_elbow", "right_wrist", "head")
    if not all(k in previous for k in need):
        return None
    out = []
    for side in ("left", "right"):
        wrist, elbow = previous[f"{side}_wrist"], previous[f"{side}_elbow"]
        arm = wrist - elbow
        out.append(wrist + 0.09 * arm / max(float(np.linalg.norm(arm)), 1e-6))
    out.append(previous["head"] + np.array([0.0, 0.10, 0.0]))
    return np.array(out)


class SkinDetector:
    """The skin probability of each view inside its foreground
    (:mod:`hmocap_ros.detection.skin`) fused on the oriented surface of the carved hull
    (:mod:`hmocap_ros.detection.skin_extremities`); the candidates are labelled by eq. 2.19
    against the last skeleton when one is given, else ``unknown`` (the tracker assigns them
    to its own predicted pose anyway). Settings: ``params.skin``."""

    name = "skin"
    description = "skin colour fused on the hull's oriented surface (thesis eq. 2.16-2.18)"
    labelled = False

    def __init__(self, cameras, params, model_path=None):
        self.fusion = SkinExtremityDetector(tuple(cameras), params.skin)

    def reset(self) -> None:
        pass

    def close(self) -> None:
        pass

    def detect(self, images, masks, previous=None, stamp_ns=None,
               previous_stamp_ns=None) -> Detections:
        maps = [skin_probability(img, mask=m) if img is not None and m is not None else None
                for img, m in zip(images, masks)]
        joints = (np.array(list(previous.values())) if previous else None)
        cand = self.fusion.detect(masks, maps, joints)
        labels = [UNKNOWN] * len(cand.positions)
        targets = skin_targets(previous) if previous else None
        if targets is not None and len(cand.positions):
            upsilon = [u for _, u in SKIN_TARGETS]
            assigned = classify(cand.positions, targets, upsilon)
            for (label, _), pos in zip(SKIN_TARGETS, assigned):
                if np.isfinite(pos).all():
                    labels[int(np.argmin(np.linalg.norm(cand.positions - pos, axis=1)))] = label
        return Detections(self.name, tuple(labels), cand.positions, cand.scores, cand.normals,
                          cand.surface, cand.probability)
