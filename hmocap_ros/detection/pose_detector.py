"""MediaPipe's pose detector on a whole view: where the person is, and the crop the landmark
network was trained on (no rclpy).

The first crop of a view's track (:mod:`.keypoint_detector`) comes from here, as in MediaPipe's
``PoseLandmarkCpu`` graph, whose later crops come from the landmarks themselves. The model,
``pose_detection.tflite`` (BlazePose detector, Apache-2.0, from the ``mediapipe==0.10.14``
wheel; ``hmocap_ros/data/models/SOURCES.md``), runs on LiteRT (:mod:`.tflite_model`). The pre-
and post-processing are those of ``mediapipe/modules/pose_detection/pose_detection_cpu.pbtxt``:

1. **Input** (``ImageToTensorCalculator``): the whole image letterboxed into 224 x 224
   (``keep_aspect_ratio``: the square of side ``max(W, H)`` about the image's centre, zero
   border), RGB as float32 in [-1, 1].
2. **Anchors** (``SsdAnchorsCalculator``, :func:`ssd_anchors`): 5 layers of strides 8, 16,
   32, 32, 32 on the 224 input, two anchors per cell (aspect ratio 1 and the interpolated
   scale), centres at ``(x + 0.5) / feature map size``, fixed size 1: 2254 anchors.
3. **Decoding** (``TensorsToDetectionsCalculator``, :func:`decode_detections`): per anchor
   12 values in x-first order (``reverse_output_order``): box centre x, y, width, height and 4
   keypoints (x, y), each divided by 224 and added to the anchor's centre (sizes: times the
   anchor's size, 1); score ``sigmoid(clip(raw, -100, 100))``, kept from 0.5 on.
4. **Weighted non-maximum suppression** (``NonMaxSuppressionCalculator``, ``WEIGHTED``, IoU
   threshold 0.3, :func:`weighted_nms`): the best-scored box and every box overlapping it by
   IoU > 0.3 form one detection whose box and keypoints are their score-weighted means, with
   the best score.
5. **Back to the image**: the letterbox's inverse.

Keypoint 0 is the hips' centre and keypoint 1 a point above the head whose distance from it is
half the side of the body's square: MediaPipe's ``pose_detection_to_roi.pbtxt`` makes the crop
from them (:func:`~.keypoint_roi.alignment_roi`: :meth:`PoseDetection.roi`).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from hmocap_ros.detection.keypoint_roi import ROI_SCALE, Roi, alignment_roi, crop_transform
from hmocap_ros.detection.tflite_model import MODEL_DIR, load_model

__all__ = ["DEFAULT_DETECTOR_MODEL", "DETECTOR_INPUT_SIZE", "PoseDetection", "PoseDetector",
           "decode_detections", "ssd_anchors", "weighted_nms"]

#: The shipped model (see ``hmocap_ros/data/models/SOURCES.md``).
DEFAULT_DETECTOR_MODEL = MODEL_DIR / "pose_detection.tflite"
#: Side of the square detector input, pixels.
DETECTOR_INPUT_SIZE = 224
_NUM_ANCHORS = 2254
_STRIDES = (8, 16, 32, 32, 32)
_MIN_SCALE, _MAX_SCALE = 0.1484375, 0.75
_SCORE_CLIP = 100.0
_NMS_IOU = 0.3
_GET_MODEL = ("it ships with hmocap_ros as hmocap_ros/data/models/pose_detection.tflite "
              "(see SOURCES.md there: mediapipe==0.10.14 wheel, "
              "mediapipe/modules/pose_detection/pose_detection.tflite)")


def ssd_anchors(size: int = DETECTOR_INPUT_SIZE, strides=_STRIDES) -> np.ndarray:
    """Anchor centres ``(N, 2)`` (x, y in [0, 1]) of MediaPipe's ``SsdAnchorsCalculator`` with
    the pose detector's options (module docstring, step 2): layers of equal stride are merged,
    two anchors per cell and layer (aspect ratio 1 and the interpolated scale), row-major cells."""
    out = []
    layer = 0
    while layer < len(strides):
        same = layer
        while same < len(strides) and strides[same] == strides[layer]:
            same += 1
        per_cell = 2 * (same - layer)
        cells = int(np.ceil(size / strides[layer]))
        y, x = np.mgrid[0:cells, 0:cells]
        centres = np.stack([(x + 0.5) / cells, (y + 0.5) / cells], axis=-1).reshape(-1, 1, 2)
        out.append(np.repeat(centres, per_cell, axis=1).reshape(-1, 2))
        layer = same
    return np.concatenate(out)


def decode_detections(raw: np.ndarray, logits: np.ndarray, anchors: np.ndarray,
                      size: int = DETECTOR_INPUT_SIZE, min_score: float = 0.5):
    """Step 3 of the module docstring: ``raw (N, 12)``, ``logits (N,)``, ``anchors (N, 2)`` ->
    ``scores (M,)``, boxes ``(M, 4)`` (x0, y0, x1, y1) and keypoints ``(M, 4, 2)``, in input
    pixels, of the anchors scoring ``min_score`` or more."""
    scores = 1.0 / (1.0 + np.exp(-np.clip(logits.astype(np.float64), -_SCORE_CLIP, _SCORE_CLIP)))
    keep = scores >= min_score
    raw, anchors = raw[keep].astype(np.float64), anchors[keep]
    centre = raw[:, 0:2] / size + anchors
    half = 0.5 * raw[:, 2:4] / size
    boxes = np.concatenate([centre - half, centre + half], axis=1) * size
    keypoints = (raw[:, 4:12].reshape(-1, 4, 2) / size + anchors[:, None, :]) * size
    return scores[keep], boxes, keypoints


def _iou(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    x0 = np.maximum(box[0], boxes[:, 0])
    y0 = np.maximum(box[1], boxes[:, 1])
    x1 = np.minimum(box[2], boxes[:, 2])
    y1 = np.minimum(box[3], boxes[:, 3])
    inter = np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None)
    area = lambda b: np.clip(b[..., 2] - b[..., 0], 0, None) * np.clip(b[..., 3] - b[..., 1], 0, None)  # noqa: E731 (one use)
    union = area(box) + area(boxes) - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def weighted_nms(scores: np.ndarray, boxes: np.ndarray, keypoints: np.ndarray,
                 iou_threshold: float = _NMS_IOU):
    """Step 4 of the module docstring: ``[(score, box (4,), keypoints (4, 2))]``, best first."""
    order = np.argsort(-scores, kind="stable")
    scores, boxes, keypoints = scores[order], boxes[order], keypoints[order]
    out = []
    remaining = np.arange(len(scores))
    while remaining.size:
        top = remaining[0]
        member = _iou(boxes[top], boxes[remaining]) > iou_threshold
        member[0] = True  # the best box, even when it has no area
        cluster = remaining[member]
        w = scores[cluster]
        out.append((float(scores[top]), (w @ boxes[cluster]) / w.sum(),
                    np.einsum("c,ckd->kd", w, keypoints[cluster]) / w.sum()))
        remaining = remaining[~member]
    return out


@dataclass(frozen=True, eq=False)
class PoseDetection:
    """One person found by the detector: score in [0, 1], box ``(4,)`` (x0, y0, x1, y1) and
    keypoints ``(4, 2)`` in image pixels (0: hips' centre, 1: the scale and rotation point
    above the head, 2: shoulders' centre, 3: the upper body's scale point)."""

    score: float
    box: np.ndarray
    keypoints: np.ndarray

    def roi(self, scale: float = ROI_SCALE) -> Roi | None:
        """The landmark network's crop (MediaPipe's ``pose_detection_to_roi``; ``scale``: the
        crop's side over the body circle's diameter)."""
        return alignment_roi(self.keypoints[0], self.keypoints[1], scale)


class PoseDetector:
    """The BlazePose detector on LiteRT (module docstring). Not thread-safe: one per thread.
    Raises :class:`~.tflite_model.ModelFileError` for a missing, corrupt or wrong model file."""

    def __init__(self, path: str | Path | None = None, threads: int = 1,
                 min_score: float = 0.5):
        self.path = Path(DEFAULT_DETECTOR_MODEL if path is None else path)
        n, size = _NUM_ANCHORS, DETECTOR_INPUT_SIZE
        self._model = load_model(self.path, "pose detection model",
                                 {"Identity": (1, n, 12), "Identity_1": (1, n, 1)},
                                 (1, size, size, 3), _GET_MODEL, threads)
        self.anchors = ssd_anchors()
        self.min_score = float(min_score)

    def detect(self, image_rgb: np.ndarray, roi: Roi | None = None) -> list[PoseDetection]:
        """The people in an RGB uint8 image ``(H, W, 3)``, best scored first; ``roi``: look
        in this square of the image only (default: the whole image, letterboxed), in image
        pixels all the same."""
        height, width = image_rgb.shape[:2]
        letterbox = roi if roi is not None else Roi(0.5 * width, 0.5 * height,
                                                    float(max(width, height)))
        matrix = crop_transform(letterbox, DETECTOR_INPUT_SIZE)
        size = DETECTOR_INPUT_SIZE
        tensor = cv2.warpAffine(image_rgb, matrix, (size, size), flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        blob = tensor[None].astype(np.float32) * np.float32(2.0 / 255.0) - np.float32(1.0)
        raw, logits = self._model.run(blob)
        scores, boxes, keypoints = decode_detections(raw[0], logits[0, :, 0], self.anchors,
                                                     size, self.min_score)
        inverse = np.linalg.inv(matrix[:, :2])
        to_image = lambda p: (p - matrix[:, 2]) @ inverse.T  # noqa: E731 (two uses below)
        out = []
        for score, box, points in weighted_nms(scores, boxes, keypoints):
            corners = to_image(box.reshape(2, 2))
            out.append(PoseDetection(score, corners.reshape(4), to_image(points)))
        return out
