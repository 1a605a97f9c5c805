"""``hmocap render overlay``'s reading and writing: a bag in, one picture per frame, a video out.

Two kinds of bag (:func:`bag_kind`):

- **multi-view** (the rig on ``/camera_rig``, images on ``/<camera>/image_raw``): every frame set
  of images (grouped by stamp, as the tracker groups them) with the tracked skeletons of that
  stamp (``/skeleton``, one message per body: body_tracker's output, recorded or written by
  ``hmocap track``), the labelled extremities (``/extremities``) and, where the bag (or the
  ``truth`` bag) has it, the ground truth (``/ground_truth/skeleton``, and
  ``/ground_truth/body_<k>/skeleton`` for the other people of a simulated room): each body's
  per-joint errors against the person whose truth lies nearest it in that frame set (mean joint
  distance), matched by joint name (:func:`hmocap_ros.eval.metrics.match_joints`); the subject's
  truth is drawn;
- **depth** (``/depth/image_raw``, no rig): every depth frame with the detected gestures of its
  stamp (``/gestures``) and the true ones (``/ground_truth/gestures``).

The outputs (skeletons, gestures) may come from another bag than the images (``outputs``: the
recording of the nodes, or a bag that ``hmocap track`` wrote); they are matched by stamp.
What is missing (no rig, no images, no outputs) raises :class:`OverlayError` with one line
naming it. :func:`write_pictures` writes a video that browsers play inline (H.264 in MP4, or
VP9 in WebM, by the ffmpeg that ``imageio-ffmpeg`` carries; MJPEG AVI by OpenCV) or a folder
of PNGs; :func:`render_overlay` does the whole (tracking the bag first when asked), for the
command and the demo. Each camera's tile is drawn at its recorded size unless a width is given.
"""

from __future__ import annotations

import itertools
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader, BagReadError
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.viz.overlay import (
    BODY_COLOURS,
    EXTREMITY_COLOUR,
    GESTURE_COLOUR,
    TRUTH_COLOUR,
    Banner,
    BodyDrawing,
    DepthGesture,
    depth_picture,
    multiview_picture,
)

__all__ = ["EXTREMITIES", "GESTURES", "SKELETON", "OverlayError", "Picture", "bag_kind", "depth_pictures",
           "multiview_pictures", "render_overlay", "write_pictures"]

SKELETON = "/skeleton"
EXTREMITIES = "/extremities"
GESTURES = "/gestures"
#: Largest stamp difference (ns) between an output and its frame set (body_tracker's slop).
SLOP_NS = 5_000_000
#: Video file suffix -> codec: ffmpeg encoders (imageio-ffmpeg) for MP4 and WebM, OpenCV's fourcc for AVI.
VIDEO_SUFFIXES = {".mp4": "libx264", ".webm": "libvpx-vp9", ".avi": "MJPG"}


class OverlayError(ValueError):
    """A bag cannot be drawn: the text names what is missing, in one line."""


@dataclass
class Picture:
    """One frame's picture (RGB uint8) and its stamp."""

    stamp_ns: int
    image: np.ndarray


def _topics(path: Path) -> dict:
    try:
        with BagReader(path) as reader:
            return reader.topics(compressed_as_raw=True)
    except BagReadError as err:
        raise OverlayError(str(err)) from err


def bag_kind(path: Path) -> str:
    """``multiview`` or ``depth`` (module docstring); OverlayError when the bag has neither a
    rig with camera images nor depth images."""
    available = _topics(path)
    images = sorted(t for t in available if t.endswith("/image_raw") and t != topics.DEPTH_IMAGE)
    if topics.CAMERA_RIG in available:
        return "multiview"
    if images:
        raise OverlayError(f"{path}: no {topics.CAMERA_RIG} (the cameras' calibration, needed to project "
                           f"the skeleton onto {', '.join(images[:4])}{' ...' if len(images) > 4 else ''})")
    if topics.DEPTH_IMAGE in available:
        return "depth"
    raise OverlayError(f"{path}: no images to draw on: neither {topics.CAMERA_RIG} with camera images "
                       f"nor {topics.DEPTH_IMAGE}")


def _by_stamp(path: Path, topic: str) -> dict[int, list]:
    out: dict[int, list] = {}
    with BagReader(path) as reader:
        if topic in reader.topics():
            for m in reader.messages([topic]):
                out.setdefault(stamp_to_ns(m.msg.header.stamp), []).append(m.msg)
    return out


