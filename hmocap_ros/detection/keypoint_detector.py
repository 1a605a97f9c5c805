"""Labelled 3D keypoints of one person from a calibrated multi-view frame set (no rclpy).

Per view, a crop around the person (:func:`roi_box`) goes through the landmark network
(:mod:`.keypoint_network`); the views' landmarks are triangulated robustly into
:data:`~.keypoint_triangulation.KEYPOINT_LABELS` (:mod:`.keypoint_triangulation`).

The crop (region of interest) of a view:

* without a previous skeleton: the bounding box of the largest foreground blob, together with
  the blobs whose boxes touch its box grown by a tenth (a limb the segmentation cut off);
* with the previous skeleton (room-frame keypoints of the last frame): its projection's box,
  padded by ``previous_box_pad`` of its height on every side (head top, hands and feet lie
  beyond the joints; the person moves between frames), tightened to the foreground inside it;
  the blob rule above when no foreground lies there;

made square about its centre with side ``box_margin`` times its longer side. Design choice:
1.15, not MediaPipe's 1.25: a person 100-250 pixels tall fills more of the 256-pixel input
(on simulated 640x480 recordings 1.1-1.15 gave the lowest joint errors, 1.0 cut off hands and
feet, 1.4 added 5 mm). The mask may have a lower resolution than the image: boxes are scaled.

The crop is turned (:func:`roi_rotation`) so that the previous skeleton's trunk, hips'
midpoint to shoulders' midpoint as projected in the view, stands upright, as MediaPipe turns
its crops to its own previous landmarks; without a previous skeleton it is upright. On
simulated recordings the turn brought the 12 limb joints' mean error from 31.8 to 29.7 mm,
most of it at the hips of a subject bending over (82 and 72 mm to 45 and 30 mm); a second
network pass to find the turn without a previous skeleton gained under 0.3 px per landmark.

The network runs on ``workers`` threads, one network instance each (OpenCV releases the GIL
during inference): on two cores two views run at once, each on one OpenCV thread
(``opencv_threads``). With both cores of a 2-core machine free, two single-threaded networks
side by side ran 4 views in 67 ms, one network on two OpenCV threads in 78 ms (33 ms of CPU
per view either way; ``benchmarks/bench_keypoints.py``).
"""
from __future__ import annotations

import logging
import queue
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from hmocap_ros.camera_model import project_points
from hmocap_ros.detection.keypoint_network import PoseLandmarkNetwork, ViewLandmarks
from hmocap_ros.detection.keypoint_triangulation import Keypoints3D, triangulate_views
from hmocap_ros.params import param

__all__ = ["KeypointParams", "KeypointDetector", "roi_box", "roi_rotation"]

_LOG = logging.getLogger(__name__)
#: masks are shrunk to about this width (pixels) to find the person's box
_ROI_MASK_WIDTH = 160
#: radians, the largest turn of a crop
_MAX_ROTATION = np.pi / 3


