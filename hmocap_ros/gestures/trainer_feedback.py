"""The interactive trainer's feedback image (thesis sec. 3.4.1, fig. 3.11): what a screen in the room shows.

:func:`feedback_image` draws, on an rgb8 image of the depth frame's size:

- the depth map false-coloured (near = warm, far = cold; no depth = black), between
  ``near_m`` and ``far_m``;
- the taught gesture's smoothed density p' (eq. 3.4) blended in white where it is high, so
  the user sees what the forest fires on while it learns;
- the box where the gesture is to be held (fig. 3.11), coloured by the state: yellow = do
  the gesture, green = learning it, grey = release, blue = learning negatives, white =
  testing / done;
- the shown detections (a circle per gesture, labelled with its name and score; the taught
  gesture's in green);
- a banner with the state, round, seconds left, threshold and the instruction, and a
  progress bar of the session along the bottom.

Text is drawn at a scale that follows the image width (readable at 320x240 and 640x480).
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["BOX_COLOURS", "colour_depth", "feedback_image"]

#: Box colour (RGB) per trainer state.
BOX_COLOURS = {
    "idle": (160, 160, 160),
    "do_gesture": (255, 220, 0),
    "update_positive": (0, 230, 0),
    "release": (160, 160, 160),
    "do_negatives": (60, 140, 255),
    "testing": (255, 255, 255),
    "done": (255, 255, 255),
}


def colour_depth(depth_m: np.ndarray, near_m: float = 0.5, far_m: float = 5.0) -> np.ndarray:
    """(H, W, 3) uint8 RGB of a depth map in metres: the turbo colour map, near = red, far =
    blue; invalid depth (<= 0, NaN, beyond ``far_m``) black."""
    d = np.asarray(depth_m, np.float32)
    valid = np.isfinite(d) & (d > 0) & (d <= far_m)
    scaled = np.where(valid, (far_m - np.clip(d, near_m, far_m)) / (far_m - near_m), 0.0)
    grey = (scaled * 255.0).astype(np.uint8)
    rgb = cv2.applyColorMap(grey, cv2.COLORMAP_TURBO)[:, :, ::-1]
    rgb = np.ascontiguousarray(rgb)
    rgb[~valid] = 0
    return rgb


def _text(img: np.ndarray, text: str, org: tuple, scale: float, colour=(255, 255, 255)) -> None:
    thick = max(1, int(round(scale * 2)))
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), thick + 2, cv2.LINE_AA)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, colour, thick, cv2.LINE_AA)


def feedback_image(depth_m: np.ndarray, status, probability: np.ndarray | None = None,
                   near_m: float = 0.5, far_m: float = 5.0) -> np.ndarray:
    """(H, W, 3) uint8 RGB feedback image of one frame (module docstring).

    ``depth_m``: the frame in metres (invalid <= 0 or NaN); ``status``: a
    :class:`~hmocap_ros.gestures.trainer.TrainerStatus`; ``probability``: (H, W) density of the
    taught gesture in [0, 1], or None.
    """
    img = colour_depth(depth_m, near_m, far_m)
    h, w = img.shape[:2]
    if probability is not None and probability.shape == (h, w):
        a = np.clip(probability, 0.0, 1.0)[:, :, None] * np.float32(0.7)
        img = (img * (1.0 - a) + 255.0 * a).astype(np.uint8)
    scale = max(0.3, w / 1000.0)
    line = int(round(30 * scale / 0.64))
    colour = BOX_COLOURS.get(status.state, (255, 255, 255))
    u, v, half = status.box
    if status.state != "idle":
        cv2.rectangle(img, (int(round(u - half)), int(round(v - half))), (int(round(u + half)), int(round(v + half))),
                      colour, max(1, w // 200))
    for det in status.detections:
        mine = det.name == status.gesture
        c = (0, 255, 0) if mine else (255, 80, 80)
        radius = max(4, int(round(12.0 / max(det.depth_m, 0.3) * w / 640.0)))
        cv2.circle(img, (int(round(det.u)), int(round(det.v))), radius, c, max(1, w // 320))
        _text(img, f"{det.name} {det.score:.2f}", (int(det.u) + radius + 2, int(det.v)), scale * 0.8, c)
    head = status.state.replace("_", " ")
    if status.state not in ("idle", "done"):
        head += f"  round {status.round}/{status.rounds}  {status.seconds_left:4.1f} s"
    if status.threshold is not None:
        head += f"  th {status.threshold:.2f}"
    cv2.rectangle(img, (0, 0), (w, 2 * line + line // 2), (0, 0, 0), -1)
    _text(img, head, (4, line), scale, colour)
    _text(img, status.instruction, (4, 2 * line), scale * 0.8)
    bar = max(3, h // 80)
    progress = float(np.clip(getattr(status, "progress", 0.0), 0.0, 1.0))
    cv2.rectangle(img, (0, h - bar), (int(round(progress * w)), h), colour, -1)
    return img
