"""``hmocap calibrate BAG --out rig.yaml``: the camera rig from a bag of a ChArUco board
(``hmocap calibrate --live --out rig.yaml``: from the cameras' topics,
:mod:`~hmocap_ros.nodes.calibration_collector`).

Reads every ``/<cam>/image_raw`` of the bag, detects the board's corners
(:mod:`hmocap_ros.calibration.detection`), takes each camera's intrinsics from the bag
(``/camera_rig`` or ``/<cam>/camera_info``) or estimates them, places the cameras
(:mod:`~hmocap_ros.calibration.initialisation`), refines everything by bundle adjustment
(:mod:`~hmocap_ros.calibration.bundle_adjustment`) and sets the room frame from the board lying
on the floor during the first ``--floor-seconds`` (:mod:`~hmocap_ros.calibration.room_frame`).
Writes the rig YAML (:mod:`hmocap_ros.geometry.rig` format), ``<stem>.report.txt`` and ``<stem>.png``
(the cameras in the room from above and from the side). Progress goes to stdout.

Bad input (no board in the bag, a board of other dimensions than configured, fewer than two
cameras that can be placed) is one line on stderr and exit status 2, and nothing is written;
a camera that never sees the board is named and left out of the rig.
"""

from __future__ import annotations

import argparse
import functools
import os
import re
import sys
from pathlib import Path

import numpy as np

__all__ = ["add_arguments", "main_from_args", "run_calibration", "run_live_calibration",
           "calibrate_session"]

_IMAGE_TOPIC = re.compile(r"^/(.+)/image_raw$")
_SLOP_NS = 10_000_000  # images of one frame set: stamps within 10 ms
_MAX_FIT_PX = 3.0  # homography residual of a view of the configured board


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from hmocap_ros.calibration.board import add_board_arguments

    parser.add_argument("bag", nargs="?", help=".mcap file or rosbag2 directory (or --live)")
    parser.add_argument("--out", type=Path, required=True,
                        help="rig YAML to write; <stem>.report.txt and <stem>.png go beside it")
    add_board_arguments(parser)
    parser.add_argument("--intrinsics", choices=("camera_info", "estimate"), default="camera_info",
                        help="camera_info: from the bag's /camera_rig or /<cam>/camera_info, estimated "
                             "for a camera that has neither; estimate: from the board views "
                             "(default camera_info)")
    parser.add_argument("--floor-seconds", type=float, default=1.0,
                        help="the board lies on the floor for this many seconds at the start: it "
                             "defines the room frame (default 1)")
    parser.add_argument("--room-frame", default="floor",
                        help="floor (default): from the board on the floor; or a camera name: its "
                             "centre is the origin, its image up is +Y")
    parser.add_argument("--every", type=int, default=1,
                        help="use every Nth image of each camera of the bag (default 1: all)")
    live = parser.add_argument_group("live topics (instead of a bag)")
    live.add_argument("--live", action="store_true",
                      help="collect the session from the cameras' /<cam>/image_raw topics")
    live.add_argument("--cameras", default=None,
                      help="cameras, comma-separated (cam_1,cam_2,...); default: every "
                           "/<cam>/image_raw topic found")
    live.add_argument("--seconds", type=float, default=60.0,
                      help="collect for this many seconds from the first frame set (default 60)")
    live.add_argument("--fps", type=float, default=3.0,
                      help="frame sets searched for the board per second, at most (default 3)")
    live.add_argument("--min-views", type=int, default=0,
                      help="stop early once every camera has seen the board this many times "
                           "(default 0: run for --seconds)")