@dataclass(frozen=True)
class KeypointParams:
    """Tunables of :class:`KeypointDetector` and
    :func:`~hmocap_ros.detection.keypoint_triangulation.triangulate_views`."""

    box_margin: float = param(
        1.15, "Side of the square crop over the longer side of the person's box (>= 1; "
              "MediaPipe's own crops use 1.25).")
    previous_box_pad: float = param(
        0.2, "Padding of the previous skeleton's projected box on every side, as a fraction of "
             "its height (>= 0).")
    min_blob_fraction: float = param(
        0.002, "Smallest foreground, as a fraction of the mask's pixels, that counts as a "
               "person (a view with less is skipped; in [0, 1)).")
    min_pose_score: float = param(
        0.5, "Smallest pose presence score of a view's network output for its landmarks to be "
             "used (in [0, 1]).")
    min_visibility: float = param(
        0.1, "Smallest keypoint weight (landmark visibility x presence x pose score, reduced "
             "outside the silhouette) for a view to take part in a keypoint (in [0, 1]).")
    confident_visibility: float = param(
        0.5, "When at least min_views agreeing views have a weight of this or more (in [0, 1]), "
             "only they are triangulated.")
    mask_tolerance_px: float = param(
        8.0, "A keypoint farther than this from the view's foreground (full-image pixels, "
             ">= 0) is outside the silhouette.")
    outside_mask_weight: float = param(
        0.3, "Factor on the weight of a keypoint outside the silhouette (in [0, 1]; 0 drops it).")
    max_reprojection_px: float = param(
        12.0, "tau: a view agrees with a 3D keypoint when its landmark lies within this many "
              "pixels of the point's projection (> 0).")
    min_views: int = param(
        2, "Fewest agreeing views for a keypoint to be reported (>= 2).")
    min_score: float = param(
        0.3, "Keypoints with a lower confidence are not reported (in [0, 1]).")
    resolve_swaps: bool = param(
        True, "Rename the sides of a view whose left and right disagree with the other views.")
    swap_margin: float = param(
        0.5, "The sides of views are renamed only when the consensus gained exceeds this share "
             "of the renamed views' weight (>= 0).")
    workers: int = param(
        2, "Threads running the network, one network instance each (>= 1).")
    opencv_threads: int = param(
        1, "OpenCV threads, set process-wide (cv2.setNumThreads) when the detector starts "
           "(>= 0; 0 leaves OpenCV's setting): with a network per worker, 1 keeps the cores "
           "from being oversubscribed.")

    def __post_init__(self) -> None:
        checks = {
            "box_margin": self.box_margin >= 1.0, "previous_box_pad": self.previous_box_pad >= 0,
            "min_blob_fraction": 0 <= self.min_blob_fraction < 1,
            "min_pose_score": 0 <= self.min_pose_score <= 1,
            "min_visibility": 0 <= self.min_visibility <= 1,
            "confident_visibility": 0 <= self.confident_visibility <= 1,
            "mask_tolerance_px": self.mask_tolerance_px >= 0,
            "outside_mask_weight": 0 <= self.outside_mask_weight <= 1,
            "max_reprojection_px": self.max_reprojection_px > 0,
            "min_views": int(self.min_views) == self.min_views and self.min_views >= 2,
            "min_score": 0 <= self.min_score <= 1, "workers": int(self.workers) >= 1,
            "opencv_threads": int(self.opencv_threads) >= 0,
            "swap_margin": self.swap_margin >= 0,
        }
        bad = [name for name, ok in checks.items() if not ok]
        if bad:
            raise ValueError("KeypointParams: out of range: "
                             + ", ".join(f"{n}={getattr(self, n)!r}" for n in bad))


def _blob_box(mask: np.ndarray, min_pixels: float):
    """Box (x0, y0, x1, y1) in mask pixels of the largest blob and the blobs whose boxes touch
    its box grown by a tenth of its size."""
    count, _, stats, _ = cv2.connectedComponentsWithStats((mask > 0).astype(np.uint8),
                                                          connectivity=8)
    if count < 2:
        return None
    stats = stats[1:]
    largest = int(np.argmax(stats[:, cv2.CC_STAT_AREA]))
    if stats[largest, cv2.CC_STAT_AREA] < min_pixels:
        return None
    x0, y0 = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
    x1, y1 = x0 + stats[:, cv2.CC_STAT_WIDTH], y0 + stats[:, cv2.CC_STAT_HEIGHT]
    pad = 0.1 * max(x1[largest] - x0[largest], y1[largest] - y0[largest])
    touch = ((x0 <= x1[largest] + pad) & (x1 >= x0[largest] - pad)
             & (y0 <= y1[largest] + pad) & (y1 >= y0[largest] - pad))
    return (float(x0[touch].min()), float(y0[touch].min()), float(x1[touch].max()),
            float(y1[touch].max()))


def _previous_box(camera, previous: dict[str, np.ndarray], pad: float):
    """Padded box (full-image pixels) of the previous keypoints' projection, or None."""
    points = np.array([p for p in previous.values() if np.all(np.isfinite(p))], dtype=np.float64)
    if len(points) < 2:
        return None
    proj = project_points([camera], points)
    pix = proj.pixels[0][proj.depth[0] > 0]
    if len(pix) < 2:
        return None
    (x0, y0), (x1, y1) = pix.min(axis=0), pix.max(axis=0)
    margin = pad * max(y1 - y0, x1 - x0)
    box = (x0 - margin, y0 - margin, x1 + margin, y1 + margin)
    if box[2] < 0 or box[3] < 0 or box[0] > camera.width or box[1] > camera.height:
        return None
    return box


