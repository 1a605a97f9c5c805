"""``hmocap eval consistency BAG [--tracked TRACKED_BAG] --json OUT``: how well a tracked body
agrees with the images of a recording that has no ground truth.

Without ground truth three checks remain, each against what the images show (the landmark
network of :mod:`hmocap_ros.detection` and the foreground of :mod:`hmocap_ros.segmentation`):

1. **Reprojection**: the tracked body's 12 limb joints (shoulders, elbows, wrists, hips, knees,
   ankles: :data:`~hmocap_ros.detection.detections.MODEL_JOINT`) projected into every view,
   against that view's keypoint of the same label where the network is confident of it
   (landmark weight of :func:`~hmocap_ros.detection.keypoint_triangulation.view_keypoints` at
   least ``confident_visibility``, 0.5): pixels, median and 90th percentile, overall, per
   joint and per view.
2. **Silhouettes**: the tracked body model (its joint states and shape) rendered in every view,
   against the view's foreground: intersection over union, mean over the views and frame sets
   with a pose.
3. **Triangulation**: the same joints against the plain robust triangulation of the views'
   keypoints (:func:`~hmocap_ros.detection.keypoint_triangulation.triangulate_views`, no body
   model, no tracking) where at least ``--min-views`` (3) views agree: millimetres, median
   and per joint.

The views' keypoints come from the landmark network on each view's tracked crop
(:class:`~hmocap_ros.segmentation.person_masks.PersonMasks`, the detector's crops); the
foreground from a background model per camera (``--learn-from``, default ``person_masks``:
a recording without ground truth does not say that its room starts empty). Without
``--tracked`` the bag is tracked first with ``hmocap track``'s defaults
(:func:`~hmocap_ros.eval.bag_tracking.track_to_bag`, into a temporary bag); with it, the tracked
bag's bodies (each slot with a ``/humans/bodies/<id>/joint_states`` topic; its ``/skeleton``
messages and ``body_shape``, :func:`~hmocap_ros.export.motion.read_motion`). A body is checked
on the frame sets where it has a skeleton at their stamp; a tracker that found nobody gives
``frames_with_pose`` 0 and null figures, not an error.

JSON (``--json``): ``frames``; for the first body ``body_id``, ``frames_with_pose``,
``reprojection_median_px``, ``reprojection_p90_px``, ``silhouette_iou_mean``,
``triangulation_gap_mm`` (median), ``per_joint``, ``per_view``, ``keypoint_pairs``,
``triangulated_points``; ``bodies``, every body's figures (those keys but the per-joint and
per-view ones); ``frames_with_bodies``, the number of frame sets with each count of bodies
with a pose (``{"0": 3, "1": 97}``); ``image_size``,
``tracked`` (the ``--tracked`` bag, null when tracked here) and ``tracking`` (the on-the-fly
run's frame sets, frame sets with a body, foreground source and notes). ``--picture``: each view
of a few frame sets with the foreground's outline (green), the rendered body's (magenta), the
views' keypoints (yellow) and the tracked joints projected (red, with the skeleton's bones).
Pixels are those of the bag's images.
"""
from __future__ import annotations

import re
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from hmocap_ros.detection.keypoint_network import ViewLandmarks

__all__ = ["ConsistencyError", "consistency_report", "evaluate_consistency", "silhouette_iou"]

#: Frame sets drawn in the picture.
PICTURE_FRAMES = 4


class ConsistencyError(ValueError):
    """Bad input of the consistency check (one line for the user)."""


def silhouette_iou(rendered: np.ndarray, foreground: np.ndarray) -> float | None:
    """Intersection over union of two masks (non-zero = inside); None when both are empty."""
    a, b = np.asarray(rendered) != 0, np.asarray(foreground) != 0
    union = np.count_nonzero(a | b)
    return None if union == 0 else np.count_nonzero(a & b) / union


