"""Extremity detection of one frame set: images and foregrounds of the rig in, 3D detections out.

The ``extremity_detection`` node, the evaluator (``hmocap eval extremities``) and the tracker's
evaluation (``hmocap eval mocap``) call :meth:`ExtremityPipeline.detect` the same way. Two
detectors, registered in :data:`DETECTORS` and chosen by ``detector``:

``skin``
    the thesis' own (sec. 2.5.1, eq. 2.16-2.18): the skin probability of each view inside its
    foreground (:mod:`hmocap_ros.detection.skin`) fused on the oriented surface of the
    carved hull (:mod:`.skin_extremities`); the candidates are labelled by eq. 2.19 against the
    last skeleton when one is given, else ``unknown`` (the tracker assigns them to its own
    predicted pose anyway).
``keypoints``
    a 2D landmark network per view on the crop MediaPipe's pipeline gives it (from the view's
    previous landmarks, the previous skeleton or a pose detector), triangulated robustly over
    the views (:mod:`.keypoint_detector`): labelled head, hands, feet and the limb joints with
    confidences (beyond the thesis, whose sec. 2.5 admits any part detector). Each view keeps
    a track from frame set to frame set: :meth:`ExtremityPipeline.reset` drops them.

``previous``: the last skeleton, label -> (3,) room position (``head``, ``left_wrist``, ...;
:func:`skeleton_labels` makes it from the body model's joints), optional for both.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from hmocap_ros.detection.detections import MODEL_JOINT, UNKNOWN, Detections
from hmocap_ros.detection.greedy_assignment import classify
from hmocap_ros.detection.keypoint_detector import KeypointDetector
from hmocap_ros.detection.params import KeypointParams
from hmocap_ros.detection.skin import skin_probability
from hmocap_ros.detection.skin_extremities import SkinExtremityDetector, SkinExtremityParams
from hmocap_ros.params import group, param

__all__ = ["DETECTORS", "ExtremityDetectionParams", "ExtremityPipeline", "skeleton_labels"]

log = logging.getLogger(__name__)

#: detector name -> what it is
DETECTORS = {
    "skin": "skin colour fused on the hull's oriented surface (thesis eq. 2.16-2.18)",
    "keypoints": "BlazePose landmarks per view, triangulated over the views",
}
#: skin labelling against the last skeleton: label, [Upsilon] (m) eq. 2.19
_SKIN_TARGETS = (("left_hand", 0.35), ("right_hand", 0.35), ("head", 0.25))


@dataclass(frozen=True)
class ExtremityDetectionParams:
    """Settings of the extremity detection (node parameters by dotted name)."""

    detector: str = param("keypoints", "Detector: 'keypoints' (a 2D landmark network per view, "
                                       "triangulated) or 'skin' (skin colour on the hull's "
                                       "surface, thesis eq. 2.16-2.18).")
    skin: SkinExtremityParams = group(SkinExtremityParams, "the skin detector")
    keypoints: KeypointParams = group(KeypointParams, "the keypoint detector")

    def __post_init__(self):
        if self.detector not in DETECTORS:
            raise ValueError(f"detector must be one of {tuple(DETECTORS)}, got {self.detector!r}")


def skeleton_labels(joint_names: Sequence[str], joints: np.ndarray) -> dict:
    """label -> (3,) position of a skeleton given by the body model's joints (the message
    labels of :data:`~.detections.MODEL_JOINT`, ``head`` from the model's head joint)."""
    index = {str(n): i for i, n in enumerate(joint_names)}
    out = {label: joints[index[j]] for label, j in MODEL_JOINT.items() if j in index}
    if "head" in index:
        out["head"] = joints[index["head"]]
    return {k: np.asarray(v, float) for k, v in out.items() if np.isfinite(v).all()}


def _skin_targets(previous: dict) -> np.ndarray | None:
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


class ExtremityPipeline:
    """One rig's extremity detection (module docstring). ``model_path``: the keypoint
    network's file (default: the shipped one); a missing or corrupt file (or pose detector
    file) raises :class:`~.tflite_model.ModelFileError` here, not on the first frame."""

    def __init__(self, cameras: Sequence, params: ExtremityDetectionParams | None = None,
                 model_path=None):
        self.cameras = tuple(cameras)
        self.params = p = params or ExtremityDetectionParams()
        self.skin = SkinExtremityDetector(self.cameras, p.skin) if p.detector == "skin" else None
        self.keypoints = (KeypointDetector(self.cameras, p.keypoints, model_path)
                          if p.detector == "keypoints" else None)
        self.last_seconds = 0.0

    def reset(self) -> None:
        """Forget the views' tracks (a recording that starts over)."""
        if self.keypoints is not None:
            self.keypoints.reset()

    def close(self) -> None:
        """Stop the keypoint detector's worker threads."""
        if self.keypoints is not None:
            self.keypoints.close()

    def detect(self, images: Sequence[np.ndarray | None], masks: Sequence[np.ndarray | None],
               previous: dict | None = None) -> Detections:
        """Detections of one frame set: per camera an RGB image (H, W, 3) uint8 and a
        foreground mask (H, W) at the rig's resolution, either None where missing."""
        t0 = time.perf_counter()
        if len(images) != len(self.cameras) or len(masks) != len(self.cameras):
            raise ValueError(f"expected {len(self.cameras)} images and masks, got "
                             f"{len(images)} and {len(masks)}")
        images, masks = _checked(self.cameras, images, masks)
        if self.keypoints is not None:
            out = self._keypoints(images, masks, previous)
        else:
            out = self._skin(images, masks, previous)
        self.last_seconds = time.perf_counter() - t0
        return out

    def _keypoints(self, images, masks, previous) -> Detections:
        kp = self.keypoints.detect(images, masks, previous)
        return Detections("keypoints", tuple(kp.labels), kp.positions, kp.scores)

    def _skin(self, images, masks, previous) -> Detections:
        maps = [skin_probability(img, mask=m) if img is not None and m is not None else None
                for img, m in zip(images, masks)]
        joints = (np.array(list(previous.values())) if previous else None)
        cand = self.skin.detect(masks, maps, joints)
        labels = [UNKNOWN] * len(cand.positions)
        targets = _skin_targets(previous) if previous else None
        if targets is not None and len(cand.positions):
            upsilon = [u for _, u in _SKIN_TARGETS]
            assigned = classify(cand.positions, targets, upsilon)
            for (label, _), pos in zip(_SKIN_TARGETS, assigned):
                if np.isfinite(pos).all():
                    labels[int(np.argmin(np.linalg.norm(cand.positions - pos, axis=1)))] = label
        return Detections("skin", tuple(labels), cand.positions, cand.scores, cand.normals,
                          cand.surface, cand.probability)


def _checked(cameras, images, masks) -> tuple[list, list]:
    """Images and masks with the ones of the wrong size or type set to None (logged)."""
    out_i, out_m = [], []
    for cam, img, m in zip(cameras, images, masks):
        if img is not None and (img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8
                                or img.shape[:2] != (cam.height, cam.width)):
            log.error("%s: image %s %s, the rig says %dx%d rgb8: view left out", cam.name,
                      img.shape, img.dtype, cam.width, cam.height)
            img = None
        if m is not None and m.shape[:2] != (cam.height, cam.width):
            log.error("%s: foreground %s, the rig says %dx%d: view left out", cam.name,
                      m.shape, cam.width, cam.height)
            m = None
        out_i.append(img)
        out_m.append(m)
    return out_i, out_m