def _other_people_truth(path: Path) -> list[str]:
    """The skeleton truth topics of the people beside the subject in ``path``
    (``/ground_truth/body_<k>/skeleton``, k = 1, 2, ...), in order."""
    from hmocap_ros.eval.people_truth import person_topic

    available = _topics(path)
    out: list[str] = []
    while person_topic(topics.GT_SKELETON, len(out) + 1) in available:
        out.append(person_topic(topics.GT_SKELETON, len(out) + 1))
    return out


def _near(by_stamp: dict[int, list], stamps: np.ndarray, stamp: int) -> list:
    """The messages of ``stamp``, else of the nearest stamp within :data:`SLOP_NS`."""
    if stamp in by_stamp:
        return by_stamp[stamp]
    if not len(stamps):
        return []
    k = int(np.clip(np.searchsorted(stamps, stamp), 1, len(stamps) - 1)) if len(stamps) > 1 else 0
    best = min({k, max(k - 1, 0)}, key=lambda i: abs(int(stamps[i]) - stamp))
    return by_stamp[int(stamps[best])] if abs(int(stamps[best]) - stamp) <= SLOP_NS else []


def _points(msg) -> np.ndarray:
    return np.array([[p.x, p.y, p.z] for p in msg.positions], np.float64).reshape(-1, 3)


def _body(msg, truths: Sequence, colour_index: int | None = None) -> BodyDrawing:
    """A tracked skeleton's drawing, its joints' errors (mm) against the truth in ``truths``
    (one skeleton per person) whose mean joint distance to it is the smallest."""
    from hmocap_ros.eval.metrics import match_joints

    joints = _points(msg)
    errors = None
    for truth in truths:
        mine = np.full(len(joints), np.nan)
        i, j = match_joints(list(msg.joint_names), list(truth.joint_names))
        mine[i] = 1000.0 * np.linalg.norm(joints[i] - _points(truth)[j], axis=1)
        if errors is None or np.nanmean(mine) < np.nanmean(errors):
            errors = mine
    return BodyDrawing(str(msg.body_id), joints, [int(p) for p in msg.parents], errors, colour_index)


def multiview_pictures(bag: Path, outputs: Path | None = None, truth: Path | None = None,
                       tile_width: int | None = None, max_frames: int | None = None) -> Iterator[Picture]:
    """The pictures of a multi-view bag (module docstring), each camera's tile ``tile_width``
    wide (default: the widest camera's recorded width); OverlayError for what is missing."""
    from hmocap_ros.geometry.rig import RigError
    from hmocap_ros.io.conversions import ConversionError
    from hmocap_ros.io.image_codec import decoded_rgb
    from hmocap_ros.io.rig_messages import rig_from_msg

    outputs = outputs or bag
    truth = truth or bag
    available = _topics(bag)
    with BagReader(bag) as reader:
        rig_msg = reader.first(topics.CAMERA_RIG) if topics.CAMERA_RIG in available else None
    if rig_msg is None:
        raise OverlayError(f"{bag}: no {topics.CAMERA_RIG} (the cameras' calibration)")
    try:
        rig = rig_from_msg(rig_msg)
    except (RigError, ValueError) as err:
        raise OverlayError(f"{bag}: {topics.CAMERA_RIG}: {err}") from err
    image_topics = [topics.camera_image(n) for n in rig.names]
    present = [t for t in image_topics if t in available]
    if not present:
        raise OverlayError(f"{bag}: no camera images ({', '.join(image_topics)})")
    skeletons = _by_stamp(outputs, SKELETON)
    if not skeletons:
        raise OverlayError(f"{outputs}: no tracked skeletons ({SKELETON}, body_tracker's output): "
                           f"record it, or track on the fly with --track")
    extremities = _by_stamp(outputs, EXTREMITIES)
    truths = _by_stamp(truth, topics.GT_SKELETON)
    sk_stamps, ex_stamps, gt_stamps = (np.array(sorted(d), np.int64) for d in (skeletons, extremities, truths))
    others = [_by_stamp(truth, t) for t in _other_people_truth(truth)]
    others_stamps = [np.array(sorted(d), np.int64) for d in others]
    tile_width = tile_width or max(camera.width for camera in rig.cameras)
    # one legend and one colour per body for the whole video: every picture of it has the same size
    body_ids = sorted({str(m.body_id) for msgs in skeletons.values() for m in msgs}, key=lambda b: (len(b), b))
    colour_index = {body_id: k for k, body_id in enumerate(body_ids)}
    keys = multiview_keys(body_ids, bool(truths), bool(extremities))
    first = None
    with BagReader(bag) as reader:
        for n, (stamp, msgs) in enumerate(reader.frame_sets(present, SLOP_NS, allow_partial=True, min_topics=1)):
            if max_frames is not None and n >= max_frames:
                return
            first = stamp if first is None else first
            images = []
            for topic in image_topics:
                try:
                    images.append(decoded_rgb(msgs[topic]) if topic in msgs else None)
                except ConversionError:
                    images.append(None)
            gt_msgs = _near(truths, gt_stamps, stamp)
            gt = gt_msgs[0] if gt_msgs else None
            people = ([gt] if gt is not None else []) + [
                near[0] for near in (_near(d, st, stamp) for d, st in zip(others, others_stamps)) if near]
            bodies = [_body(msg, people, colour_index[str(msg.body_id)])
                      for msg in _near(skeletons, sk_stamps, stamp)]
            ex = _near(extremities, ex_stamps, stamp)
            ex_points = (list(ex[0].labels), _points(ex[0])) if ex and len(ex[0].labels) else None
            detail = "  ".join(
                f"{b.body_id}" + (f": mean joint error {np.nanmean(b.errors_mm):.0f} mm"
                                  if b.errors_mm is not None and np.isfinite(b.errors_mm).any() else "")
                for b in bodies) or "no body tracked"
            banner = Banner(f"{bag.name}  t = {(stamp - first) * 1e-9:6.2f} s", detail,
                            legend=gt is not None and bool(bodies),
                            keys=keys)
            truth_body = BodyDrawing("truth", _points(gt), [int(p) for p in gt.parents]) if gt is not None else None
            yield Picture(stamp, multiview_picture(rig.cameras, images, bodies, banner, truth_body, ex_points,
                                                   tile_width))