def _stats(values) -> dict:
    values = np.asarray(values, dtype=np.float64)
    if values.size == 0:
        return {"median": None, "p90": None, "count": 0}
    return {"median": float(np.median(values)), "p90": float(np.percentile(values, 90)),
            "count": int(values.size)}


class _Body:
    """The tracked body's joints and mesh at a frame set's stamp."""

    def __init__(self, motion):
        from hmocap_ros.body import load_body_model
        from hmocap_ros.detection.detections import MODEL_JOINT

        self.model = load_body_model("tracking")
        self.motion = motion
        names = list(motion.point_names)
        self.joints = {label: names.index(joint) for label, joint in MODEL_JOINT.items()
                       if joint in names}
        self.by_stamp = {int(s): i for i, s in enumerate(motion.stamps_ns)}
        dof_index = {n: i for i, n in enumerate(motion.dof_names)}
        self.dof_columns = [dof_index.get(n) for n in self.model.skeleton.dof_names]
        self.dofs = motion.dofs_at_skeleton_frames() if len(motion.dof_names) else None

    def shape_at(self, stamp: int):
        shapes = [s for t, s in self.motion.shapes if t <= stamp] or [s for _, s in self.motion.shapes[:1]]
        return shapes[-1] if shapes else None

    def at(self, stamp: int):
        """(label -> (3,) joint, mesh vertices (V, 3) or None), or None without a pose."""
        i = self.by_stamp.get(int(stamp))
        if i is None or not np.isfinite(self.motion.points[i]).all():
            return None
        joints = {label: self.motion.points[i, j] for label, j in self.joints.items()}
        vertices = None
        if self.dofs is not None and None not in self.dof_columns:
            params = self.dofs[i, self.dof_columns]
            shape = self.shape_at(stamp)
            if np.isfinite(params).all() and shape is not None:
                vertices = self.model.forward(params[None], shape).vertices[0]
        return joints, vertices


def _outline(mask: np.ndarray) -> np.ndarray:
    import cv2

    mask = (np.asarray(mask) != 0).astype(np.uint8)
    return (mask - cv2.erode(mask, np.ones((3, 3), np.uint8))).astype(bool)


