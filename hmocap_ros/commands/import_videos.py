"""``hmocap import videos CAM1.mp4 CAM2.mp4 ... --calibration FILE --out BAG``.

Synchronised video files and another tool's calibration (Pose2Sim/Anipose TOML, Qualisys QCA,
OpenCV/EasyMocap intri/extri, ROS camera_info YAML, or this package's rig YAML) into a bag in
the documented layout: camera images and camera_info, the latched ``/camera_rig`` and
``/tf_static`` (:mod:`hmocap_ros.video_import`). The calibration's world becomes the room frame
(+Y up, metres, floor at y = 0): its up axis and unit from the file, else from ``--up`` and
``--units``, else from the cameras, with a note. A progress bar goes to stderr; bad input (a
video that cannot be read, camera names, counts or image sizes that do not match, a calibration
missing a camera or in no known format) is one line on stderr and exit status 2, and no bag is
written.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_arguments", "main_from_args"]

PROG = "hmocap import videos"


def _list(text: str | None) -> tuple[str, ...] | None:
    return None if text is None else tuple(v.strip() for v in text.split(",") if v.strip())


def _rotations(items) -> dict:
    rotate = {}
    for item in items or ():
        name, _, degrees = item.rpartition("=")
        try:
            value = int(degrees)
        except ValueError:
            value = -1
        if not name or value not in (0, 90, 180, 270):
            raise ValueError(f"--rotate takes CAMERA=DEGREES with 0, 90, 180 or 270, got {item!r}")
        rotate[name] = value // 90
    return rotate


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from hmocap_ros.calibration.formats import AXES, FORMATS, UNITS

    parser.add_argument("videos", nargs="+", metavar="VIDEO", help="video files, one per camera")
    parser.add_argument("--calibration", required=True,
                        help="the cameras' calibration: file or folder in any supported format")
    parser.add_argument("--out", required=True, help="bag to write (.mcap, or a rosbag2 folder)")
    parser.add_argument("--names", default=None,
                        help="comma-separated calibration camera of each video (default: the "
                             "videos' file names, else the calibration's order)")
    parser.add_argument("--start", type=float, default=0.0,
                        help="seconds into the videos where the import starts (default 0)")
    parser.add_argument("--seconds", type=float, default=None,
                        help="seconds to import (default: to the end of the shortest video)")
    parser.add_argument("--scale", type=float, default=1.0,
                        help="resize the images by this factor, e.g. 0.5 (default 1)")
    parser.add_argument("--offsets", default=None,
                        help="comma-separated frame offset of each video: its frame start+o+i "
                             "joins frame set i (default: all 0, sync by frame index)")
    parser.add_argument("--rotate", action="append", metavar="CAMERA=DEG",
                        help="a video turned by DEG (90, 180, 270) clockwise from its calibration's "
                             "image (repeatable)")
    parser.add_argument("--no-upright", dest="upright", action="store_false",
                        help="keep the frames as decoded (default: turn each camera by quarter "
                             "turns so that the room's up is the image's up)")
    parser.add_argument("--format", dest="calibration_format", choices=tuple(FORMATS), default=None,
                        help="the calibration's format (default: from its content)")
    parser.add_argument("--up", default=None, metavar="AXIS",
                        help=f"the calibration world's up axis ({', '.join(AXES)}; default: what "
                             f"the file says, else the cameras' image-up direction)")
    parser.add_argument("--units", choices=tuple(UNITS), default=None,
                        help="the calibration's length unit (default: what the file says, else "
                             "from the cameras' spread)")
    parser.add_argument("--floor", type=float, default=0.0,
                        help="the floor's height along the up axis in the calibration's unit "
                             "(default 0: the origin is on the floor)")
    parser.add_argument("--no-compress", dest="compress", action="store_false",
                        help="write the bag's chunks uncompressed (faster, about twice the size)")
    parser.add_argument("--raw", dest="raw_images", action="store_true",
                        help="write the images raw (sensor_msgs/Image rgb8 on /<camera>/image_raw; "
                             "default: JPEG sensor_msgs/CompressedImage on /<camera>/image_raw/compressed, "
                             "as image_transport's compressed transport; docs/real_sensors.md "
                             "compares the two)")
    parser.add_argument("--jpeg-quality", type=int, default=90, metavar="Q",
                        help="JPEG quality of the images, 1-100 (default 90)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def main_from_args(ns: argparse.Namespace) -> int:
    from tqdm import tqdm

    from hmocap_ros.video_import import ImportOptions, VideoImportError, import_videos

    out = Path(ns.out)
    bar = None

    def progress(done: int, total: int | None) -> None:
        nonlocal bar
        if bar is None:
            bar = tqdm(total=total, desc=f"importing {out.name}", unit="set", file=sys.stderr,
                       disable=ns.quiet, dynamic_ncols=True)
        bar.update(1)

    try:
        if out.exists():
            raise ValueError(f"{out} exists already; refusing to overwrite it")
        offsets = _list(ns.offsets)
        options = ImportOptions(
            names=_list(ns.names), start=ns.start, seconds=ns.seconds, scale=ns.scale,
            offsets=None if offsets is None else tuple(int(v) for v in offsets),
            rotate=_rotations(ns.rotate), upright=ns.upright,
            calibration_format=ns.calibration_format, up=ns.up, units=ns.units, floor=ns.floor,
            compress=ns.compress, raw_images=ns.raw_images, jpeg_quality=ns.jpeg_quality)
        result = import_videos(ns.videos, ns.calibration, out, options, progress)
    except (VideoImportError, ValueError) as error:
        if bar is not None:
            bar.close()
        print(f"{PROG}: {error}", file=sys.stderr)
        return 2
    if bar is not None:
        bar.close()
    plan = result.plan
    for note in plan.notes:
        print(f"{PROG}: note: {note}", file=sys.stderr)
    for warning in plan.warnings:
        print(f"{PROG}: warning: {warning}", file=sys.stderr)
    frames = result.frame_sets * result.cameras
    size = out.stat().st_size if out.is_file() else sum(p.stat().st_size for p in out.rglob("*"))
    camera = plan.rig[0]
    print(f"{out}: {result.frame_sets} frame sets x {result.cameras} cameras "
          f"({', '.join(plan.rig.names)}) at {camera.width}x{camera.height}, {plan.fps:g} fps, "
          f"{size / 1e6:.1f} MB")
    print(f"  {result.wall_seconds:.1f} s, {frames / max(result.wall_seconds, 1e-9):.1f} frames/s "
          f"({result.frame_sets / max(result.wall_seconds, 1e-9):.1f} frame sets/s); process CPU "
          f"{1e3 * result.cpu_seconds / max(frames, 1):.1f} ms per frame")
    return 0