def _reduced(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """The mask shrunk by an integer factor to about :data:`_ROI_MASK_WIDTH` pixels wide (a cell
    is foreground when any of its pixels is), and the factor."""
    factor = mask.shape[1] // _ROI_MASK_WIDTH
    if factor < 2:
        return mask, 1
    h, w = mask.shape[0] // factor, mask.shape[1] // factor
    return cv2.resize(mask[:h * factor, :w * factor], (w, h), interpolation=cv2.INTER_AREA), factor


def roi_box(camera, mask: np.ndarray | None, previous: dict[str, np.ndarray] | None,
            params: KeypointParams):
    """The square crop ``(x0, y0, x1, y1)`` (full-image pixels) of one view (module
    docstring), or None when the view shows no person. The boxes are found on the mask shrunk
    to about 160 pixels wide."""
    box = None if not previous else _previous_box(camera, previous, params.previous_box_pad)
    if mask is not None:
        small, factor = _reduced(mask)
        sx, sy = camera.width / mask.shape[1] * factor, camera.height / mask.shape[0] * factor
        mh, mw = small.shape[:2]
        min_pixels = max(1.0, params.min_blob_fraction * small.size)
        fg_box = None
        if box is not None:
            c0, r0 = max(0, int(box[0] / sx)), max(0, int(box[1] / sy))
            c1, r1 = min(mw, int(np.ceil(box[2] / sx)) + 1), min(mh, int(np.ceil(box[3] / sy)) + 1)
            rows, cols = np.nonzero(small[r0:r1, c0:c1])
            if rows.size >= min_pixels:
                fg_box = (c0 + cols.min(), r0 + rows.min(),
                          c0 + cols.max() + 1, r0 + rows.max() + 1)
        if fg_box is None:
            fg_box = _blob_box(small, min_pixels)
        if fg_box is None:
            return None
        box = (fg_box[0] * sx - 0.5, fg_box[1] * sy - 0.5,
               fg_box[2] * sx - 0.5, fg_box[3] * sy - 0.5)
    if box is None:
        return None
    cx, cy = 0.5 * (box[0] + box[2]), 0.5 * (box[1] + box[3])
    half = 0.5 * params.box_margin * max(box[2] - box[0], box[3] - box[1], 8.0)
    return cx - half, cy - half, cx + half, cy + half


def roi_rotation(camera, previous: dict[str, np.ndarray] | None) -> float:
    """Rotation (radians, :func:`~.keypoint_network.crop_transform`) that stands the previous
    skeleton's trunk (hips' midpoint to shoulders' midpoint) upright in the view's crop; 0
    without a previous skeleton with both hips and shoulders in front of the camera."""
    need = ("left_hip", "right_hip", "left_shoulder", "right_shoulder")
    if not previous or not all(k in previous and np.all(np.isfinite(previous[k])) for k in need):
        return 0.0
    proj = project_points([camera], np.array([previous[k] for k in need], dtype=np.float64))
    if np.any(proj.depth[0] <= 0):
        return 0.0
    pix = proj.pixels[0]
    dx, dy = 0.5 * (pix[2] + pix[3]) - 0.5 * (pix[0] + pix[1])
    return float(np.clip(np.arctan2(dx, -dy), -_MAX_ROTATION, _MAX_ROTATION))


class KeypointDetector:
    """Per view the landmark network, then robust triangulation (module docstring).

    ``cameras``: the rig's cameras (a :class:`~hmocap_ros.rig.Rig` or a list); ``model_path``:
    the landmark model (default: the shipped one; :class:`~.keypoint_network.ModelFileError`
    when it is missing or corrupt). :attr:`last_timings` holds the seconds per stage of the
    last :meth:`detect`: ``roi``, ``network`` (all views, wall clock), ``network/<camera>``
    (each view's inference), ``triangulation`` and ``total``.
    """

    def __init__(self, cameras, params: KeypointParams | None = None, model_path=None):
        self.cameras = list(cameras)
        self.params = params or KeypointParams()
        if self.params.opencv_threads > 0:
            cv2.setNumThreads(int(self.params.opencv_threads))
        workers = max(1, min(int(self.params.workers), len(self.cameras)))
        self._networks: queue.SimpleQueue = queue.SimpleQueue()
        for _ in range(workers):
            self._networks.put(PoseLandmarkNetwork(model_path))
        self._pool = (ThreadPoolExecutor(workers, thread_name_prefix="keypoints")
                      if workers > 1 else None)
        self._reported: set[str] = set()
        self.last_timings: dict[str, float] = {}

    def close(self) -> None:
        """Stop the worker threads."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def _skip(self, camera, cause: str) -> None:
        if cause not in self._reported:
            self._reported.add(cause)
            _LOG.warning("keypoint detection skips camera %s: %s (reported once per cause)",
                         camera.name, cause)

    def _check(self, camera, image) -> bool:
        if image is None:
            self._skip(camera, "no image")
            return False
        if image.shape != (camera.height, camera.width, 3) or image.dtype != np.uint8:
            self._skip(camera, f"image of {image.dtype} {image.shape}, expected uint8 "
                               f"({camera.height}, {camera.width}, 3)")
            return False
        return True

    def _infer(self, image, box, rotation) -> tuple[ViewLandmarks, float]:
        network = self._networks.get()
        try:
            t0 = time.perf_counter()
            return network.run(image, box, rotation), time.perf_counter() - t0
        finally:
            self._networks.put(network)

    def detect(self, images: Sequence[np.ndarray | None], masks: Sequence[np.ndarray | None],
               previous: dict[str, np.ndarray] | None = None) -> Keypoints3D:
        """3D keypoints of one frame set: per camera an RGB uint8 image (or None) and a uint8
        foreground mask (or None; ``masks=None``: none at all); ``previous``: label -> (3,) room
        position of the last skeleton's keypoints, optional. A view without an image, with an
        image of the wrong size or type, or without foreground (without a mask: without a
        previous skeleton) is skipped, logged once per cause."""
        masks = [None] * len(self.cameras) if masks is None else list(masks)
        if len(images) != len(self.cameras) or len(masks) != len(self.cameras):
            raise ValueError(f"need one image and one mask per camera ({len(self.cameras)}), "
                             f"got {len(images)} images and {len(masks)} masks")
        t0 = time.perf_counter()
        boxes: list = [None] * len(self.cameras)
        turns = [0.0] * len(self.cameras)
        for v, (camera, image, mask) in enumerate(zip(self.cameras, images, masks)):
            if not self._check(camera, np.asarray(image) if image is not None else None):
                continue
            boxes[v] = roi_box(camera, mask, previous, self.params)
            turns[v] = roi_rotation(camera, previous)
            if boxes[v] is None:
                self._skip(camera, "no foreground" if mask is not None
                           else "no mask and no previous skeleton")
        t1 = time.perf_counter()
        jobs = [v for v, box in enumerate(boxes) if box is not None]
        if self._pool is None:
            results = [self._infer(images[v], boxes[v], turns[v]) for v in jobs]
        else:
            results = list(self._pool.map(
                lambda v: self._infer(images[v], boxes[v], turns[v]), jobs))
        t2 = time.perf_counter()
        views: list = [None] * len(self.cameras)
        timings = {"roi": t1 - t0, "network": t2 - t1}
        for v, (landmarks, seconds) in zip(jobs, results):
            views[v] = landmarks
            timings[f"network/{self.cameras[v].name}"] = seconds
        used_masks = [m if b is not None else None for m, b in zip(masks, boxes)]
        result = triangulate_views(self.cameras, views, used_masks, previous, self.params)
        t3 = time.perf_counter()
        timings.update(triangulation=t3 - t2, total=t3 - t0)
        self.last_timings = timings
        return result
