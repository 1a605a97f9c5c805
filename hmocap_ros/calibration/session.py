"""What a calibration session has gathered, image by image, from a bag or from live topics:
the cameras, their image sizes and given intrinsics, and the board's corners in every image."""

from __future__ import annotations

import cv2
import numpy as np

from hmocap_ros.calibration.board import BoardSpec
from hmocap_ros.calibration.detection import CornerDetection, CornerDetector

__all__ = ["CalibrationSession"]


class CalibrationSession:
    """Board detections of the cameras ``names`` (indices into it are the camera numbers).

    ``intrinsics`` maps a camera name to ``(K, D, width, height, source)`` when given
    (camera_info)."""

    def __init__(self, names: list, spec: BoardSpec):
        self.names = list(names)
        self.spec = spec
        self.sizes: dict = {}  # camera -> (width, height)
        self.intrinsics: dict = {}  # camera name -> (K, D, width, height, source)
        self.detections: list = []  # (camera, stamp_ns, CornerDetection)
        self.n_images: dict = {}  # camera -> images searched
        self._detector = CornerDetector(spec)

    def add_image(self, camera: int, stamp_ns: int, image: np.ndarray) -> CornerDetection:
        """Search one (H, W, 3) RGB or (H, W) grey uint8 image of camera ``camera`` for the
        board; returns the detection."""
        grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
        self.sizes[camera] = (grey.shape[1], grey.shape[0])
        self.n_images[camera] = self.n_images.get(camera, 0) + 1
        detection = self._detector.detect(grey)
        self.detections.append((camera, int(stamp_ns), detection))
        return detection

    @property
    def n_images_total(self) -> int:
        return sum(self.n_images.values())
