"""Synchronised videos and another tool's calibration into a multi-view bag (no rclpy).

:func:`plan_import` matches the videos with the calibration's cameras, reads the calibration into
the room frame (:mod:`hmocap_ros.calibration.formats`), fits each camera to its video's frames
(:mod:`.camera_fit`: turned, scaled or cut) and turns it upright, cuts views a few pixels larger
than the others to their size (:func:`~.camera_fit.common_size`: the tracker stacks the views'
silhouettes, so a frame set's views share one size), and settles which frames make the frame
sets; :func:`import_videos` writes the bag. The bag is in the documented layout
(:mod:`hmocap_ros.io.topics`), as ``hmocap sim mocap`` writes it without the ground truth:

* ``/camera_rig`` (latched ``hmocap_interfaces/CameraRig``) and ``/tf_static`` (latched: the room
  frame to each camera's optical frame), at the first frame set's stamp;
* per frame set and camera ``/<camera>/image_raw/compressed`` (sensor_msgs/CompressedImage,
  JPEG at ``jpeg_quality``, as image_transport's ``compressed`` transport publishes it), or with
  ``raw_images`` ``/<camera>/image_raw`` (rgb8), and ``/<camera>/camera_info``, all stamped
  ``BASE_STAMP_NS + frame / fps`` (the first video's frame index and rate) and logged at that
  stamp. The package's readers take both kinds alike (:mod:`hmocap_ros.io.bag_reader`); a
  replay sends the topics as stored, for nodes with ``image_transport:=compressed``.

Matching: ``names`` gives the calibration's camera of each video; without it, each video's file
stem when every stem is a calibration camera, else the calibration's cameras in order when the
counts are equal. A camera's name in the bag is its calibration name made a valid ROS name
(other characters become ``_``; a name that does not start with a letter gets ``cam_`` before
it). Synchronisation is by frame index: frame set ``i`` holds frame ``s + o_k + i`` of video
``k``, ``s`` the first video's frame at ``start`` seconds and ``o_k`` its offset in frames.
Videos of different lengths are imported to the shortest, videos of different rates at the
first one's rate, each with a warning that names them.
"""
from __future__ import annotations

import dataclasses
import functools
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from hmocap_ros.video_import.camera_fit import (
    CameraFitError,
    common_size,
    crop_camera,
    fit_camera,
    rotate_camera,
    upright_turns,
)
from hmocap_ros.video_import.videos import FrameSetReader, VideoError, VideoInfo, probe_video

if TYPE_CHECKING:
    from hmocap_ros.geometry.rig import Rig

__all__ = ["BASE_STAMP_NS", "ImportOptions", "ImportPlan", "ImportResult", "VideoImportError",
           "bag_camera_name", "import_videos", "plan_import"]

#: Stamp of a video's frame 0 in the bag (the simulator's base stamp).
BASE_STAMP_NS = 1_700_000_000_000_000_000
#: Largest relative difference between two videos' frame rates that is not reported.
_RATE_TOLERANCE = 1e-3


class VideoImportError(ValueError):
    """Bad input of an import (one line for the user)."""


@dataclass(frozen=True)
class ImportOptions:
    """What ``hmocap import videos`` takes besides the files (module docstring).

    names: the calibration camera of each video, or None; start, seconds: the part imported
    (seconds; None: to the end); scale: the factor the images are resized by (<= 1);
    offsets: frames added to each video's index, or None; rotate: calibration camera name ->
    clockwise quarter turns from the calibration's image to the video's; upright: turn each
    camera so that the room's up is the image's up; calibration_format, up, units, floor: how
    to read the calibration (:func:`hmocap_ros.calibration.formats.load_calibration_rig`);
    compress: zstd-compress the bag's chunks; raw_images: write sensor_msgs/Image rgb8 instead
    of JPEG CompressedImage; jpeg_quality: the JPEG quality (1-100).
    """

    names: tuple[str, ...] | None = None
    start: float = 0.0
    seconds: float | None = None
    scale: float = 1.0
    offsets: tuple[int, ...] | None = None
    rotate: dict = field(default_factory=dict)
    upright: bool = True
    calibration_format: str | None = None
    up: str | None = None
    units: str | None = None
    floor: float = 0.0
    compress: bool = True
    raw_images: bool = False
    jpeg_quality: int = 90


