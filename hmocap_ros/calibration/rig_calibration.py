"""The camera rig from a gathered calibration session (of a bag or of live topics).

Checks the board's views against the configured board, takes or estimates each camera's
intrinsics (:mod:`~hmocap_ros.calibration.initialisation`), places the cameras and refines
everything by bundle adjustment (:mod:`~hmocap_ros.calibration.pipeline`), sets the room frame
(:mod:`~hmocap_ros.calibration.room_frame`), and writes the rig YAML
(:mod:`hmocap_ros.geometry.rig` format), ``<stem>.report.txt`` and ``<stem>.png``, each whole or
not at all.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from hmocap_ros.calibration.session import CalibrationSession

__all__ = ["calibrate_session"]

_SLOP_NS = 10_000_000  # images of one frame set: stamps within 10 ms
_MAX_FIT_PX = 3.0  # homography residual of a view of the configured board


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


def _intrinsics(intrinsics: str, session, names, seen, grouped, corner_points, log):
    """Per camera K (3, 3) and D (5,): from the bag's camera_info when given and of the
    images' size, else estimated from its board views. Returns (K, D, any estimated)."""
    from hmocap_ros.calibration.initialisation import estimate_intrinsics

    K = np.zeros((len(names), 3, 3))
    D = np.zeros((len(names), 5))
    estimated = False
    for c, name in enumerate(names):
        given = session.intrinsics.get(name) if intrinsics == "camera_info" else None
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


def calibrate_session(session: CalibrationSession, source: Path | str, *, out: Path | str,
                      room_frame: str, floor_seconds: float, intrinsics: str,
                      log: Callable[[str], None] = print) -> tuple[Path, Path, Path]:
    """The rig from a gathered :class:`~hmocap_ros.calibration.session.CalibrationSession`
    (of a bag or of live topics, named ``source``): board checks, intrinsics, placement,
    bundle adjustment, room frame, and the files written. ``room_frame`` is ``"floor"`` (the
    board lying on the floor during the first ``floor_seconds``) or a camera's name;
    ``intrinsics`` ``"camera_info"`` takes each camera's intrinsics from the session where
    given, anything else estimates them. Returns the rig YAML, the report and the picture."""
    from hmocap_ros.calibration.observations import Observations
    from hmocap_ros.calibration.pipeline import calibrate_rig
    from hmocap_ros.calibration.report import camera_rows, report_text
    from hmocap_ros.geometry import PinholeCamera
    from hmocap_ros.geometry.rig import Rig

    spec, out = session.spec, Path(out)
    views = _check_board(session, spec, source)
    names = session.names
    seen = {c: sum(1 for v in views if v[0] == c) for c in range(len(names))}
    for c, name in enumerate(names):
        log(f"  {name}: board in {seen[c]} of {session.n_images.get(c, 0)} images")
    use_floor = room_frame == "floor"
    grouped, n_poses = _group_views(session, views, floor_seconds, use_floor)
    obs = Observations.from_views(grouped, len(names), n_poses)
    corner_points = spec.corner_points()
    K, D, estimated = _intrinsics(intrinsics, session, names, seen, grouped, corner_points, log)
    room_camera = None
    if not use_floor:
        if room_frame not in names:
            raise ValueError(f"--room-frame {room_frame!r}: not floor nor a camera of "
                             f"{source} ({', '.join(names)})")
        room_camera = names.index(room_frame)
    elif not any(k[1] == 0 for k in grouped):
        raise ValueError(f"{source}: no camera sees the board on the floor in the first "
                         f"{floor_seconds:g} s; lay it there or give --room-frame CAMERA")
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
    room = "board on the floor" if use_floor else f"camera {room_frame}"
    text = report_text(rows, total, room)
    report_path, picture_path = _write_outputs(out, rig, text, solution, source, room, total)
    log(text.rstrip())
    return out, report_path, picture_path
