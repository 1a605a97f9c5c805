"""Labelled 3D keypoints of one person from a calibrated multi-view frame set (no rclpy).

Per view, a crop around the person goes through the landmark network (:mod:`.keypoint_network`);
the views' landmarks are triangulated robustly into
:data:`~.keypoint_triangulation.KEYPOINT_LABELS` (:mod:`.keypoint_triangulation`).

The crop is the one the network was trained on, as MediaPipe's ``PoseLandmarkCpu`` graph makes
it (:mod:`.keypoint_roi`): a square turned so that the body stands upright, 1.25 times the
body's circle (MediaPipe's scale; docs/tracking.md, section 3.7, says why not a tighter one).
Each view keeps a track; its crop comes, in this order, from

1. **the view's previous landmarks** (the track): the auxiliary points 33 (hips' centre) and 34
   (scale point) of the last frame set whose pose presence score reached ``min_pose_score``
   (MediaPipe's ``pose_landmarks_to_roi``);
2. **the previous skeleton** projected into the view, when the view has no track (first frame
   of a view, or a view that lost the person) and a skeleton is given: centre at the hips'
   midpoint, up along the trunk, radius the farthest keypoint from it grown by
   ``previous_box_pad`` (:func:`~.keypoint_roi.skeleton_roi`);
3. **the pose detector** on the whole view (:mod:`.pose_detector`, MediaPipe's
   ``pose_detection_to_roi``): the best-scored detection whose box meets the view's
   foreground (any detection without a mask);
4. **the foreground**: the upright square about the box of the largest foreground blob and the
   blobs whose boxes touch its box grown by a tenth (a limb the segmentation cut off), side
   ``box_margin`` times the box's longer side, when the detector finds nobody there.

A view whose mask shows no foreground is skipped and its track dropped; so is the track of a
view whose pose presence falls below ``min_pose_score``. :meth:`KeypointDetector.reset` drops
every track (a replay that starts over). Design choice: MediaPipe smooths the auxiliary points
with a one-euro filter before it crops (a steadier crop on a still person); the crop here is
taken from the last landmarks as they are, since frame sets reach the detector at irregular
intervals (the live node takes the newest and skips the others) and a filter tuned for a
steady video rate would lag behind a moving person.

The views run one after the other, each network on ``threads`` LiteRT threads. Design choice:
one network using LiteRT's own threads rather than views in parallel (a single-threaded
network per thread; LiteRT releases the GIL), since it costs less CPU and wall time per frame
set (docs/tracking.md, sec. 2.4, with the figures of ``benchmarks/bench_keypoints.py``).
"""
from __future__ import annotations

import logging
import time
from typing import Sequence

import cv2
import numpy as np

from hmocap_ros.detection.keypoint_network import PoseLandmarkNetwork, ViewLandmarks
from hmocap_ros.detection.keypoint_roi import Roi, box_roi, landmarks_roi, skeleton_roi
from hmocap_ros.detection.keypoint_triangulation import Keypoints3D, triangulate_views
from hmocap_ros.detection.params import KeypointParams
from hmocap_ros.detection.pose_detector import PoseDetector
from hmocap_ros.detection.view_rotation import (
    CostMeter,
    SkeletonHistory,
    carried_landmarks,
    views_for_rate,
    views_to_run,
)
from hmocap_ros.geometry import project_points

__all__ = ["CROP_SOURCES", "KeypointDetector", "foreground_box", "previous_pixels"]

_LOG = logging.getLogger(__name__)
#: masks are shrunk to about this width (pixels) to find the person's box
_ROI_MASK_WIDTH = 160
#: where a view's crop came from (module docstring), in the order they are tried; a view
#: whose network did not run this frame set and whose landmarks were carried forward
#: (:mod:`.view_rotation`) is ``carried``
CROP_SOURCES = ("track", "skeleton", "detector", "foreground")


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