def depth_pictures(bag: Path, outputs: Path | None = None, truth: Path | None = None,
                   width: int = 640, max_frames: int | None = None) -> Iterator[Picture]:
    """The pictures of a depth bag (module docstring); OverlayError for what is missing."""
    from hmocap_ros.io.conversions import ConversionError, depth_image_to_metres

    outputs = outputs or bag
    truth = truth or bag
    detected = _by_stamp(outputs, GESTURES)
    if not detected:
        raise OverlayError(f"{outputs}: no gesture detections ({GESTURES}, gesture_detection's output): "
                           f"record it, or write it with hmocap detect gestures")
    true = _by_stamp(truth, topics.GT_GESTURES)
    info = None
    with BagReader(bag) as reader:
        if topics.DEPTH_INFO in reader.topics():
            info = reader.first(topics.DEPTH_INFO)
    fx = float(info.k[0]) if info is not None and info.k[0] > 0 else None
    keys = depth_keys(bool(true))
    det_stamps, gt_stamps = (np.array(sorted(d), np.int64) for d in (detected, true))
    first = None
    with BagReader(bag) as reader:
        for n, m in enumerate(reader.messages([topics.DEPTH_IMAGE])):
            if max_frames is not None and n >= max_frames:
                return
            stamp = stamp_to_ns(m.msg.header.stamp)
            first = stamp if first is None else first
            try:
                depth = depth_image_to_metres(m.msg)
            except ConversionError:
                continue
            found = [DepthGesture(g.u, g.v, g.name, float(g.score), g.position.z if g.position_valid else 0.0)
                     for msg in _near(detected, det_stamps, stamp) for g in msg.gestures]
            held = [DepthGesture(g.u, g.v, g.name, None, g.position.z if g.position_valid else 0.0)
                    for msg in _near(true, gt_stamps, stamp) for g in msg.gestures]
            detail = ", ".join(f"{g.name} {g.score:.2f}" for g in found) or "no gesture detected"
            if held:
                detail += "   truth: " + ", ".join(g.name for g in held)
            banner = Banner(f"{bag.name}  t = {(stamp - first) * 1e-9:6.2f} s", detail, keys=keys)
            yield Picture(stamp, depth_picture(depth, found, held, banner, fx, width))


