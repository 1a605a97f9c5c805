"""The 2D body-landmark network of one view: BlazePose GHUM 3D ("Pose landmark full", MediaPipe),
run with OpenCV's dnn module on a square crop of the person.

Method: the pre- and post-processing of MediaPipe's ``PoseLandmarkByRoiCpu`` graph. Checked
against ``mediapipe==0.10.14``: on identical inputs the raw outputs equal TFLite's to 1e-3 px;
on simulated 640x480 frames the landmarks in image pixels lie within 1.2-1.9 px (median) of
those of ``mp.solutions.pose``, whose crops are its own.

1. **Crop**: the caller's box (full-image pixels) is made square about its centre with side
   ``max(width, height)``, optionally turned about it, and mapped onto the 256 x 256 network
   input by one affine warp (bilinear, replicated border where the square leaves the image,
   as MediaPipe's ``ImageToTensorCalculator``): without rotation, input pixel
   ``u' = (u - x0) * 256 / side``.
2. **Input**: RGB as float32 in [0, 1] (the model's training range, MediaPipe's
   ``output_tensor_float_range {min: 0, max: 1}``), NCHW 1 x 3 x 256 x 256.
3. **Outputs**: ``Identity`` (39 x [x, y, z, visibility, presence], x and y in input pixels,
   visibility and presence as logits: a sigmoid gives [0, 1]), ``Identity_1`` (the pose
   presence score, already in [0, 1]) and ``Identity_3`` (39 heatmaps of 64 x 64, logits).
4. **Heatmap refinement** (MediaPipe's ``RefineLandmarksFromHeatmapCalculator``, kernel 7):
   each landmark's x, y becomes the sigmoid(heatmap)-weighted mean of the 7 x 7 heatmap cells
   around it, where the window's largest weight reaches 0.5.
5. **Back to the image**: the inverse of the crop's affine map.

The first 33 landmarks are BlazePose's (:data:`LANDMARK_NAMES`); 33 and 34 are the auxiliary
points MediaPipe aligns its next crop with (hip centre, and a point whose distance from it is
half the side of the body's square box).

The crop's rotation is the caller's (:class:`~.keypoint_detector.KeypointDetector` turns it
to the previous skeleton's trunk): MediaPipe turns its crop to the axis of its own auxiliary
points, which needs a network pass first.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

__all__ = ["ModelFileError", "DEFAULT_MODEL", "INPUT_SIZE", "NUM_LANDMARKS", "LANDMARK_NAMES",
           "PoseLandmarkNetwork", "ViewLandmarks", "crop_transform", "refine_from_heatmap"]

#: The shipped model (see ``hmocap_ros/data/models/SOURCES.md``).
DEFAULT_MODEL = (Path(__file__).resolve().parents[1] / "data" / "models"
                 / "pose_landmark_full.tflite")
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
_OUTPUTS = ("Identity", "Identity_1", "Identity_3")
_HEATMAP_KERNEL = 7
_HEATMAP_MIN_CONFIDENCE = 0.5
_GET_MODEL = ("it ships with hmocap_ros as hmocap_ros/data/models/pose_landmark_full.tflite "
              "(see SOURCES.md there: mediapipe==0.10.14 wheel, "
              "mediapipe/modules/pose_landmark/pose_landmark_full.tflite)")


class ModelFileError(RuntimeError):
    """The landmark model file is missing or unreadable; the message names the file and where
    to get it."""


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


def crop_transform(box, rotation: float = 0.0) -> tuple[np.ndarray, float]:
    """Affine map ``(2, 3)`` from full-image pixels to network-input pixels of the square crop
    about ``box = (x_min, y_min, x_max, y_max)`` (side ``max(width, height)``), turned by
    ``rotation`` (radians, positive turns the image counter-clockwise about the box centre:
    a person leaning to the image's right by that angle stands upright in the crop), and the
    scale (input pixels per image pixel)."""
    x_min, y_min, x_max, y_max = (float(v) for v in box)
    side = max(x_max - x_min, y_max - y_min)
    if not np.isfinite(side) or side <= 1.0 or not np.all(np.isfinite((x_min, y_min, rotation))):
        raise ValueError(f"box must be (x_min, y_min, x_max, y_max) with a side > 1 px, "
                         f"got {box!r}")
    scale = INPUT_SIZE / side
    centre = np.array([0.5 * (x_min + x_max), 0.5 * (y_min + y_max)])
    c, s = np.cos(rotation), np.sin(rotation)
    linear = scale * np.array([[c, s], [-s, c]])
    offset = 0.5 * INPUT_SIZE - linear @ centre
    return np.hstack([linear, offset[:, None]]), scale


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


def tflite_available() -> bool:
    """Whether this OpenCV reads TFLite models (4.8 and later; Ubuntu 24.04's 4.6 does not)."""
    return getattr(cv2.dnn, "readNetFromTFLite", None) is not None


def default_detector(default: str) -> tuple[str, str]:
    """The extremity detector a run takes when none is asked for: ``default``, or ``skin`` with
    the reason when ``default`` is ``keypoints`` and this OpenCV cannot run the network (as
    extremity_detection falls back); ``(detector, note)``, the note empty when nothing changed."""
    if default != "keypoints" or tflite_available():
        return default, ""
    return "skin", (f"the keypoint detector needs OpenCV's TFLite reader (4.8 and later, this is "
                    f"{cv2.__version__}): detecting with the skin detector, as extremity_detection does")


def _load(path: Path):
    if not path.is_file():
        raise ModelFileError(f"pose landmark model {path} not found: {_GET_MODEL}")
    reader = getattr(cv2.dnn, "readNetFromTFLite", None)
    if reader is None:
        raise ModelFileError(f"pose landmark model {path} cannot be read: OpenCV "
                             f"{cv2.__version__} has no TFLite importer (4.8 and later have); the "
                             f"keypoint detector is unavailable, the skin detector works (detector skin)")
    # OpenCV 5's default engine returns one of the model's outputs only; its classic engine
    # (OpenCV 4's only one) returns them all
    engine = getattr(cv2.dnn, "ENGINE_CLASSIC", None)
    try:
        net = reader(str(path)) if engine is None else reader(str(path), engine=engine)
        outputs = set(net.getUnconnectedOutLayersNames())
    except cv2.error as error:
        reason = str(error).strip().splitlines()[-1][:160]
        raise ModelFileError(f"pose landmark model {path} is corrupt or not a TFLite model "
                             f"({reason}): {_GET_MODEL}") from None
    missing = [name for name in _OUTPUTS if name not in outputs]
    if missing:
        raise ModelFileError(f"pose landmark model {path} lacks the outputs {', '.join(missing)} "
                             f"of pose_landmark_full: {_GET_MODEL}")
    return net


class PoseLandmarkNetwork:
    """BlazePose "Pose landmark full" on OpenCV dnn (see the module docstring).

    Not thread-safe: give each thread its own instance. Raises :class:`ModelFileError` when
    the model file is missing, corrupt or not this model (its outputs are checked with one
    run on a blank input).
    """

    def __init__(self, path: str | Path | None = None):
        self.path = Path(DEFAULT_MODEL if path is None else path)
        self._net = _load(self.path)
        try:
            outputs = self._forward(np.zeros((1, 3, INPUT_SIZE, INPUT_SIZE), np.float32))
        except cv2.error as error:
            reason = str(error).strip().splitlines()[-1][:160]
            raise ModelFileError(f"pose landmark model {self.path} does not run ({reason}): "
                                 f"{_GET_MODEL}") from None
        shapes = tuple(o.size for o in outputs)
        if shapes != (NUM_LANDMARKS * 5, 1, NUM_LANDMARKS * 64 * 64):
            raise ModelFileError(f"pose landmark model {self.path} has output sizes {shapes}, "
                                 f"not those of pose_landmark_full: {_GET_MODEL}")

    def _forward(self, blob: np.ndarray) -> list[np.ndarray]:
        self._net.setInput(blob)
        return list(self._net.forward(list(_OUTPUTS)))

    def infer(self, crop_rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """The network on a 256 x 256 RGB uint8 crop: landmarks ``(39, 2)`` in input pixels
        (heatmap-refined), visibility ``(39,)``, presence ``(39,)``, pose presence score."""
        if crop_rgb.shape != (INPUT_SIZE, INPUT_SIZE, 3):
            raise ValueError(f"crop must be {INPUT_SIZE}x{INPUT_SIZE}x3, got {crop_rgb.shape}")
        blob = cv2.dnn.blobFromImage(crop_rgb, scalefactor=1.0 / 255.0)  # NCHW float32, [0, 1]
        raw, flag, heat = self._forward(blob)
        raw = raw.reshape(NUM_LANDMARKS, 5).astype(np.float64)
        xy = refine_from_heatmap(raw[:, :2], heat.reshape(NUM_LANDMARKS, 64, 64))
        return xy, _sigmoid(raw[:, 3]), _sigmoid(raw[:, 4]), float(flag.reshape(-1)[0])

    def run(self, image_rgb: np.ndarray, box: tuple[float, float, float, float],
            rotation: float = 0.0) -> ViewLandmarks:
        """Landmarks of the person in ``box = (x_min, y_min, x_max, y_max)`` (full-image pixels;
        the crop is the square about its centre of side ``max(width, height)``: the caller adds
        any margin) of an RGB uint8 image ``(H, W, 3)``; ``rotation``: see
        :func:`crop_transform`."""
        image_rgb = np.asarray(image_rgb)
        if image_rgb.ndim != 3 or image_rgb.shape[2] != 3 or image_rgb.dtype != np.uint8:
            raise ValueError(f"image must be RGB uint8 (H, W, 3), "
                             f"got {image_rgb.dtype} {image_rgb.shape}")
        matrix, _ = crop_transform(box, rotation)
        crop = cv2.warpAffine(image_rgb, matrix, (INPUT_SIZE, INPUT_SIZE), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REPLICATE)
        xy, visibility, presence, score = self.infer(crop)
        xy = (xy - matrix[:, 2]) @ np.linalg.inv(matrix[:, :2]).T
        return ViewLandmarks(xy=xy, visibility=visibility, presence=presence, score=score)
