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
import re
import sys
from pathlib import Path

import numpy as np

from hmocap_ros.calibration.rig_calibration import calibrate_session

__all__ = ["add_arguments", "main_from_args", "run_calibration", "run_live_calibration"]

_IMAGE_TOPIC = re.compile(r"^/(.+)/image_raw$")


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


def _session_options(ns: argparse.Namespace) -> dict:
    """The options of :func:`~hmocap_ros.calibration.rig_calibration.calibrate_session`."""
    return {"out": ns.out, "room_frame": ns.room_frame, "floor_seconds": ns.floor_seconds,
            "intrinsics": ns.intrinsics}


def run_calibration(ns: argparse.Namespace, log=print) -> tuple[Path, Path, Path]:
    """The whole command on a bag (module docstring) but the error handling; returns the
    files written."""
    from hmocap_ros.calibration.board import board_from_args

    spec = board_from_args(ns)
    if ns.every < 1:
        raise ValueError("--every must be 1 or more")
    bag = Path(ns.bag)
    session = _read(bag, spec, ns.every, log)
    return calibrate_session(session, bag, **_session_options(ns), log=log)


def run_live_calibration(ns: argparse.Namespace, ros_args: list | None = None,
                         log=print) -> tuple[Path, Path, Path]:
    """``--live``: the session from the cameras' topics, then the same calibration."""
    from hmocap_ros.calibration.board import board_from_args
    from hmocap_ros.nodes.calibration_collector import collect_live

    session = collect_live(ns, board_from_args(ns), ros_args or [], log)
    return calibrate_session(session, "live topics", **_session_options(ns), log=log)


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