def frame_rate(stamps: list[int], default: float = 25.0) -> float:
    """Frames per second of stamps (the median interval), for a video that plays in real time."""
    steps: np.ndarray = np.diff(np.asarray(stamps, np.int64))
    steps = steps[steps > 0]
    return float(np.clip(1e9 / np.median(steps), 1.0, 120.0)) if len(steps) else default


def write_pictures(pictures: Iterator[Picture], out: Path, fps: float | None = None) -> tuple[int, Path]:
    """Write the pictures to ``out``: a video for a name ending in one of :data:`VIDEO_SUFFIXES`
    (``fps``: default the stamps' rate), else a folder of ``frame_NNNNN.png``. Returns the count
    and the path; OverlayError when no picture came or the video cannot be written. A video is
    written beside ``out`` and takes its name only once complete."""
    out = Path(out)
    if fps is None:  # the rate of the first frames, then on as they come
        pictures = iter(pictures)
        head = list(itertools.islice(pictures, 10))
        fps = frame_rate([p.stamp_ns for p in head])
        pictures = itertools.chain(head, pictures)
    suffix = out.suffix.lower()
    count = 0
    if suffix not in VIDEO_SUFFIXES:
        for picture in pictures:
            out.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(out / f"frame_{count:05d}.png"), np.ascontiguousarray(picture.image[:, :, ::-1]))
            count += 1
    else:
        partial = out.with_name(f".{out.stem}.partial{out.suffix}")
        writer: _Video | None = None
        try:
            size = None
            for picture in pictures:
                if writer is None:
                    size = (picture.image.shape[0] // 2 * 2, picture.image.shape[1] // 2 * 2)
                    out.parent.mkdir(parents=True, exist_ok=True)
                    writer = _Video(partial, suffix, size[1], size[0], fps)
                assert size is not None  # set with the writer
                writer.write(_fitted(picture.image, size))
                count += 1
            if writer is not None:
                writer.close()
                partial.replace(out)
        finally:
            if writer is not None:
                writer.abandon()
            partial.unlink(missing_ok=True)
    if count == 0:
        raise OverlayError(f"nothing to draw: no frame in the bag (nothing written to {out})")
    return count, out


def _fitted(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``image`` cropped or padded (black, at the bottom and right) to ``size`` (height, width):
    every frame of a video has the first one's size."""
    if image.shape[:2] == size:
        return image
    out = np.zeros((*size, 3), np.uint8)
    h, w = min(size[0], image.shape[0]), min(size[1], image.shape[1])
    out[:h, :w] = image[:h, :w]
    return out


class _Video:
    """A video being written: H.264 MP4 or VP9 WebM through imageio-ffmpeg's ffmpeg (yuv420p,
    ``+faststart``: browsers and chat tools play it inline), MJPEG AVI through OpenCV."""

    def __init__(self, path: Path, suffix: str, width: int, height: int, fps: float):
        self.path = path
        self._cv = None
        self._ffmpeg = None
        codec = VIDEO_SUFFIXES[suffix]
        if suffix == ".avi":
            self._cv = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*codec), fps, (width, height))
            if not self._cv.isOpened():
                raise OverlayError(f"{path}: OpenCV cannot write {codec} here; give a .mp4 name, or a folder "
                                   f"to write PNG frames")
            return
        try:
            import imageio_ffmpeg
        except ImportError as err:
            raise OverlayError(f"{path}: writing {suffix} needs imageio-ffmpeg (pip install imageio-ffmpeg; "
                               f"make setup installs it), or give a folder to write PNG frames") from err
        quality = ["-crf", "20", "-preset", "veryfast"] if suffix == ".mp4" else ["-crf", "32", "-b:v", "0"]
        self._ffmpeg = imageio_ffmpeg.write_frames(
            str(path), (width, height), fps=fps, codec=codec, pix_fmt_in="rgb24", pix_fmt_out="yuv420p",
            quality=None, macro_block_size=2, ffmpeg_log_level="error",
            output_params=[*quality, *(["-movflags", "+faststart"] if suffix == ".mp4" else [])])
        self._ffmpeg.send(None)

    def write(self, rgb: np.ndarray) -> None:
        if self._cv is not None:
            self._cv.write(np.ascontiguousarray(rgb[:, :, ::-1]))
            return
        assert self._ffmpeg is not None  # one of the two writers is open
        try:
            self._ffmpeg.send(np.ascontiguousarray(rgb))
        except (OSError, RuntimeError) as err:
            raise OverlayError(f"{self.path}: ffmpeg failed: {err}") from err

    def close(self) -> None:
        """Finish the file (the encoder flushes its last frames)."""
        if self._cv is not None:
            self._cv.release()
            self._cv = None
        if self._ffmpeg is not None:
            ffmpeg, self._ffmpeg = self._ffmpeg, None
            try:
                ffmpeg.close()
            except (OSError, RuntimeError) as err:
                raise OverlayError(f"{self.path}: ffmpeg failed: {err}") from err

    def abandon(self) -> None:
        """Stop writing (a no-op after :meth:`close`)."""
        try:
            self.close()
        except OverlayError:
            pass