def _tile(rgb, foreground, rendered, pixels, weights, labels, joint_pixels, bones):
    import cv2

    image = np.ascontiguousarray(rgb.copy())
    if foreground is not None:
        image[_outline(foreground)] = (40, 220, 40)
    if rendered is not None:
        image[_outline(rendered)] = (230, 40, 230)
    radius = max(2, image.shape[0] // 160)
    for (a, b) in bones:
        if a in joint_pixels and b in joint_pixels:
            cv2.line(image, tuple(int(v) for v in joint_pixels[a]),
                     tuple(int(v) for v in joint_pixels[b]), (230, 40, 40), max(1, radius // 2))
    for k in range(len(labels)):
        if weights[k] > 0:
            cv2.circle(image, tuple(int(v) for v in pixels[k]), radius, (250, 230, 40), -1)
    for pixel in joint_pixels.values():
        cv2.circle(image, tuple(int(v) for v in pixel), radius, (230, 40, 40), 1)
    return image


def _picture(path: Path, rows: list) -> None:
    """Tiles (one row per frame set, one column per view) at a common height, as a PNG."""
    import cv2

    height = 360
    lines = []
    for tiles in rows:
        scaled = [cv2.resize(t, (max(1, round(t.shape[1] * height / t.shape[0])), height),
                             interpolation=cv2.INTER_AREA) for t in tiles]
        lines.append(np.hstack(scaled))
    width = max(line.shape[1] for line in lines)
    sheet = np.vstack([np.pad(line, ((0, 0), (0, width - line.shape[1]), (0, 0))) for line in lines])
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))


_BONES = (("left_shoulder", "right_shoulder"), ("left_hip", "right_hip"),
          ("left_shoulder", "left_hip"), ("right_shoulder", "right_hip"),
          *((f"{s}_shoulder", f"{s}_elbow") for s in ("left", "right")),
          *((f"{s}_elbow", f"{s}_wrist") for s in ("left", "right")),
          *((f"{s}_hip", f"{s}_knee") for s in ("left", "right")),
          *((f"{s}_knee", f"{s}_ankle") for s in ("left", "right")))


class _Scores:
    """One body's checks, accumulated over the frame sets where it has a pose."""

    def __init__(self, body: _Body, names: Sequence[str]):
        self.body = body
        self.labels = list(body.joints)
        self.names = list(names)
        self.reproj: dict[tuple[str, str], list[float]] = {(label, name): [] for label in self.labels
                                                           for name in self.names}
        self.gaps: dict[str, list[float]] = {label: [] for label in self.labels}
        self.ious: dict[str, list[float]] = {name: [] for name in self.names}
        self.n_pose = 0

    def add(self, found, cameras, pixels, weights, keypoints, foregrounds, params, min_views: int):
        """Score one frame set's pose ``found`` (:meth:`_Body.at`); returns its projected joints
        and rendered silhouettes (for the picture)."""
        from hmocap_ros.detection.keypoint_triangulation import TRIANGULATED_POINTS
        from hmocap_ros.geometry.projection import project_points
        from hmocap_ros.render import render_silhouettes

        self.n_pose += 1
        joints, vertices = found
        points = np.array([joints[label] for label in self.labels])
        projected = project_points(cameras, points)
        rendered: list[np.ndarray | None] = [None] * len(cameras)
        if vertices is not None:
            mesh = project_points(cameras, vertices)
            for k, camera in enumerate(cameras):
                if np.all(mesh.depth[k] > 0):
                    rendered[k] = render_silhouettes(mesh.pixels[k], self.body.model.faces,
                                                     camera.height, camera.width)
        for k, name in enumerate(self.names):
            for j, label in enumerate(self.labels):
                p = TRIANGULATED_POINTS.index(label)
                if weights[k, p] >= params.confident_visibility and projected.depth[k, j] > 0:
                    self.reproj[(label, name)].append(
                        float(np.linalg.norm(projected.pixels[k, j] - pixels[k, p])))
            silhouette, foreground = rendered[k], foregrounds[k]
            if silhouette is not None and foreground is not None:
                iou = silhouette_iou(silhouette, foreground)
                if iou is not None:
                    self.ious[name].append(iou)
        triangulated = dict(zip(keypoints.labels, zip(keypoints.positions, keypoints.views_used)))
        for label in self.labels:
            if label in triangulated and triangulated[label][1] >= min_views:
                self.gaps[label].append(1000.0 * float(np.linalg.norm(
                    triangulated[label][0] - joints[label])))
        return projected, rendered

    def summary(self) -> dict:
        """The body's figures (module docstring's JSON keys)."""
        every_error = [e for values in self.reproj.values() for e in values]
        every_gap = [g for values in self.gaps.values() for g in values]
        every_iou = [v for values in self.ious.values() for v in values]
        overall = _stats(every_error)
        labels, names = self.labels, self.names
        return {
            "body_id": self.body.motion.body_id,
            "frames_with_pose": self.n_pose,
            "reprojection_median_px": overall["median"],
            "reprojection_p90_px": overall["p90"],
            "silhouette_iou_mean": float(np.mean(every_iou)) if every_iou else None,
            "triangulation_gap_mm": _stats(every_gap)["median"],
            "keypoint_pairs": overall["count"],
            "triangulated_points": len(every_gap),
            "per_joint": {label: {"reprojection": _stats([e for n in names for e in self.reproj[(label, n)]]),
                                  "triangulation_gap_mm": _stats(self.gaps[label])} for label in labels},
            "per_view": {name: {"reprojection": _stats([e for label in labels
                                                        for e in self.reproj[(label, name)]]),
                                "silhouette_iou_mean": (float(np.mean(self.ious[name]))
                                                        if self.ious[name] else None)}
                         for name in names},
        }


def consistency_report(bag, motion, *, learn_from: str = "person_masks", min_views: int = 3,
                       max_frames: int | None = None, picture: Path | None = None,
                       progress=None) -> dict:
    """The checks of the module docstring for ``bag`` and the tracked bodies' ``motion`` (a
    :class:`~hmocap_ros.export.motion.BodyMotion`, or a list of them, the first body first)."""
    from hmocap_ros.detection.keypoint_triangulation import TRIANGULATED_POINTS, triangulate_views, view_keypoints
    from hmocap_ros.detection.params import KeypointParams
    from hmocap_ros.io import topics
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.image_codec import decoded_rgb
    from hmocap_ros.io.rig_messages import rig_from_msg
    from hmocap_ros.segmentation import ForegroundParams, background_models
    from hmocap_ros.segmentation.person_masks import PersonMasks

    motions = list(motion) if isinstance(motion, (list, tuple)) else [motion]
    params = KeypointParams()
    with BagReader(bag) as reader:
        available = reader.topics(compressed_as_raw=True)
        if topics.CAMERA_RIG not in available:
            raise ConsistencyError(f"{bag}: no {topics.CAMERA_RIG}: the cameras are unknown")
        rig = rig_from_msg(reader.first(topics.CAMERA_RIG))
        image_topics = [topics.camera_image(n) for n in rig.names]
        present = [t for t in image_topics if t in available]
        if not present:
            raise ConsistencyError(f"{bag}: none of the image topics {', '.join(image_topics)}")
        scores = [_Scores(_Body(m), rig.names) for m in motions]
        fg_models = background_models(ForegroundParams(learn_from=learn_from), rig.names)
        masks = PersonMasks(threads=params.threads)
        total = max(available[t].count for t in present)
        if max_frames is not None:
            total = min(total, max_frames)
        chosen = set(np.linspace(0, max(total - 1, 0), PICTURE_FRAMES).round().astype(int).tolist())
        n_frames = 0
        with_bodies: dict[int, int] = {}
        rows = []
        for stamp, msgs in reader.frame_sets(present, 0, allow_partial=True, min_topics=1):
            images = [decoded_rgb(msgs[t]) if t in msgs else None for t in image_topics]
            views: list[ViewLandmarks | None] = []
            foregrounds: list[np.ndarray | None] = []
            for k, (name, image) in enumerate(zip(rig.names, images)):
                if image is None or image.shape[:2] != (rig[k].height, rig[k].width):
                    views.append(None)
                    foregrounds.append(None)
                    continue
                foregrounds.append(fg_models[k].apply(image, int(stamp)))
                views.append(masks.segment(name, image)[0])
            pixels, weights = view_keypoints(rig.cameras, views, foregrounds, params)
            keypoints = triangulate_views(rig.cameras, views, foregrounds, None, params)
            n_frames += 1
            posed = 0
            tiles = []
            for b, body_scores in enumerate(scores):
                found = body_scores.body.at(stamp)
                if found is None:
                    continue
                posed += 1
                projected, rendered = body_scores.add(found, rig.cameras, pixels, weights, keypoints,
                                                      foregrounds, params, min_views)
                if b == 0 and picture is not None and n_frames - 1 in chosen:
                    labels = body_scores.labels
                    for k in range(len(rig)):
                        if images[k] is None:
                            continue
                        joint_pixels = {label: projected.pixels[k, j] for j, label in enumerate(labels)
                                        if projected.depth[k, j] > 0}
                        tiles.append(_tile(images[k], foregrounds[k], rendered[k], pixels[k],
                                           weights[k] * (weights[k] >= params.confident_visibility),
                                           TRIANGULATED_POINTS, joint_pixels, _BONES))
            with_bodies[posed] = with_bodies.get(posed, 0) + 1
            if tiles:
                rows.append(tiles)
            if progress is not None:
                progress(n_frames, total)
            if max_frames is not None and n_frames >= max_frames:
                break
    if picture is not None and rows:
        _picture(Path(picture), rows)
    bodies = [s.summary() for s in scores]
    first = {k: v for k, v in bodies[0].items()}
    return {
        "bag": str(bag),
        "tracked": str(motions[0].bag),
        **{k: first[k] for k in ("body_id", "frames_with_pose", "reprojection_median_px",
                                 "reprojection_p90_px", "silhouette_iou_mean",
                                 "triangulation_gap_mm", "keypoint_pairs", "triangulated_points")},
        "frames": n_frames,
        "min_views": int(min_views),
        "image_size": {name: [c.width, c.height] for name, c in zip(rig.names, rig)},
        "learn_from": learn_from,
        "per_joint": first["per_joint"],
        "per_view": first["per_view"],
        "bodies": [{k: v for k, v in body.items() if k not in ("per_joint", "per_view")}
                   for body in bodies],
        "frames_with_bodies": {str(k): v for k, v in sorted(with_bodies.items())},
    }


def _tracked_motions(path, name: str) -> list:
    """Every body slot of body_tracker's output bag ``path`` (those with a
    ``/humans/bodies/<id>/joint_states`` topic, the first body first), each a motion without
    frames where the tracker never followed anybody in it."""
    from hmocap_ros.export.motion import BodyMotion, ExportError, read_motion
    from hmocap_ros.io.bag_reader import BagReader

    with BagReader(path) as reader:
        available = reader.topics()
    if "/skeleton" not in available and "/humans/bodies/tracked" not in available:
        raise ConsistencyError(f"{name}: not body_tracker's output (no /skeleton, no "
                               f"/humans/bodies/tracked; make it with hmocap track)")
    slots = [m.group(1) for t in available
             if (m := re.fullmatch(r"/humans/bodies/([^/]+)/joint_states", t))]
    ids = sorted(slots, key=lambda b: (len(b), b)) or ["b0"]
    out = []
    for body in ids:
        try:
            out.append(read_motion(path, "tracked", body) if "/skeleton" in available else None)
        except ExportError:
            out.append(None)
        if out[-1] is None:
            out[-1] = BodyMotion(bag=Path(path), source="tracked", body_id=body,
                                 stamps_ns=np.zeros(0, np.int64), point_names=(),
                                 parents=np.zeros(0, int), points=np.zeros((0, 0, 3)),
                                 dof_stamps_ns=np.zeros(0, np.int64), dof_names=(),
                                 dofs=np.zeros((0, 0)))
    return out


def evaluate_consistency(bag, tracked=None, *, learn_from: str = "person_masks",
                         min_views: int = 3, max_frames: int | None = None,
                         picture: Path | None = None, progress=None) -> dict:
    """Track ``bag`` unless ``tracked`` is given, then :func:`consistency_report`.
    :class:`ConsistencyError` for bad input."""
    from hmocap_ros.eval.bag_tracking import TrackError, track_to_bag
    from hmocap_ros.export.motion import ExportError
    from hmocap_ros.io.bag_reader import BagReadError

    try:
        if tracked is None:
            with tempfile.TemporaryDirectory(prefix="hmocap_consistency_") as folder:
                out = Path(folder) / "tracked.mcap"
                tracking = track_to_bag(bag, out, max_frames=max_frames)
                motion = _tracked_motions(out, f"{bag} tracked")
        else:
            tracking = None
            motion = _tracked_motions(tracked, str(tracked))
    except (TrackError, ExportError, BagReadError) as error:
        raise ConsistencyError(str(error)) from None
    try:
        report = consistency_report(bag, motion, learn_from=learn_from, min_views=min_views,
                                    max_frames=max_frames, picture=picture, progress=progress)
    except BagReadError as error:
        raise ConsistencyError(str(error)) from None
    report["tracked"] = None if tracked is None else str(tracked)
    if tracking is not None:
        report["tracking"] = {"frame_sets": tracking["frame_sets"], "with_pose": tracking["with_pose"],
                              "silhouettes": tracking.get("silhouettes"), "notes": tracking["notes"]}
    return report