@dataclass(frozen=True, eq=False)
class ImportPlan:
    """The frame sets to import: the bag's rig (cameras in video order), the videos, the first
    frame of each, the number of sets, the frame rate, the quarter turns each video's frames
    are turned by, the notes and warnings for the user, and the size ``(width, height)`` all
    turned frames are cut to (None: none is cut)."""

    rig: Rig
    videos: tuple[VideoInfo, ...]
    first: tuple[int, ...]
    count: int
    fps: float
    turns: tuple[int, ...]
    notes: tuple[str, ...]
    warnings: tuple[str, ...]
    cut: tuple[int, int] | None = None

    def stamp_ns(self, frame_set: int) -> int:
        """The stamp of frame set ``frame_set``: :data:`BASE_STAMP_NS` plus the time of its frame
        in the first video (module docstring)."""
        return BASE_STAMP_NS + int(round((self.first[0] + frame_set) * 1e9 / self.fps))


@dataclass(frozen=True)
class ImportResult:
    """What :func:`import_videos` wrote: frame sets, and the wall and process CPU seconds of
    decoding, converting and writing them (the checks before excluded)."""

    bag: Path
    frame_sets: int
    cameras: int
    wall_seconds: float
    cpu_seconds: float
    plan: ImportPlan


def bag_camera_name(name: str) -> str:
    """A calibration camera's name as a ROS name token (module docstring)."""
    token = re.sub(r"[^A-Za-z0-9_]", "_", str(name))
    return token if token[:1].isalpha() else f"cam_{token}"


def _match(videos: list[VideoInfo], calibration_names: tuple[str, ...],
           names: tuple[str, ...] | None, notes: list) -> list[str]:
    """The calibration camera of each video (module docstring)."""
    if names is not None:
        if len(names) != len(videos):
            raise VideoImportError(f"{len(videos)} videos and {len(names)} names (--names)")
        missing = [n for n in names if n not in calibration_names]
        if missing:
            raise VideoImportError(f"the calibration has no camera {', '.join(map(repr, missing))} "
                                   f"(its cameras: {', '.join(calibration_names)})")
        chosen = list(names)
    else:
        stems = [v.path.name.split(".")[0] for v in videos]
        if all(s in calibration_names for s in stems):
            chosen = stems
        elif len(videos) == len(calibration_names):
            chosen = list(calibration_names)
            notes.append("videos matched with the calibration's cameras in order: "
                         + ", ".join(f"{v.path.name} = {n}" for v, n in zip(videos, chosen)))
        else:
            unknown = [s for s in stems if s not in calibration_names]
            raise VideoImportError(
                f"{len(videos)} videos and {len(calibration_names)} calibrated cameras, and "
                f"{', '.join(map(repr, unknown))} name no camera of the calibration "
                f"({', '.join(calibration_names)}): give --names")
    twice = sorted({n for n in chosen if chosen.count(n) > 1})
    if twice:
        raise VideoImportError(f"camera(s) {', '.join(twice)} given to several videos")
    left = [n for n in calibration_names if n not in chosen]
    if left:
        notes.append(f"calibrated cameras without a video, left out: {', '.join(left)}")
    return chosen


def _frames(videos: list[VideoInfo], options: ImportOptions, warnings: list) -> tuple:
    """(first frame per video, number of frame sets, frame rate)."""
    fps = videos[0].fps
    slower = [v.path.name for v in videos if abs(v.fps - fps) > _RATE_TOLERANCE * fps]
    if slower:
        warnings.append(f"frame rates differ ({', '.join(f'{v.path.name} {v.fps:g}' for v in videos)}"
                        f" fps): synchronised by frame index at {fps:g} fps")
    offsets = options.offsets or (0,) * len(videos)
    if len(offsets) != len(videos):
        raise VideoImportError(f"{len(videos)} videos and {len(offsets)} offsets (--offsets)")
    if options.start < 0 or (options.seconds is not None and options.seconds <= 0):
        raise VideoImportError("--start must be >= 0 and --seconds > 0")
    start = int(round(options.start * fps))
    first = [start + int(o) for o in offsets]
    bad = [v.path.name for v, f in zip(videos, first) if f < 0]
    if bad:
        raise VideoImportError(f"the offsets put {', '.join(bad)} before its first frame")
    left = [v.frames - f if v.frames else None for v, f in zip(videos, first)]
    known = [n for n in left if n is not None]
    count = min(known) if known else None
    if count is not None and count <= 0:
        raise VideoImportError(f"--start {options.start:g} s is past the end of "
                               f"{', '.join(v.path.name for v, n in zip(videos, left) if n is not None and n <= 0)}")
    if known and len(set(known)) > 1:
        shortest = [v.path.name for v, n in zip(videos, left) if n == count]
        lengths = ", ".join(f"{v.path.name} {n}" for v, n in zip(videos, left) if n is not None)
        warnings.append(f"the videos have different lengths ({lengths} "
                        f"frames from the start): imported to the shortest ({', '.join(shortest)})")
    if options.seconds is not None:
        wanted = max(1, int(round(options.seconds * fps)))
        count = wanted if count is None else min(count, wanted)
    return tuple(first), count if count is not None else 2**31 - 1, fps