def multiview_keys(body_ids: Sequence[str], truth: bool, extremities: bool) -> list[tuple[tuple[int, int, int], str]]:
    """The legend of a multi-view video, the same on every picture: what each colour means
    (:class:`~hmocap_ros.viz.overlay.Banner`): each of ``body_ids`` in its colour (by its place in
    the list, :data:`~hmocap_ros.viz.overlay.BODY_COLOURS`), and the ground truth and the
    extremities where the bag has them. With the truth, the joints are coloured by their error
    (the scale at the banner's right)."""
    tracked = "tracked, joints by error" if truth else "tracked"
    keys = [(BODY_COLOURS[k % len(BODY_COLOURS)], f"{body_id} {tracked}") for k, body_id in enumerate(body_ids)]
    if truth:
        keys.append((TRUTH_COLOUR, "ground truth"))
    if extremities:
        keys.append((EXTREMITY_COLOUR, "x detected body parts"))
    return keys


def depth_keys(truth: bool) -> list[tuple[tuple[int, int, int], str]]:
    """The legend of a depth picture."""
    return [(GESTURE_COLOUR, "detected gesture, score")] + ([(TRUTH_COLOUR, "true gesture")] if truth else [])


def render_overlay(bag, out, *, outputs=None, truth=None, track: bool = False, overrides: dict | None = None,
                   width: int | None = None, fps: float | None = None, max_frames: int | None = None,
                   progress=None) -> tuple[int, Path]:
    """Draw ``bag`` into ``out`` (``hmocap render overlay``, :mod:`hmocap_ros.commands.render_overlay`):
    the skeletons and gestures of ``bag`` or of ``outputs`` (of a tracking run on the fly with
    ``track``), the truth of ``bag`` or ``truth``; returns the pictures written and the path.
    :class:`OverlayError` for bad input."""
    bag = Path(bag)
    kind = bag_kind(bag)
    with tempfile.TemporaryDirectory(prefix="hmocap_overlay_") as tmp:
        if track:
            if kind != "multiview":
                raise OverlayError(f"{bag}: --track needs a multi-view bag (a rig and camera images)")
            from hmocap_ros.eval.bag_tracking import TrackError, track_to_bag

            outputs = Path(tmp) / "tracked.mcap"
            if progress is not None:
                progress(f"tracking {bag.name} ...")
            try:
                counts = track_to_bag(bag, outputs, max_frames=max_frames, overrides=overrides, progress=progress)
            except TrackError as err:
                raise OverlayError(str(err)) from err
            if not counts["with_pose"]:
                raise OverlayError(f"{bag}: the tracker found nobody in its {counts['frame_sets']} frame sets")
        outputs = Path(outputs) if outputs is not None else None
        truth = Path(truth) if truth is not None else None
        for path in (outputs, truth):
            if path is not None and not path.exists():
                raise OverlayError(f"{path}: does not exist")
        if kind == "multiview":
            pictures = multiview_pictures(bag, outputs, truth, tile_width=width, max_frames=max_frames)
        else:
            pictures = depth_pictures(bag, outputs, truth, width=width or 640, max_frames=max_frames)
        return write_pictures(_reported(pictures, progress), Path(out), fps)


def _reported(pictures, progress, period_s: float = 5.0):
    """``pictures`` passed on, with ``progress("N pictures drawn")`` every ``period_s`` seconds."""
    last = time.monotonic()
    for k, picture in enumerate(pictures):
        if progress is not None and time.monotonic() - last >= period_s:
            last = time.monotonic()
            progress(f"{k} pictures drawn")
        yield picture