def _reduced(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """The mask shrunk by an integer factor to about :data:`_ROI_MASK_WIDTH` pixels wide (a cell
    is foreground when any of its pixels is), and the factor."""
    factor = mask.shape[1] // _ROI_MASK_WIDTH
    if factor < 2:
        return mask, 1
    h, w = mask.shape[0] // factor, mask.shape[1] // factor
    return cv2.resize(mask[:h * factor, :w * factor], (w, h), interpolation=cv2.INTER_AREA), factor


def foreground_box(camera, mask: np.ndarray, params: KeypointParams):
    """The person's box ``(x0, y0, x1, y1)`` (full-image pixels) in a view's foreground mask
    (any resolution: scaled to the camera's): the largest blob and the blobs touching it, found
    on the mask shrunk to about 160 pixels wide; None when there is no foreground."""
    small, factor = _reduced(mask)
    sx, sy = camera.width / mask.shape[1] * factor, camera.height / mask.shape[0] * factor
    box = _blob_box(small, max(1.0, params.min_blob_fraction * small.size))
    if box is None:
        return None
    return box[0] * sx - 0.5, box[1] * sy - 0.5, box[2] * sx - 0.5, box[3] * sy - 0.5


def previous_pixels(camera, previous: dict[str, np.ndarray] | None) -> dict[str, np.ndarray]:
    """label -> (2,) pixel of the previous skeleton's keypoints in front of ``camera``."""
    if not previous:
        return {}
    labels = [k for k, p in previous.items() if np.all(np.isfinite(p))]
    if not labels:
        return {}
    proj = project_points([camera], np.array([previous[k] for k in labels], dtype=np.float64))
    return {k: proj.pixels[0][i] for i, k in enumerate(labels) if proj.depth[0][i] > 0}


def _meets(box, detection_box) -> bool:
    return bool(detection_box[0] < box[2] and detection_box[2] > box[0]
                and detection_box[1] < box[3] and detection_box[3] > box[1])


class KeypointDetector:
    """Per view the landmark network on its tracked crop, then robust triangulation (module
    docstring).

    ``cameras``: the rig's cameras (a :class:`~hmocap_ros.geometry.rig.Rig` or a list); ``model_path``:
    the landmark model, ``detector_path`` the pose detector's (default: the shipped ones;
    :class:`~.tflite_model.ModelFileError` when one is missing or corrupt).
    :attr:`last_timings` holds the seconds per stage of the last :meth:`detect`: ``roi``,
    ``network`` (all views, wall clock), ``network/<camera>`` (each view's landmark network
    and, where it ran, pose detector), ``triangulation`` and ``total``; :attr:`last_sources`
    where each view's crop came from (:data:`CROP_SOURCES`, None: skipped).
    """

    def __init__(self, cameras, params: KeypointParams | None = None, model_path=None,
                 detector_path=None):
        self.cameras = list(cameras)
        self.params = params or KeypointParams()
        threads = int(self.params.threads)
        # None once closed
        self._network: PoseLandmarkNetwork | None = PoseLandmarkNetwork(model_path, threads)
        self._detector: PoseDetector | None = PoseDetector(detector_path, threads,
                                                           self.params.min_detection_score)
        self._reported: set[str] = set()
        self._tracks: list[Roi | None] = [None] * len(self.cameras)
        self.last_timings: dict[str, float] = {}
        #: per camera, the frame sets whose triangulation left the view out (its landmarks
        #: disagreeing with the other views')
        self.views_left_out: dict[str, int] = {}
        self.last_sources: list[str | None] = [None] * len(self.cameras)
        #: per view, the stamp and landmarks of its last network run (:mod:`.view_rotation`)
        self._landmarks: list[tuple[int, ViewLandmarks] | None] = [None] * len(self.cameras)
        self._skeletons = SkeletonHistory()
        self._cost = CostMeter()
        #: seconds of a frame set's work outside this detector (segmentation, tracking),
        #: which the caller measures: counted when ``pose_rate_hz`` chooses the views
        self.other_stages_s = 0.0
        #: the views whose network ran on the last frame set
        self.last_views_run = 0

    def close(self) -> None:
        """Release the networks."""
        self._network = self._detector = None

    def reset(self) -> None:
        """Drop every view's track and carried landmarks: the next crops come from the
        skeleton or the detector."""
        self._tracks = [None] * len(self.cameras)
        self._landmarks = [None] * len(self.cameras)
        self._skeletons.clear()

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

    def _plan(self, v: int, camera, mask, previous):
        """(crop or None, source, foreground box) of view ``v`` before the networks run: the
        track's or the skeleton's crop, or None and ``detector`` with the box the detection
        must meet (None: any)."""
        fg_box = None
        if mask is not None:
            fg_box = foreground_box(camera, mask, self.params)
            if fg_box is None:
                self._tracks[v] = None
                return None, None, None
        if self._tracks[v] is not None:
            return self._tracks[v], "track", fg_box
        roi = skeleton_roi(previous_pixels(camera, previous), self.params.previous_box_pad)
        if roi is not None and roi.overlaps(camera.width, camera.height):
            return roi, "skeleton", fg_box
        return None, "detector", fg_box

    def _infer(self, image, roi, source, fg_box) -> tuple[ViewLandmarks | None, str, float]:
        t0 = time.perf_counter()
        assert self._network is not None and self._detector is not None, "detector closed"
        if roi is None:
            found = [d for d in self._detector.detect(image)
                     if fg_box is None or _meets(fg_box, d.box)]
            roi = found[0].roi() if found else None
            if roi is None and fg_box is not None:
                roi, source = box_roi(fg_box, self.params.box_margin), "foreground"
            if roi is None:
                return None, source, time.perf_counter() - t0
        return self._network.run(image, roi), source, time.perf_counter() - t0

    def _follow(self, v: int, camera, view: ViewLandmarks | None) -> None:
        """The view's next crop from its landmarks (None: lost)."""
        roi = None
        if view is not None and view.score >= self.params.min_pose_score:
            roi = landmarks_roi(view.xy)
        self._tracks[v] = roi if roi is not None and roi.overlaps(camera.width,
                                                                  camera.height) else None

    def _views_per_set(self, n_views: int) -> int:
        p = self.params
        k = int(p.views_per_set)
        if p.pose_rate_hz > 0:
            k = max(k, views_for_rate(p.pose_rate_hz, self._cost.per_view_s,
                                      self._cost.other_s + self.other_stages_s, n_views))
        return k

    def detect(self, images: Sequence[np.ndarray | None], masks: Sequence[np.ndarray | None],
               previous: dict[str, np.ndarray] | None = None, stamp_ns: int | None = None,
               previous_stamp_ns: int | None = None) -> Keypoints3D:
        """3D keypoints of one frame set: per camera an RGB uint8 image (or None) and a uint8
        foreground mask (or None; ``masks=None``: none at all); ``previous``: label -> (3,) room
        position of the last skeleton's keypoints, optional. A view without an image, with an
        image of the wrong size or type, or with a mask without foreground is skipped, logged
        once per cause; so is a view where the detector finds nobody (without a mask).

        ``stamp_ns``: the frame set's stamp, and ``previous_stamp_ns`` the skeleton's: with
        ``views_per_set`` > 0, the network runs on some views and the others' landmarks are
        carried forward (:mod:`.view_rotation`); without a stamp every view runs."""
        masks = [None] * len(self.cameras) if masks is None else list(masks)
        if len(images) != len(self.cameras) or len(masks) != len(self.cameras):
            raise ValueError(f"need one image and one mask per camera ({len(self.cameras)}), "
                             f"got {len(images)} images and {len(masks)} masks")
        t0 = time.perf_counter()
        plans: list = [None] * len(self.cameras)
        for v, (camera, image, mask) in enumerate(zip(self.cameras, images, masks)):
            if not self._check(camera, np.asarray(image) if image is not None else None):
                self._tracks[v] = None
                continue
            plan = self._plan(v, camera, mask, previous)
            if plan[1] is None:
                self._skip(camera, "no foreground")
                continue
            plans[v] = plan
        for v, plan in enumerate(plans):
            if plan is None:
                self._landmarks[v] = None
        if previous and previous_stamp_ns is not None:
            self._skeletons.add(int(previous_stamp_ns), previous)
        candidates = [v for v, plan in enumerate(plans) if plan is not None]
        rotating = stamp_ns is not None and self.params.views_per_set > 0
        jobs = candidates
        if rotating:
            assert stamp_ns is not None
            oldest = stamp_ns - self.params.max_carry_ms * 1e6
            self._landmarks = [item if item is not None and item[0] >= oldest else None
                               for item in self._landmarks]
            jobs = views_to_run([None if item is None else item[0] for item in self._landmarks],
                                candidates, self._views_per_set(len(self.cameras)))
        t1 = time.perf_counter()
        results = [self._infer(images[v], *plans[v]) for v in jobs]
        t2 = time.perf_counter()
        views: list = [None] * len(self.cameras)
        self.last_sources = [None] * len(self.cameras)
        timings = {"roi": t1 - t0, "network": t2 - t1}
        for v, (landmarks, source, seconds) in zip(jobs, results):
            views[v] = landmarks
            self.last_sources[v] = source if landmarks is not None else None
            timings[f"network/{self.cameras[v].name}"] = seconds
            self._follow(v, self.cameras[v], landmarks)
            self._landmarks[v] = (None if landmarks is None or stamp_ns is None
                                  else (int(stamp_ns), landmarks))
            if landmarks is None:
                self._skip(self.cameras[v], "the pose detector finds nobody")
        if rotating:
            assert stamp_ns is not None
            now = self._skeletons.at(stamp_ns)
            for v in sorted(set(candidates) - set(jobs)):
                item = self._landmarks[v]
                if item is None:
                    continue
                views[v] = carried_landmarks(self.cameras[v], item[1],
                                             self._skeletons.at(item[0]), now)
                self.last_sources[v] = "carried"
                self._follow(v, self.cameras[v], views[v])
        self.last_views_run = len(jobs)
        used_masks = [m if plan is not None else None for m, plan in zip(masks, plans)]
        result = triangulate_views(self.cameras, views, used_masks, previous, self.params)
        for v in result.views_left_out:
            name = self.cameras[v].name
            self.views_left_out[name] = self.views_left_out.get(name, 0) + 1
        t3 = time.perf_counter()
        timings.update(triangulation=t3 - t2, total=t3 - t0)
        self.last_timings = timings
        self._cost.add(t2 - t1, len(jobs), (t1 - t0) + (t3 - t2))
        return result
