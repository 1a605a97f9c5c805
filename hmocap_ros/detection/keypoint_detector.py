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
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from hmocap_ros.detection.keypoint_network import PoseLandmarkNetwork, ViewLandmarks
from hmocap_ros.detection.keypoint_roi import Roi, box_roi, landmarks_roi, skeleton_roi
from hmocap_ros.detection.keypoint_triangulation import (
    Keypoints3D,
    near_foreground,
    triangulate_views,
)
from hmocap_ros.detection.params import KeypointParams
from hmocap_ros.detection.people_search import (
    is_tracked,
    landmark_hips,
    landmarks_owner,
    new_people,
    occluded_bodies,
    pixels_box,
)
from hmocap_ros.detection.pose_detector import PoseDetector
from hmocap_ros.detection.view_rotation import (
    CostMeter,
    SkeletonHistory,
    carried_landmarks,
    views_for_rate,
    views_to_run,
)
from hmocap_ros.geometry import project_points

__all__ = ["CROP_SOURCES", "KeypointDetector", "PersonKeypoints", "foreground_blobs",
           "foreground_box", "previous_pixels"]

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


def foreground_blobs(camera, mask: np.ndarray, params: KeypointParams) -> list[tuple]:
    """The boxes ``(x0, y0, x1, y1)`` (full-image pixels) of every foreground blob of at least
    ``min_blob_fraction`` of a view's mask (found on the mask shrunk to about 160 pixels
    wide), largest first."""
    small, factor = _reduced(mask)
    sx, sy = camera.width / mask.shape[1] * factor, camera.height / mask.shape[0] * factor
    count, _, stats, _ = cv2.connectedComponentsWithStats((small > 0).astype(np.uint8),
                                                          connectivity=8)
    stats = stats[1:count]
    stats = stats[stats[:, cv2.CC_STAT_AREA] >= max(1.0, params.min_blob_fraction * small.size)]
    stats = stats[np.argsort(-stats[:, cv2.CC_STAT_AREA], kind="stable")]
    x0, y0 = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
    x1, y1 = x0 + stats[:, cv2.CC_STAT_WIDTH], y0 + stats[:, cv2.CC_STAT_HEIGHT]
    return [(a * sx - 0.5, b * sy - 0.5, c * sx - 0.5, d * sy - 0.5)
            for a, b, c, d in zip(x0, y0, x1, y1)]


def previous_pixels(camera, previous: dict[str, np.ndarray] | None) -> dict[str, np.ndarray]:
    """label -> (2,) pixel of the previous skeleton's keypoints in front of ``camera``."""
    if not previous:
        return {}
    labels = [k for k, p in previous.items() if np.all(np.isfinite(p))]
    if not labels:
        return {}
    proj = project_points([camera], np.array([previous[k] for k in labels], dtype=np.float64))
    return {k: proj.pixels[0][i] for i, k in enumerate(labels) if proj.depth[0][i] > 0}


class _PersonViews:
    """One tracked body's state in the views: per view its crop track and its last network
    landmarks ``(stamp, landmarks)``, and the body's skeletons fed back."""

    def __init__(self, n_views: int) -> None:
        self.tracks: list[Roi | None] = [None] * n_views
        self.landmarks: list[tuple[int, ViewLandmarks] | None] = [None] * n_views
        self.skeletons = SkeletonHistory()


@dataclass(frozen=True)
class PersonKeypoints:
    """One person's keypoints of a frame set: ``body_id`` the tracked body whose crops found
    them, or ``""`` for a person no body follows yet (found by the pose detector in two
    views or more)."""

    body_id: str
    keypoints: Keypoints3D


def _hips(skeleton: dict) -> np.ndarray:
    if "left_hip" in skeleton and "right_hip" in skeleton:
        return 0.5 * (np.asarray(skeleton["left_hip"], float)
                      + np.asarray(skeleton["right_hip"], float))
    return np.full(3, np.nan)


#: the pose detector's crop about a foreground blob where nobody was found: the upright
#: square of this many times the blob's longer side (the detector needs the person's
#: surroundings to see a whole body)
BLOB_CROP_MARGIN = 1.5
#: a new person's hips' centre must lie within this share of the image's longer side of
#: every view's foreground (:meth:`KeypointDetector._on_foreground`)
FOREGROUND_TOLERANCE = 0.02