def _read(bag: Path, spec, every: int, log):
    """The session of a bag: its cameras, given intrinsics and the board in its images."""
    from hmocap_ros.calibration.session import CalibrationSession
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.camera_info import camera_info_to_dict
    from hmocap_ros.io.image_codec import decoded_rgb
    from hmocap_ros.io.msg_factory import stamp_to_ns
    from hmocap_ros.io.rig_messages import rig_from_msg

    with BagReader(bag) as reader:
        topics = reader.topics(compressed_as_raw=True)
        camera_of = {t: m.group(1) for t, info in topics.items()
                     if (m := _IMAGE_TOPIC.match(t))
                     and info.msgtype in ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")}
        image_topics = sorted(camera_of)
        if not image_topics:
            raise ValueError(f"{bag}: no /<camera>/image_raw topics of sensor_msgs/Image (nor their /compressed)")
        session = CalibrationSession([camera_of[t] for t in image_topics], spec)
        if "/camera_rig" in topics:
            for cam in rig_from_msg(reader.first("/camera_rig")):
                session.intrinsics[cam.name] = (cam.K, cam.D, cam.width, cam.height, "/camera_rig")
        for name in session.names:
            if f"/{name}/camera_info" in topics:
                info = camera_info_to_dict(reader.first(f"/{name}/camera_info"))
                session.intrinsics[name] = (np.asarray(info["K"]).reshape(3, 3),
                                            np.asarray(info["D"], float), int(info["width"]),
                                            int(info["height"]), f"/{name}/camera_info")
        index = {t: k for k, t in enumerate(image_topics)}
        counts = np.zeros(len(image_topics), int)
        total = sum(topics[t].count for t in image_topics)
        log(f"reading {bag}: {total} images of {len(image_topics)} cameras "
            f"({', '.join(session.names)}), using every {every}")
        done = 0
        for item in reader.messages(image_topics):
            k = index[item.topic]
            counts[k] += 1
            if (counts[k] - 1) % every:
                continue
            session.add_image(k, stamp_to_ns(item.msg.header.stamp), decoded_rgb(item.msg))
            done += 1
            if done % 200 == 0:
                log(f"  {done} images searched for the board")
    return session


def _check_board(session, spec, bag) -> list:
    """Views that fit the board; raises ValueError for no board or a board of other dimensions."""
    from hmocap_ros.calibration.detection import MIN_CORNERS, corner_fit_error

    with_markers = [d for _, _, d in session.detections if len(d.marker_ids)]
    if not with_markers:
        raise ValueError(f"{bag}: no ChArUco marker of {spec.dictionary} in any of the "
                         f"{len(session.detections)} images: is the board in view, is --dict right?")
    foreign = sum(bool(np.any(d.marker_ids >= spec.n_markers)) for d in with_markers)
    views = [(c, s, d) for c, s, d in session.detections if d.n >= MIN_CORNERS]
    fits = np.array([corner_fit_error(spec, d) for _, _, d in views])
    bad = int(np.sum(fits > _MAX_FIT_PX))
    if foreign > 0.2 * len(with_markers) or (len(views) and bad > 0.3 * len(views)) or not views:
        top = max(int(d.marker_ids.max()) for d in with_markers)
        raise ValueError(
            f"{bag}: the board seen does not fit a {spec.describe()} board (markers up to id {top}, "
            f"the board has {spec.n_markers}; {bad} of {len(views)} views off the board's geometry "
            f"by more than {_MAX_FIT_PX:g} px): check --board, --square, --marker and --dict")
    return [v for v, f in zip(views, fits) if f <= _MAX_FIT_PX]


def _group_views(session, views, floor_seconds: float, use_floor: bool) -> tuple[dict, int]:
    """Detections grouped by (camera, board pose): pose 0 is the board lying on the floor
    (every image of the first ``floor_seconds`` when the room frame comes from it), then one
    pose per frame set. Returns the groups and the number of poses."""
    stamps = np.array(sorted({s for _, s, _ in session.detections}))
    frame_of = dict(zip(stamps, np.concatenate([[0], np.cumsum(np.diff(stamps) > _SLOP_NS)])))
    floor_end = stamps[0] + int(floor_seconds * 1e9)
    pose_of: dict = {}
    grouped: dict = {}
    for c, s, d in views:
        f = frame_of[s]
        key = 0 if (use_floor and s < floor_end) else pose_of.setdefault(f, len(pose_of) + 1)
        grouped.setdefault((c, key), []).append((d.ids, d.pixels))
    return grouped, len(pose_of) + 1


def _intrinsics(ns, session, names, seen, grouped, corner_points, log):
    """Per camera K (3, 3) and D (5,): from the bag's camera_info when given and of the
    images' size, else estimated from its board views. Returns (K, D, any estimated)."""
    from hmocap_ros.calibration.initialisation import estimate_intrinsics

    K = np.zeros((len(names), 3, 3))
    D = np.zeros((len(names), 5))
    estimated = False
    for c, name in enumerate(names):
        given = session.intrinsics.get(name) if ns.intrinsics == "camera_info" else None
        if given is not None and c in session.sizes and given[2:4] != session.sizes[c]:
            log(f"  {name}: {given[4]} is for {given[2]}x{given[3]} images, the images are "
                f"{session.sizes[c][0]}x{session.sizes[c][1]}: estimating instead")
            given = None
        if given is not None:
            K[c], D[c] = given[0], np.pad(given[1].ravel(), (0, 5))[:5]
            log(f"  {name}: intrinsics from {given[4]}")
        elif seen[c]:
            own = [v for (cc, _), items in grouped.items() if cc == c for v in items]
            try:
                K[c], D[c], rms = estimate_intrinsics(corner_points, own, session.sizes[c])
            except ValueError as err:
                raise ValueError(f"{name}: {err}") from None
            estimated = True
            log(f"  {name}: intrinsics estimated, fx {K[c, 0, 0]:.1f} fy {K[c, 1, 1]:.1f}, "
                f"RMS {rms:.3f} px")
    return K, D, estimated


def _write_outputs(out: Path, rig, text: str, solution, source, room: str,
                   total: float) -> tuple[Path, Path]:
    """The rig YAML, the report and the picture, each written whole or not at all."""
    from hmocap_ros.calibration.report import save_rig_picture
    from hmocap_ros.geometry.rig import save_rig

    label = Path(str(source)).name
    stem = out.name[:-len(out.suffix)] if out.suffix else out.name
    report_path, picture_path = out.with_name(f"{stem}.report.txt"), out.with_name(f"{stem}.png")
    tmp = [p.with_name(f".{p.name}.partial") for p in (out, report_path, picture_path)]
    try:
        save_rig(rig, tmp[0], header=f"Calibrated by hmocap calibrate from {label}; {room}; "
                                     f"reprojection RMS {total:.3f} px.")
        tmp[1].write_text(text)
        save_rig_picture(tmp[2].with_suffix(".png"), list(rig.names), solution.R, solution.t,
                         solution.t_board, f"{label}: {len(rig)} cameras, RMS {total:.3f} px")
        os.replace(tmp[2].with_suffix(".png"), picture_path)
        os.replace(tmp[1], report_path)
        os.replace(tmp[0], out)
    finally:
        for p in (*tmp, tmp[2].with_suffix(".png")):
            p.unlink(missing_ok=True)
    return report_path, picture_path


def run_calibration(ns: argparse.Namespace, log=print) -> tuple[Path, Path, Path]:
    """The whole command on a bag (module docstring) but the error handling; returns the
    files written."""
    from hmocap_ros.calibration.board import board_from_args

    spec = board_from_args(ns)
    if ns.every < 1:
        raise ValueError("--every must be 1 or more")
    bag = Path(ns.bag)
    session = _read(bag, spec, ns.every, log)
    return calibrate_session(ns, session, bag, log)


def calibrate_session(ns: argparse.Namespace, session, source: Path | str,
                      log=print) -> tuple[Path, Path, Path]:
    """The rig from a gathered :class:`~hmocap_ros.calibration.session.CalibrationSession`
    (of a bag or of live topics, named ``source``): board checks, intrinsics, placement,
    bundle adjustment, room frame, and the files written."""
    from hmocap_ros.calibration.observations import Observations
    from hmocap_ros.calibration.pipeline import calibrate_rig
    from hmocap_ros.calibration.report import camera_rows, report_text
    from hmocap_ros.geometry import PinholeCamera
    from hmocap_ros.geometry.rig import Rig

    spec, out = session.spec, Path(ns.out)
    views = _check_board(session, spec, source)
    names = session.names
    seen = {c: sum(1 for v in views if v[0] == c) for c in range(len(names))}
    for c, name in enumerate(names):
        log(f"  {name}: board in {seen[c]} of {session.n_images.get(c, 0)} images")
    use_floor = ns.room_frame == "floor"
    grouped, n_poses = _group_views(session, views, ns.floor_seconds, use_floor)
    obs = Observations.from_views(grouped, len(names), n_poses)
    corner_points = spec.corner_points()
    K, D, estimated = _intrinsics(ns, session, names, seen, grouped, corner_points, log)
    room_camera = None
    if not use_floor:
        if ns.room_frame not in names:
            raise ValueError(f"--room-frame {ns.room_frame!r}: not floor nor a camera of "
                             f"{source} ({', '.join(names)})")
        room_camera = names.index(ns.room_frame)
    elif not any(k[1] == 0 for k in grouped):
        raise ValueError(f"{source}: no camera sees the board on the floor in the first "
                         f"{ns.floor_seconds:g} s; lay it there or give --room-frame CAMERA")
    log("placing the cameras")
    solution = calibrate_rig(obs, corner_points, K, D, names, floor_pose=0 if use_floor else None,
                             room_camera=room_camera, refine_intrinsics=estimated, log=log)
    for c, why in solution.left_out.items():
        log(f"  {names[c]}: left out of the rig: {why}")
    cameras = []
    for j, c in enumerate(solution.cameras):
        w, h = session.sizes[c]
        cameras.append(PinholeCamera(name=names[c], width=w, height=h, K=solution.K[j],
                                     D=solution.D[j], R=solution.R[j], t=solution.t[j]))
    rig = Rig("room", tuple(cameras))
    rows = camera_rows(names, solution, session.n_images, seen)
    total = float(np.sqrt(np.mean(np.sum(solution.bundle.residuals ** 2, axis=1))))
    room = "board on the floor" if use_floor else f"camera {ns.room_frame}"
    text = report_text(rows, total, room)
    report_path, picture_path = _write_outputs(out, rig, text, solution, source, room, total)
    log(text.rstrip())
    return out, report_path, picture_path


def run_live_calibration(ns: argparse.Namespace, ros_args: list | None = None,
                         log=print) -> tuple[Path, Path, Path]:
    """``--live``: the session from the cameras' topics, then the same calibration."""
    from hmocap_ros.calibration.board import board_from_args
    from hmocap_ros.nodes.calibration_collector import collect_live

    session = collect_live(ns, board_from_args(ns), ros_args or [], log)
    return calibrate_session(ns, session, "live topics", log)


def main_from_args(ns: argparse.Namespace, ros_args: list | None = None) -> int:
    from hmocap_ros.calibration.pipeline import CalibrationError
    from hmocap_ros.geometry.rig import RigError
    from hmocap_ros.io.bag_reader import BagReadError

    if bool(ns.bag) == bool(ns.live):
        print("hmocap calibrate: give a bag or --live (not both)", file=sys.stderr)
        return 2
    try:
        log = functools.partial(print, flush=True)
        out, report, picture = (run_live_calibration(ns, ros_args, log) if ns.live
                                else run_calibration(ns, log))
    except (BagReadError, CalibrationError, RigError, ValueError) as err:
        print(f"hmocap calibrate: {err}", file=sys.stderr)
        return 2
    except OSError as err:
        print(f"hmocap calibrate: cannot write {ns.out}: {err.strerror or err}", file=sys.stderr)
        return 2
    print(f"wrote {out}, {report}, {picture}")
    return 0