def plan_import(video_paths, calibration, options: ImportOptions = ImportOptions()) -> ImportPlan:
    """Check the inputs and settle the frame sets (module docstring);
    :class:`VideoImportError` (one line) for anything that does not fit."""
    from hmocap_ros.calibration.formats import CalibrationFormatError, load_calibration_rig, read_calibration
    from hmocap_ros.geometry.rig import Rig

    if not video_paths:
        raise VideoImportError("no videos")
    if not 0 < options.scale <= 1:
        raise VideoImportError(f"--scale must be in (0, 1], got {options.scale:g}")
    notes: list[str] = []
    warnings: list[str] = []
    try:
        videos = [probe_video(p) for p in video_paths]
        foreign = read_calibration(calibration, options.calibration_format)
        chosen = _match(videos, foreign.names, options.names, notes)
        sizes = {name: (v.width, v.height) for name, v in zip(chosen, videos)}
        room_rig, rig_notes = load_calibration_rig(
            calibration, format=options.calibration_format, up=options.up, units=options.units,
            floor=options.floor, sizes=sizes)
    except (VideoError, CalibrationFormatError) as error:
        raise VideoImportError(str(error)) from None
    notes += rig_notes
    unknown = sorted(set(options.rotate) - set(chosen))
    if unknown:
        raise VideoImportError(f"--rotate names {', '.join(unknown)}, which has no video")
    cameras, turns = [], []
    bag_names = [bag_camera_name(n) for n in chosen]
    if len(set(bag_names)) < len(bag_names):
        raise VideoImportError(f"the cameras {', '.join(chosen)} give the same ROS names "
                               f"{', '.join(bag_names)}")
    for name, bag_name, video in zip(chosen, bag_names, videos):
        try:
            camera, note = fit_camera(room_rig[name], (video.width, video.height),
                                      int(options.rotate.get(name, 0)))
        except CameraFitError as error:
            raise VideoImportError(f"{video.path.name}: {error}") from None
        if note:
            notes.append(f"{name}: {note}")
        k = upright_turns(camera) if options.upright else 0
        if k:
            camera = rotate_camera(camera, k)
            notes.append(f"{name}: frames turned {90 * k} deg clockwise so that the room's up is up")
        cameras.append(dataclasses.replace(camera, name=bag_name, frame_id=""))
        turns.append(k)
    cut = common_size(cameras)
    if cut is not None:
        cut_names = [c.name for c in cameras if (c.width, c.height) != cut]
        cameras = [crop_camera(c, *cut) if c.name in cut_names else c for c in cameras]
        notes.append(f"{', '.join(cut_names)}: cut to {cut[0]}x{cut[1]} at the right and bottom, "
                     f"the size of the other views")
    if options.scale != 1:
        cameras = [c.scaled(options.scale) for c in cameras]
    first, count, fps = _frames(videos, options, warnings)
    return ImportPlan(Rig(room_rig.frame_id, tuple(cameras)), tuple(videos), first, count, fps,
                      tuple(turns), tuple(notes), tuple(warnings), cut)


_ROTATIONS = {1: cv2.ROTATE_90_CLOCKWISE, 2: cv2.ROTATE_180, 3: cv2.ROTATE_90_COUNTERCLOCKWISE}


def _rgb(frame: np.ndarray, turns: int, camera, cut: tuple[int, int] | None = None) -> np.ndarray:
    """A decoded BGR frame as the camera's RGB image: turned, cut to ``cut`` (width, height)
    at the right and bottom, resized, converted."""
    if turns:
        frame = cv2.rotate(frame, _ROTATIONS[turns])
    if cut is not None:
        frame = frame[:cut[1], :cut[0]]
    if frame.shape[:2] != (camera.height, camera.width):
        frame = cv2.resize(frame, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
    return cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)


