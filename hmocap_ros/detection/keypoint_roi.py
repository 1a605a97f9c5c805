"""The crop (region of interest) a keypoint network sees: a square turned about its centre, and
where it comes from (no rclpy).

A :class:`Roi` is MediaPipe's ``NormalizedRect`` in image pixels: a square of side ``side``
about ``centre``, turned by ``rotation`` (radians; positive: the square's up axis leans to the
image's right, so a person leaning right by that angle stands upright in the crop).
:func:`crop_transform` maps it onto a network input (``ImageToTensorCalculator``: the square's
corners onto the input's corners).

The ROIs of MediaPipe's pose pipeline (``pose_detection_to_roi.pbtxt``,
``pose_landmarks_to_roi.pbtxt``: ``AlignmentPointsRectsCalculator`` then
``RectTransformationCalculator`` with ``scale 1.25``, ``square_long``):

* :func:`alignment_roi`: from two alignment points, ``centre`` (the hips' centre) and
  ``scale_point`` (a point whose distance from it is half the side of the body's square):
  centre at ``centre``, side ``2 |scale_point - centre| x 1.25``, rotation so that
  ``centre -> scale_point`` points up (``90 deg - atan2(-dy, dx)``). The pose detector's
  keypoints 0 and 1 give the first crop of a track, the landmark network's auxiliary points 33
  and 34 the next one (:func:`landmarks_roi`).
* :func:`skeleton_roi`: the same from a previous 3D skeleton projected into the view (when
  the view has no landmarks of its own yet): centre at the hips' midpoint, up along the trunk
  (hips' midpoint to shoulders' midpoint), radius the farthest projected keypoint from the
  centre grown by ``pad`` (head top, hands and feet lie beyond the joints).
* :func:`box_roi`: an upright square about a box (a foreground blob), side ``margin`` times the
  box's longer side.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ROI_SCALE", "Roi", "alignment_roi", "box_roi", "crop_transform", "landmarks_roi",
           "skeleton_roi"]

#: MediaPipe's ``RectTransformationCalculator`` scale of the pose ROIs.
ROI_SCALE = 1.25
#: Landmarks of the landmark network that align its next crop: hips' centre, scale point.
ALIGNMENT_LANDMARKS = (33, 34)


@dataclass(frozen=True)
class Roi:
    """A square crop in image pixels (module docstring): centre (x, y), side, rotation."""

    cx: float
    cy: float
    side: float
    rotation: float = 0.0

    def __post_init__(self):
        values = (self.cx, self.cy, self.side, self.rotation)
        if not np.all(np.isfinite(values)) or self.side <= 1.0:
            raise ValueError(f"a ROI needs a finite centre and rotation and a side > 1 px, "
                             f"got {values}")

    def corners(self) -> np.ndarray:
        """(4, 2) corners, top-left, top-right, bottom-right, bottom-left of the crop."""
        c, s = np.cos(self.rotation), np.sin(self.rotation)
        right, down = np.array([c, s]), np.array([-s, c])
        half = 0.5 * self.side
        centre = np.array([self.cx, self.cy])
        return np.array([centre + half * (sx * right + sy * down)
                         for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])

    def overlaps(self, width: int, height: int) -> bool:
        """Whether the crop's bounding box meets the image."""
        corners = self.corners()
        return bool(corners[:, 0].max() > 0 and corners[:, 1].max() > 0
                    and corners[:, 0].min() < width and corners[:, 1].min() < height)


def crop_transform(roi: Roi, size: int) -> np.ndarray:
    """Affine map ``(2, 3)`` from image pixels to the pixels of a ``size`` x ``size`` network
    input showing ``roi`` upright."""
    scale = size / roi.side
    c, s = np.cos(roi.rotation), np.sin(roi.rotation)
    linear = scale * np.array([[c, s], [-s, c]])
    offset = 0.5 * size - linear @ np.array([roi.cx, roi.cy])
    return np.hstack([linear, offset[:, None]])


def alignment_roi(centre, scale_point, scale: float = ROI_SCALE) -> Roi | None:
    """MediaPipe's ROI from two alignment points (module docstring); None when they coincide
    or are not finite."""
    centre, scale_point = np.asarray(centre, float), np.asarray(scale_point, float)
    dx, dy = scale_point - centre
    radius = float(np.hypot(dx, dy))
    if not np.isfinite(radius) or radius < 1.0:
        return None
    return Roi(float(centre[0]), float(centre[1]), 2.0 * radius * scale,
               float(np.arctan2(dx, -dy)))


def landmarks_roi(xy: np.ndarray, scale: float = ROI_SCALE) -> Roi | None:
    """The next crop from a view's landmarks ``(39, 2)`` (image pixels): points 33 and 34."""
    centre, scale_point = xy[list(ALIGNMENT_LANDMARKS)]
    return alignment_roi(centre, scale_point, scale)


def skeleton_roi(pixels: dict[str, np.ndarray], pad: float,
                 scale: float = ROI_SCALE) -> Roi | None:
    """The crop of a previous skeleton projected into a view (module docstring): ``pixels``,
    label -> (2,) image pixel of its keypoints in front of the camera; ``pad``: the radius grows
    by this share. None without both hips and shoulders."""
    need = ("left_hip", "right_hip", "left_shoulder", "right_shoulder")
    if not all(k in pixels for k in need):
        return None
    hips = 0.5 * (pixels["left_hip"] + pixels["right_hip"])
    shoulders = 0.5 * (pixels["left_shoulder"] + pixels["right_shoulder"])
    trunk = shoulders - hips
    length = float(np.hypot(*trunk))
    if length < 1.0:
        return None
    points = np.array(list(pixels.values()), dtype=np.float64)
    radius = float(np.max(np.linalg.norm(points - hips, axis=1))) * (1.0 + pad)
    return alignment_roi(hips, hips + radius * trunk / length, scale)


def box_roi(box, margin: float) -> Roi:
    """The upright square about ``box = (x0, y0, x1, y1)``, side ``margin`` x its longer side."""
    x0, y0, x1, y1 = (float(v) for v in box)
    return Roi(0.5 * (x0 + x1), 0.5 * (y0 + y1), margin * max(x1 - x0, y1 - y0, 8.0))
