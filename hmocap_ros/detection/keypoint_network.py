"""The 2D body-landmark network of one view: BlazePose GHUM 3D ("Pose landmark full", MediaPipe),
run with LiteRT (XNNPACK) on a square crop of the person.

Method: the pre- and post-processing of MediaPipe's ``PoseLandmarkByRoiCpu`` graph
(``mediapipe==0.10.14``):

1. **Crop**: the caller's :class:`~.keypoint_roi.Roi` (a square in image pixels, turned about
   its centre) mapped onto the 256 x 256 network input by one affine warp (bilinear,
   replicated border where the square leaves the image, as MediaPipe's
   ``ImageToTensorCalculator``): :func:`~.keypoint_roi.crop_transform`.
2. **Input**: RGB as float32 in [0, 1] (the model's training range, MediaPipe's
   ``output_tensor_float_range {min: 0, max: 1}``), NHWC 1 x 256 x 256 x 3.
3. **Outputs**: ``Identity`` (39 x [x, y, z, visibility, presence], x and y in input pixels,
   visibility and presence as logits: a sigmoid gives [0, 1]), ``Identity_1`` (the pose
   presence score, already in [0, 1]) and ``Identity_3`` (39 heatmaps of 64 x 64, logits);
   with ``segmentation=True`` also ``Identity_2``, the person's segmentation over the crop
   (256 x 256 logits; MediaPipe's ``segmentation_mask`` after a sigmoid), which
   :meth:`PoseLandmarkNetwork.segment` maps back onto the image.
4. **Heatmap refinement** (MediaPipe's ``RefineLandmarksFromHeatmapCalculator``, kernel 7):
   each landmark's x, y becomes the sigmoid(heatmap)-weighted mean of the 7 x 7 heatmap cells
   around it, where the window's largest weight reaches 0.5.
5. **Back to the image**: the inverse of the crop's affine map.

The first 33 landmarks are BlazePose's (:data:`LANDMARK_NAMES`); 33 and 34 are the auxiliary
points MediaPipe aligns its next crop with (hip centre, and a point whose distance from it is
half the side of the body's square box: :func:`~.keypoint_roi.landmarks_roi`).

Runtime: LiteRT (``ai-edge-litert``) with XNNPACK, ``threads`` threads per network
(:mod:`.tflite_model`) rather than OpenCV's dnn module: it is the faster of the two
(docs/tracking.md, sec. 2.4, "Runtime", made by ``benchmarks/bench_keypoints.py``), and it does
not depend on OpenCV's version.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from hmocap_ros.detection.keypoint_roi import Roi, crop_transform
from hmocap_ros.detection.tflite_model import MODEL_DIR, ModelFileError, load_model

__all__ = ["ModelFileError", "DEFAULT_MODEL", "INPUT_SIZE", "NUM_LANDMARKS", "LANDMARK_NAMES",
           "PoseLandmarkNetwork", "ViewLandmarks", "refine_from_heatmap"]

#: The shipped model (see ``hmocap_ros/data/models/SOURCES.md``).
DEFAULT_MODEL = MODEL_DIR / "pose_landmark_full.tflite"
#: Side of the square network input, pixels.
INPUT_SIZE = 256
#: Landmarks the network outputs (33 BlazePose landmarks and 6 auxiliary points).
NUM_LANDMARKS = 39
#: Names of the 33 BlazePose landmarks, in output order (the subject's left and right).
LANDMARK_NAMES = (
    "nose", "left_eye_inner", "left_eye", "left_eye_outer", "right_eye_inner", "right_eye",
    "right_eye_outer", "left_ear", "right_ear", "mouth_left", "mouth_right", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_pinky",
    "right_pinky", "left_index", "right_index", "left_thumb", "right_thumb", "left_hip",
    "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle", "left_heel",
    "right_heel", "left_foot_index", "right_foot_index",
)
#: the outputs used, with their shapes (NHWC heatmaps)
_OUTPUTS = {"Identity": (1, NUM_LANDMARKS * 5), "Identity_1": (1, 1),
            "Identity_3": (1, 64, 64, NUM_LANDMARKS)}
#: the person segmentation over the crop (logits), read with ``segmentation=True``
_SEGMENTATION_OUTPUT = {"Identity_2": (1, INPUT_SIZE, INPUT_SIZE, 1)}
_HEATMAP_KERNEL = 7
_HEATMAP_MIN_CONFIDENCE = 0.5
_GET_MODEL = ("it ships with hmocap_ros as hmocap_ros/data/models/pose_landmark_full.tflite "
              "(see SOURCES.md there: mediapipe==0.10.14 wheel, "
              "mediapipe/modules/pose_landmark/pose_landmark_full.tflite)")


@dataclass(frozen=True, eq=False)
class ViewLandmarks:
    """The network's landmarks in one view.

    xy: (39, 2) full-image pixels (distorted image, OpenCV pixel centres); visibility and
    presence: (39,) in [0, 1] (the network's sigmoid outputs: visible in the image, and inside
    the crop); score: the pose presence score in [0, 1].
    """

    xy: np.ndarray
    visibility: np.ndarray
    presence: np.ndarray
    score: float


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-np.clip(x, -60.0, 60.0)))


def refine_from_heatmap(xy: np.ndarray, heatmaps: np.ndarray,
                        kernel: int = _HEATMAP_KERNEL,
                        min_confidence: float = _HEATMAP_MIN_CONFIDENCE) -> np.ndarray:
    """Landmarks ``(L, 2)`` (input pixels) refined on heatmaps ``(L, h, w)`` of logits.

    Per landmark, the cell it falls in (truncated like MediaPipe's integer conversion) is the
    centre of a ``kernel`` x ``kernel`` window (clipped to the map); where the window's largest
    sigmoid reaches ``min_confidence`` the landmark becomes the sigmoid-weighted mean of the
    window's cell indices, scaled back to input pixels (cell ``c`` -> ``c * 256 / w``). Landmarks
    outside the map are kept.
    """
    n, h, w = heatmaps.shape
    col = np.trunc(xy[:, 0] * w / INPUT_SIZE)
    row = np.trunc(xy[:, 1] * h / INPUT_SIZE)
    inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    offsets = np.arange(kernel) - (kernel - 1) // 2
    cols = col[:, None] + offsets[None, :]  # (L, k)
    rows = row[:, None] + offsets[None, :]
    col_ok = (cols >= 0) & (cols < w)
    row_ok = (rows >= 0) & (rows < h)
    ci = np.clip(cols, 0, w - 1).astype(np.intp)
    ri = np.clip(rows, 0, h - 1).astype(np.intp)
    weights = _sigmoid(heatmaps[np.arange(n)[:, None, None], ri[:, :, None], ci[:, None, :]])
    weights = weights * (row_ok[:, :, None] & col_ok[:, None, :])  # (L, k, k)
    total = weights.sum(axis=(1, 2))
    refine = inside & (weights.max(axis=(1, 2)) >= min_confidence) & (total > 0)
    safe = np.where(total > 0, total, 1.0)
    mean_col = np.einsum("lij,lj->l", weights, cols) / safe
    mean_row = np.einsum("lij,li->l", weights, rows) / safe
    out = np.array(xy, dtype=np.float64, copy=True)
    out[refine, 0] = mean_col[refine] * INPUT_SIZE / w
    out[refine, 1] = mean_row[refine] * INPUT_SIZE / h
    return out


class PoseLandmarkNetwork:
    """BlazePose "Pose landmark full" on LiteRT (see the module docstring).

    Not thread-safe: give each thread its own instance. ``threads``: LiteRT threads of this
    instance; ``segmentation``: also read the person segmentation (:meth:`segment`). Raises
    :class:`ModelFileError` when the model file is missing, corrupt or not this model (its
    input and output shapes are checked and it runs once on zeros).
    """

    def __init__(self, path: str | Path | None = None, threads: int = 1,
                 segmentation: bool = False):
        self.path = Path(DEFAULT_MODEL if path is None else path)
        outputs = {**_OUTPUTS, **(_SEGMENTATION_OUTPUT if segmentation else {})}
        self.segmentation = bool(segmentation)
        self._model = load_model(self.path, "pose landmark model", outputs,
                                 (1, INPUT_SIZE, INPUT_SIZE, 3), _GET_MODEL, threads)
        self._last_segmentation: np.ndarray | None = None

    def infer(self, crop_rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """The network on a 256 x 256 RGB uint8 crop: landmarks ``(39, 2)`` in input pixels
        (heatmap-refined), visibility ``(39,)``, presence ``(39,)``, pose presence score."""
        if crop_rgb.shape != (INPUT_SIZE, INPUT_SIZE, 3):
            raise ValueError(f"crop must be {INPUT_SIZE}x{INPUT_SIZE}x3, got {crop_rgb.shape}")
        blob = crop_rgb[None].astype(np.float32) * np.float32(1.0 / 255.0)  # NHWC, [0, 1]
        raw, flag, heat, *rest = self._model.run(blob)
        self._last_segmentation = rest[0].reshape(INPUT_SIZE, INPUT_SIZE) if rest else None
        raw = raw.reshape(NUM_LANDMARKS, 5).astype(np.float64)
        heat = heat.reshape(64, 64, NUM_LANDMARKS).transpose(2, 0, 1)
        xy = refine_from_heatmap(raw[:, :2], heat)
        return xy, _sigmoid(raw[:, 3]), _sigmoid(raw[:, 4]), float(flag.reshape(-1)[0])

    def run(self, image_rgb: np.ndarray, roi: Roi) -> ViewLandmarks:
        """Landmarks of the person in ``roi`` (image pixels; the caller's crop) of an RGB uint8
        image ``(H, W, 3)``."""
        image_rgb = np.asarray(image_rgb)
        if image_rgb.ndim != 3 or image_rgb.shape[2] != 3 or image_rgb.dtype != np.uint8:
            raise ValueError(f"image must be RGB uint8 (H, W, 3), "
                             f"got {image_rgb.dtype} {image_rgb.shape}")
        matrix = crop_transform(roi, INPUT_SIZE)
        crop = cv2.warpAffine(image_rgb, matrix, (INPUT_SIZE, INPUT_SIZE), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REPLICATE)
        xy, visibility, presence, score = self.infer(crop)
        xy = (xy - matrix[:, 2]) @ np.linalg.inv(matrix[:, :2]).T
        self._last_matrix = matrix
        return ViewLandmarks(xy=xy, visibility=visibility, presence=presence, score=score)

    def segment(self, image_rgb: np.ndarray, roi: Roi) -> tuple[ViewLandmarks, np.ndarray]:
        """:meth:`run`, and the probability that each pixel of the image is the person: float32
        ``(H, W)`` in [0, 1], the sigmoid of the network's segmentation mapped back through the
        crop's affine map (bilinear; 0 outside the crop). Needs ``segmentation=True``."""
        if not self.segmentation:
            raise ValueError("this network was loaded without its segmentation output "
                             "(segmentation=True)")
        view = self.run(image_rgb, roi)
        assert self._last_segmentation is not None  # run() keeps it for segmentation=True
        height, width = np.asarray(image_rgb).shape[:2]
        probability = _sigmoid(self._last_segmentation).astype(np.float32)
        mask = cv2.warpAffine(probability, self._last_matrix, (width, height),
                              flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        return view, mask