def _write_latched(writer, factory, rig, stamp: int) -> None:
    from hmocap_ros.io import topics
    from hmocap_ros.io.bag_writer import LATCHED
    from hmocap_ros.io.rig_messages import rig_to_msg
    from hmocap_ros.io.tf import TF_MESSAGE_TYPE, TF_STATIC_TOPIC, rig_transforms, tf_message

    writer.add_topic(topics.CAMERA_RIG, "hmocap_interfaces/msg/CameraRig", LATCHED)
    writer.add_topic(TF_STATIC_TOPIC, TF_MESSAGE_TYPE, LATCHED)
    writer.write(topics.CAMERA_RIG, rig_to_msg(rig, stamp, factory), stamp)
    writer.write(TF_STATIC_TOPIC, tf_message(rig_transforms(rig), stamp, factory), stamp)


def import_videos(video_paths, calibration, out, options: ImportOptions = ImportOptions(),
                  progress=None) -> ImportResult:
    """Write the bag ``out`` of the videos (module docstring); ``progress``: called with the
    number of frame sets written so far and the total (None when unknown) after each set.
    :class:`VideoImportError` for bad input; the bag is written whole or not at all."""
    from hmocap_ros.io import topics
    from hmocap_ros.io.bag_writer import BagWriteError, whole_bag
    from hmocap_ros.io.camera_info import dict_to_camera_info
    from hmocap_ros.io.compressed_images import numpy_to_compressed
    from hmocap_ros.io.image_codec import transport_topic
    from hmocap_ros.io.images import numpy_to_image
    from hmocap_ros.io.msg_factory import RosbagsFactory
    from hmocap_ros.io.typestore import hmocap_typestore

    plan = plan_import(video_paths, calibration, options)
    rig = plan.rig
    factory = RosbagsFactory(hmocap_typestore())
    infos = [c.to_camera_info_dict() for c in rig]
    if not 1 <= options.jpeg_quality <= 100:
        raise VideoImportError(f"the JPEG quality must be 1 to 100, got {options.jpeg_quality}")
    transport = "raw" if options.raw_images else "compressed"
    image_topics = [transport_topic(topics.camera_image(c.name), transport) for c in rig]
    info_topics = [f"/{c.name}/camera_info" for c in rig]
    written = 0
    total = plan.count if plan.count < 2**31 - 1 else None
    wall0, cpu0 = time.perf_counter(), time.process_time()
    try:
        with whole_bag(out, compress=options.compress) as writer:
            convert = [functools.partial(_rgb, turns=k, camera=c, cut=plan.cut)
                       for k, c in zip(plan.turns, rig)]
            with FrameSetReader([v.path for v in plan.videos], list(plan.first), plan.count,
                                convert) as reader:
                for images in reader:
                    stamp = plan.stamp_ns(written)
                    if written == 0:
                        _write_latched(writer, factory, rig, stamp)
                    for k, (camera, image) in enumerate(zip(rig, images)):
                        if options.raw_images:
                            msg = numpy_to_image(image, "rgb8", stamp, camera.frame_id, factory)
                        else:
                            msg = numpy_to_compressed(image, "jpeg", stamp, camera.frame_id, factory,
                                                      quality=options.jpeg_quality)
                        writer.write(image_topics[k], msg, stamp)
                        writer.write(info_topics[k], dict_to_camera_info(infos[k], stamp, factory), stamp)
                    written += 1
                    if progress is not None:
                        progress(written, total)
                ended = reader.ended_early
            if written == 0:
                raise VideoImportError("no frame set could be read from the videos")
    except VideoError as error:
        raise VideoImportError(str(error)) from None
    except BagWriteError as error:
        raise VideoImportError(str(error)) from None
    warnings = list(plan.warnings)
    if ended and total is not None:
        warnings.append(f"{', '.join(p.name for p in ended)} ended after {written} of {total} frame "
                        f"sets (the container's frame count was wrong)")
    plan = dataclasses.replace(plan, count=written, warnings=tuple(warnings))
    return ImportResult(Path(out), written, len(rig), time.perf_counter() - wall0,
                        time.process_time() - cpu0, plan)
