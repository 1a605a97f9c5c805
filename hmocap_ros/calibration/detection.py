"""ChArUco corners in one image, and whether the detections fit the configured board.

:class:`CornerDetector` runs OpenCV's ``cv2.aruco.CharucoDetector`` (markers, then the
chessboard corners between them, refined to sub-pixel) and returns the corners with their
ids; with an OpenCV that has no ``CharucoDetector`` (4.6, Ubuntu 24.04's python3-opencv) the
same two steps through the older functions (``detectMarkers``, ``interpolateCornersCharuco``),
with the same settings. :func:`corner_fit_error` checks a detection against the board's geometry: the corners of a
plane seen by a camera are related to their board coordinates by a homography (up to the
lens distortion, small over a board), so a large residual means the markers were laid out
differently from the configured board (other square counts or sizes).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from hmocap_ros.calibration.board import BoardSpec

__all__ = ["CornerDetection", "CornerDetector", "corner_fit_error", "MIN_CORNERS"]

#: Corners a view needs to take part (a pose from fewer is fragile).
MIN_CORNERS = 6


@dataclass(frozen=True, eq=False)
class CornerDetection:
    """The board in one image: ``ids`` (n,) of inner corners, ``pixels`` (n, 2), and the ids of
    the markers found (``marker_ids``, possibly more than the corners use)."""

    ids: np.ndarray
    pixels: np.ndarray
    marker_ids: np.ndarray

    @property
    def n(self) -> int:
        return len(self.ids)


#: Whether this OpenCV has the ChArUco detector class (4.7 and later).
HAS_CHARUCO_DETECTOR = hasattr(cv2.aruco, "CharucoDetector")
#: The aruco module for its functions before 4.7 (Ubuntu 24.04 ships 4.6), absent from the 4.7+ type stubs.
_ARUCO_BEFORE_4_7: Any = cv2.aruco


class CornerDetector:
    """One ChArUco detector for the board ``spec``, reused for every image (module docstring)."""

    def __init__(self, spec: BoardSpec):
        self.spec = spec
        self._board = spec.cv_board()
        params = (cv2.aruco.DetectorParameters() if HAS_CHARUCO_DETECTOR
                  else _ARUCO_BEFORE_4_7.DetectorParameters_create())
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE  # the chessboard corners are refined
        params.minMarkerPerimeterRate = 0.01
        self._params = params
        self._detector = None
        if HAS_CHARUCO_DETECTOR:
            charuco = cv2.aruco.CharucoParameters()
            charuco.minMarkers = 1
            refine = cv2.aruco.RefineParameters()
            self._detector = cv2.aruco.CharucoDetector(self._board, charuco, params, refine)

    def _detect_board(self, grey: np.ndarray):
        """(corners, corner ids, marker ids) as ``CharucoDetector.detectBoard`` gives them."""
        if self._detector is not None:
            corners, ids, _marker_corners, marker_ids = self._detector.detectBoard(grey)
            return corners, ids, marker_ids
        marker_corners, marker_ids, _rejected = _ARUCO_BEFORE_4_7.detectMarkers(
            grey, self._board.dictionary, parameters=self._params)
        if marker_ids is None or len(marker_ids) == 0:
            return None, None, None
        _count, corners, ids = _ARUCO_BEFORE_4_7.interpolateCornersCharuco(
            marker_corners, marker_ids, grey, self._board, minMarkers=1)
        return corners, ids, marker_ids

    def detect(self, image: np.ndarray) -> CornerDetection:
        """Corners of an (H, W, 3) RGB or (H, W) grey uint8 image (none: ``n == 0``)."""
        grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
        corners, ids, marker_ids = self._detect_board(grey)
        marker_ids = np.zeros(0, int) if marker_ids is None else marker_ids.ravel().astype(int)
        if ids is None or len(ids) == 0:
            return CornerDetection(np.zeros(0, int), np.zeros((0, 2)), marker_ids)
        ids = ids.ravel().astype(int)
        pixels = _refine(grey, ids, corners.reshape(-1, 2), self.spec.columns - 1)
        return CornerDetection(ids, pixels, marker_ids)


def _square_pixels(ids: np.ndarray, pixels: np.ndarray, per_row: int) -> float:
    """Side of a square in the image (pixels): the smaller of the median distances between
    corners adjacent along the board's x and along its y."""
    where = {int(i): p for i, p in zip(ids, pixels)}
    along_x = [np.linalg.norm(where[i + 1] - where[i]) for i in where
               if i + 1 in where and i % per_row != per_row - 1]
    along_y = [np.linalg.norm(where[i + per_row] - where[i]) for i in where if i + per_row in where]
    medians = [float(np.median(d)) for d in (along_x, along_y) if d]
    return min(medians) if medians else 10.0


def _refine(grey: np.ndarray, ids: np.ndarray, pixels: np.ndarray, per_row: int) -> np.ndarray:
    """Sub-pixel saddle points (``cv2.cornerSubPix``) in a window of about 0.3 square: wide
    enough to average the noise, narrow enough to keep the markers' edges out."""
    half = int(np.clip(round(0.3 * _square_pixels(ids, pixels, per_row)), 2, 5))
    refined = cv2.cornerSubPix(grey, pixels.astype(np.float32).reshape(-1, 1, 2).copy(), (half, half),
                               (-1, -1), (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-4))
    return refined.reshape(-1, 2).astype(np.float64)


def corner_fit_error(spec: BoardSpec, detection: CornerDetection) -> float:
    """RMS pixel residual of the best homography from board coordinates to the detected
    corners (NaN below 6 corners): sub-pixel for the configured board, pixels for another."""
    if detection.n < MIN_CORNERS:
        return float("nan")
    board = spec.corner_points()[detection.ids, :2]
    H, _ = cv2.findHomography(board, detection.pixels, 0)
    if H is None:
        return float("inf")
    mapped = cv2.perspectiveTransform(board[None], H)[0]
    return float(np.sqrt(np.mean(np.sum((mapped - detection.pixels) ** 2, axis=1))))