def _holds(box, points: np.ndarray) -> bool:
    """Whether any of the pixels ``(N, 2)`` lies inside ``box`` (x0, y0, x1, y1)."""
    p = np.asarray(points, float).reshape(-1, 2)
    return bool(np.any((p[:, 0] >= box[0]) & (p[:, 0] <= box[2])
                       & (p[:, 1] >= box[1]) & (p[:, 1] <= box[3])))


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
        #: with several people (:meth:`detect_people`): each tracked body's state by body id
        self._bodies: dict[str, _PersonViews] = {}
        self._searches = 0
        #: with several people, what was left out and how often: ``occluded`` (a body's crop
        #: in a view behind a nearer body's), ``other person`` (a body's landmarks on another
        #: body), ``one view`` (a detected person that no second view confirms), ``off the
        #: foreground`` (a pair of views' person that another view's foreground refutes)
        self.people_left_out: dict[str, int] = {}

    def close(self) -> None:
        """Release the networks."""
        self._network = self._detector = None

    def reset(self) -> None:
        """Drop every view's track and carried landmarks: the next crops come from the
        skeleton or the detector."""
        self._tracks = [None] * len(self.cameras)
        self._landmarks = [None] * len(self.cameras)
        self._skeletons.clear()
        self._bodies.clear()

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

    def _next_crop(self, camera, view: ViewLandmarks | None) -> Roi | None:
        """A view's next crop from its landmarks (None: lost)."""
        roi = None
        if view is not None and view.score >= self.params.min_pose_score:
            roi = landmarks_roi(view.xy)
        return roi if roi is not None and roi.overlaps(camera.width, camera.height) else None

    def _follow(self, v: int, camera, view: ViewLandmarks | None) -> None:
        """The view's next crop from its landmarks (None: lost)."""
        self._tracks[v] = self._next_crop(camera, view)

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

    # ------------------------------------------------------------------ several people

    def _count(self, what: str) -> None:
        self.people_left_out[what] = self.people_left_out.get(what, 0) + 1

    def _usable_views(self, images, masks) -> list[tuple | None]:
        """Per view, None when it cannot be used, else its foreground box (None: no mask)."""
        usable: list[tuple | None] = []
        for camera, image, mask in zip(self.cameras, images, masks):
            if not self._check(camera, np.asarray(image) if image is not None else None):
                usable.append(None)
                continue
            box = (None,) if mask is None else (foreground_box(camera, mask, self.params),)
            if box[0] is None and mask is not None:
                self._skip(camera, "no foreground")
                usable.append(None)
                continue
            usable.append(box)
        return usable

    def _search(self, images, masks, usable, hips_px: np.ndarray, room: int) -> list:
        """People no body follows (:func:`~.people_search.new_people`): the pose detector on
        every usable view, then on each foreground blob where neither it nor a tracked body
        has a person (the detector finds the most prominent people of a whole view), its
        detections on the view's foreground and no tracked body's (``hips_px (V, B, 2)``: the
        bodies' projected hips)."""
        assert self._detector is not None, "detector closed"
        found: list[list] = []
        for v, (camera, image, mask) in enumerate(zip(self.cameras, images, masks)):
            if usable[v] is None:
                found.append([])
                continue
            fg = usable[v][0]
            dets = [d for d in self._detector.detect(image) if fg is None or _meets(fg, d.box)]
            if mask is not None:
                known = np.vstack([hips_px[v].reshape(-1, 2)]
                                  + [d.keypoints[:1] for d in dets])
                for blob in foreground_blobs(camera, mask, self.params):
                    if _holds(blob, known):
                        continue
                    roi = box_roi(blob, BLOB_CROP_MARGIN)
                    dets += [d for d in self._detector.detect(image, roi)
                             if _holds(blob, d.keypoints[:1])]
            found.append([d for d in dets if not is_tracked(d, hips_px[v])])
        size = max(max(c.width, c.height) for c in self.cameras)
        people = new_people(self.cameras, found, self.params.new_person_tolerance * size, room)
        taken = {(v, id(d)) for p in people for v, d in p.detections.items()}
        if any((v, id(d)) not in taken for v, dets in enumerate(found) for d in dets):
            self._count("one view")
        kept = [p for p in people if self._on_foreground(p.hips, masks)]
        if len(kept) < len(people):
            self._count("off the foreground")
        return kept

    def _unexplained(self, masks, usable, hips_px: np.ndarray) -> bool:
        """Whether a usable view may hold a person no body follows: it has no mask, or a
        foreground blob without any tracked body's projected hips (``hips_px (V, B, 2)``)."""
        for v, (camera, mask) in enumerate(zip(self.cameras, masks)):
            if usable[v] is None:
                continue
            if mask is None:
                return True
            known = hips_px[v].reshape(-1, 2)
            if any(not _holds(blob, known) for blob in foreground_blobs(camera, mask, self.params)):
                return True
        return False

    def _on_foreground(self, point: np.ndarray, masks) -> bool:
        """Whether a room point lies on (within :data:`FOREGROUND_TOLERANCE` of the image's
        longer side of) the foreground of every view that has a mask and sees it: two views'
        detections of two different people can triangulate to a point where nobody stands,
        which the other views' foreground refutes."""
        proj = project_points(self.cameras, np.asarray(point, float)[None])
        for v, (camera, mask) in enumerate(zip(self.cameras, masks)):
            if mask is None or not proj.visible[v, 0]:
                continue
            tolerance = FOREGROUND_TOLERANCE * max(camera.width, camera.height)
            if not near_foreground(mask, proj.pixels[v], camera.width, camera.height,
                                   tolerance)[0]:
                return False
        return True

    def detect_people(self, images: Sequence[np.ndarray | None],
                      masks: Sequence[np.ndarray | None] | None,
                      bodies: dict[str, dict] | None, stamp_ns: int | None = None,
                      previous_stamp_ns: int | None = None) -> list[PersonKeypoints]:
        """The keypoints of every person in a frame set (``max_people`` > 1): ``bodies``, body
        id -> the tracked body's last skeleton (label -> (3,) room position); ``stamp_ns``,
        ``previous_stamp_ns`` as in :meth:`detect`.

        Each tracked body's crop per view comes from its track or its projected skeleton;
        crops behind a nearer body's are left out (:func:`~.people_search.occluded_bodies`) and
        landmarks that lie on another body are dropped (:func:`~.people_search.landmarks_owner`);
        its views run in rotation as :meth:`detect`'s. While fewer than ``max_people`` bodies
        are tracked, the pose detector looks for the others (every ``search_every`` frame
        sets, when a view has no mask or a foreground blob without a tracked body's projected hips)
        and every person two views agree on is returned with body id ``""``. Bodies are
        returned in id order, then the new people, best agreeing first."""
        n = len(self.cameras)
        masks = [None] * n if masks is None else list(masks)
        if len(images) != n or len(masks) != n:
            raise ValueError(f"need one image and one mask per camera ({n}), "
                             f"got {len(images)} images and {len(masks)} masks")
        assert self._network is not None, "detector closed"
        p = self.params
        t0 = time.perf_counter()
        bodies = {k: v for k, v in (bodies or {}).items() if v}
        for gone in set(self._bodies) - set(bodies):
            del self._bodies[gone]
        ids = sorted(bodies)
        states = [self._bodies.setdefault(b, _PersonViews(n)) for b in ids]
        for b, state in zip(ids, states):
            if previous_stamp_ns is not None:
                state.skeletons.add(int(previous_stamp_ns), bodies[b])
        usable = self._usable_views(images, masks)
        hips = np.array([_hips(bodies[b]) for b in ids]).reshape(-1, 3)
        finite = np.isfinite(hips).all(axis=1)
        proj = project_points(self.cameras, np.where(finite[:, None], hips, 0.0))
        hips_px = np.where((finite[None, :] & (proj.depth > 0))[..., None], proj.pixels, np.nan)
        depth = np.where(finite[None, :] & (proj.depth > 0), proj.depth, np.nan)
        crops: list[list[Roi | None]] = []
        extents: list[list[np.ndarray | None]] = []
        for b, state in zip(ids, states):
            row: list[Roi | None] = []
            extent: list[np.ndarray | None] = []
            for v, camera in enumerate(self.cameras):
                pixels = previous_pixels(camera, bodies[b])
                extent.append(pixels_box(pixels))
                roi = state.tracks[v] if usable[v] is not None else None
                if roi is None and usable[v] is not None:
                    roi = skeleton_roi(pixels, p.previous_box_pad)
                    roi = roi if roi is not None and roi.overlaps(camera.width, camera.height) else None
                row.append(roi)
            crops.append(row)
            extents.append(extent)
        for v in range(n):
            hidden = occluded_bodies([row[v] for row in extents], depth[v], p.occluded_share)
            for i, behind in enumerate(hidden):
                if behind:
                    crops[i][v] = None
                    states[i].tracks[v] = None
                    self._count("occluded")
        jobs: list[list[int]] = []
        k = self._views_per_set(n)
        rotating = stamp_ns is not None and p.views_per_set > 0
        for i, state in enumerate(states):
            for v in range(n):
                if crops[i][v] is None:
                    state.landmarks[v] = None
            candidates = [v for v in range(n) if crops[i][v] is not None]
            if rotating:
                assert stamp_ns is not None
                oldest = stamp_ns - p.max_carry_ms * 1e6
                state.landmarks = [item if item is not None and item[0] >= oldest else None
                                   for item in state.landmarks]
                candidates = views_to_run([None if item is None else item[0]
                                           for item in state.landmarks], candidates, k)
            jobs.append(candidates)
        t1 = time.perf_counter()
        people = []
        self._searches += 1
        if (len(ids) < p.max_people and self._searches % int(p.search_every) == 0
                and self._unexplained(masks, usable, hips_px)):
            people = self._search(images, masks, usable, hips_px, p.max_people - len(ids))
        out: list[PersonKeypoints] = []
        views_run = 0
        for i, (b, state) in enumerate(zip(ids, states)):
            views: list = [None] * n
            for v in jobs[i]:
                image, roi = images[v], crops[i][v]
                assert image is not None and roi is not None  # a job is a usable view's crop
                landmarks: ViewLandmarks | None = self._network.run(image, roi)
                views_run += 1
                if landmarks is not None and len(ids) > 1:
                    owner = landmarks_owner(landmark_hips(landmarks.xy), hips_px[v])
                    if owner not in (-1, i):
                        self._count("other person")
                        landmarks = None
                views[v] = landmarks
                state.tracks[v] = self._next_crop(self.cameras[v], landmarks)
                state.landmarks[v] = (None if landmarks is None or stamp_ns is None
                                      else (int(stamp_ns), landmarks))
            if rotating:
                assert stamp_ns is not None
                now = state.skeletons.at(stamp_ns)
                for v in range(n):
                    item = state.landmarks[v]
                    if v in jobs[i] or item is None or crops[i][v] is None:
                        continue
                    views[v] = carried_landmarks(self.cameras[v], item[1],
                                                 state.skeletons.at(item[0]), now)
                    state.tracks[v] = self._next_crop(self.cameras[v], views[v])
            used = [m if crops[i][v] is not None else None for v, m in enumerate(masks)]
            out.append(PersonKeypoints(b, triangulate_views(self.cameras, views, used,
                                                            bodies[b], p)))
        for person in people:
            views = [None] * n
            for v, detection in person.detections.items():
                found = detection.roi()
                image = images[v]
                if found is not None and image is not None:
                    views[v] = self._network.run(image, found)
                    views_run += 1
            used = [m if views[v] is not None else None for v, m in enumerate(masks)]
            out.append(PersonKeypoints("", triangulate_views(self.cameras, views, used, None, p)))
        t2 = time.perf_counter()
        self.last_views_run = views_run
        self.last_timings = {"roi": t1 - t0, "network": t2 - t1, "total": t2 - t0}
        if views_run:
            self._cost.add(t2 - t1, views_run, t1 - t0)
        return out
