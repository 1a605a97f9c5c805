"""Extremity detection of one frame set: images and foregrounds of the rig in, 3D detections out.

The ``extremity_detection`` node, the evaluator (``hmocap eval extremities``) and the tracker's
evaluation (``hmocap eval mocap``) call :meth:`ExtremityPipeline.detect` the same way. The
detector is the one :data:`~.detectors.DETECTORS` registers under ``detector``
(:mod:`.detectors`): ``skin``, the thesis' own (sec. 2.5.1, eq. 2.16-2.18, skin colour on the
carved hull's oriented surface, unlabelled candidates), or ``keypoints``, a 2D landmark
network per view triangulated over the views (labelled joints with confidences). The pipeline
checks the images' and masks' sizes and times the detector.

``previous``: the last skeleton, label -> (3,) room position (``head``, ``left_wrist``, ...;
:func:`skeleton_labels` makes it from the body model's joints), optional for both.
"""
from __future__ import annotations

import inspect
import logging
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from hmocap_ros.detection.detections import MODEL_JOINT, Detections
from hmocap_ros.detection.detectors import DETECTORS, ExtremityDetector, get_detector
from hmocap_ros.detection.params import KeypointParams
from hmocap_ros.detection.skin_extremities import SkinExtremityParams
from hmocap_ros.params import group, param

__all__ = ["DETECTORS", "ExtremityDetectionParams", "ExtremityPipeline", "skeleton_labels"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ExtremityDetectionParams:
    """Settings of the extremity detection (node parameters by dotted name)."""

    detector: str = param("keypoints", "Detector: 'keypoints' (a 2D landmark network per view, "
                                       "triangulated) or 'skin' (skin colour on the hull's "
                                       "surface, thesis eq. 2.16-2.18).")
    skin: SkinExtremityParams = group(SkinExtremityParams, "the skin detector")
    keypoints: KeypointParams = group(KeypointParams, "the keypoint detector")

    def __post_init__(self):
        get_detector(self.detector)  # ValueError naming the registered ones


def skeleton_labels(joint_names: Sequence[str], joints: np.ndarray) -> dict:
    """label -> (3,) position of a skeleton given by the body model's joints (the message
    labels of :data:`~.detections.MODEL_JOINT`, ``head`` from the model's head joint)."""
    index = {str(n): i for i, n in enumerate(joint_names)}
    out = {label: joints[index[j]] for label, j in MODEL_JOINT.items() if j in index}
    if "head" in index:
        out["head"] = joints[index["head"]]
    return {k: np.asarray(v, float) for k, v in out.items() if np.isfinite(v).all()}


class ExtremityPipeline:
    """One rig's extremity detection (module docstring). ``model_path``: the keypoint
    network's file (default: the shipped one); a missing or corrupt file (or pose detector
    file) raises :class:`~.tflite_model.ModelFileError` here, not on the first frame."""

    def __init__(self, cameras: Sequence, params: ExtremityDetectionParams | None = None,
                 model_path=None):
        self.cameras = tuple(cameras)
        self.params = p = params or ExtremityDetectionParams()
        #: the registered detector ``detector`` names (:mod:`.detectors`)
        self.detector: ExtremityDetector = get_detector(p.detector)(self.cameras, p,
                                                                    model_path)
        # a detector whose detect() takes no stamps (they are optional in the protocol)
        self._takes_stamps = "stamp_ns" in inspect.signature(self.detector.detect).parameters
        self.last_seconds = 0.0

    def report_other_stages(self, seconds: float) -> None:
        """A frame set's seconds outside the detection (segmentation, tracking) in the same
        process, for a detector that sizes its work to a rate (the keypoint detector's
        ``pose_rate_hz``); the others ignore it."""
        report = getattr(self.detector, "report_other_stages", None)
        if report is not None:
            report(seconds)

    def reset(self) -> None:
        """Forget the detector's tracks (a recording that starts over)."""
        self.detector.reset()

    def close(self) -> None:
        """Stop the detector's worker threads."""
        self.detector.close()

    def detect(self, images: Sequence[np.ndarray | None], masks: Sequence[np.ndarray | None],
               previous: dict | None = None, stamp_ns: int | None = None,
               previous_stamp_ns: int | None = None) -> Detections:
        """Detections of one frame set: per camera an RGB image (H, W, 3) uint8 and a
        foreground mask (H, W) at the rig's resolution, either None where missing;
        ``stamp_ns`` the frame set's stamp and ``previous_stamp_ns`` the skeleton's (the
        keypoint detector's views in rotation need both)."""
        t0 = time.perf_counter()
        if len(images) != len(self.cameras) or len(masks) != len(self.cameras):
            raise ValueError(f"expected {len(self.cameras)} images and masks, got "
                             f"{len(images)} and {len(masks)}")
        images, masks = _checked(self.cameras, images, masks)
        if self._takes_stamps:
            out = self.detector.detect(images, masks, previous, stamp_ns=stamp_ns,
                                       previous_stamp_ns=previous_stamp_ns)
        else:
            out = self.detector.detect(images, masks, previous)
        self.last_seconds = time.perf_counter() - t0
        return out


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
