"""Rig calibration: bundle adjustment on exact synthetic observations, a rendered session
against its true rig, and the bad inputs of ``hmocap calibrate``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hmocap_ros.calibration.board import BoardSpec
from hmocap_ros.calibration.bundle_adjustment import bundle_adjust
from hmocap_ros.calibration.observations import Observations
from hmocap_ros.calibration.pipeline import calibrate_rig
from hmocap_ros.calibration.room_frame import FLOOR_ROTATION
from hmocap_ros.cli import main as hmocap
from hmocap_ros.geometry.rig import load_rig
from hmocap_ros.geometry.rotations import rotation_angle_deg, rotvec_to_matrix
from hmocap_sim.calibration_path import board_poses
from hmocap_sim.mocap_rig import make_rig

BOARD = ["--board", "5x4", "--square", "0.3", "--marker", "0.21"]


def _synthetic(rig, spec, rng, floor_seconds=1.0):
    """Exact corner observations of a board lying on the floor for ``floor_seconds``, then
    carried until 12 s in front of ``rig``; one board pose per frame."""
    t = np.arange(0.0, 12.0, 0.5)
    R, o = board_poses(t, floor_seconds, spec.size_m, rng)
    pts = spec.corner_points()
    views = {}
    for i in range(len(t)):
        proj = rig.project(pts @ R[i].T + o[i])
        for k, cam in enumerate(rig):
            facing = (cam.R @ R[i][:, 2]) @ (cam.R @ o[i] + cam.t) > 0
            vis = proj.visible[k] & facing
            if vis.sum() >= 6:
                views.setdefault((k, i), []).append((np.flatnonzero(vis), proj.pixels[k][vis]))
    return Observations.from_views(views, len(rig), len(t)), R, o


def test_bundle_adjustment_recovers_perturbed_rig():
    rig = make_rig(3, 320, 240)
    spec = BoardSpec()
    rng = np.random.default_rng(3)
    obs, R_board, t_board = _synthetic(rig, spec, rng)
    K, R, t, D = rig.arrays()
    # World = camera 0's frame (the gauge the adjustment holds).
    R_w = R @ R[0].T
    t_w = t - np.einsum("kij,j->ki", R_w, t[0])
    Rb = np.einsum("ij,pjk->pik", R[0], R_board)
    tb = t_board @ R[0].T + t[0]
    R0 = rotvec_to_matrix(rng.normal(0, 0.02, (3, 3))) @ R_w
    R0[0] = np.eye(3)
    t0 = t_w + np.r_[[[0, 0, 0]], rng.normal(0, 0.05, (2, 3))]
    Rb0 = rotvec_to_matrix(rng.normal(0, 0.02, (len(Rb), 3))) @ Rb
    tb0 = tb + rng.normal(0, 0.05, tb.shape)
    result = bundle_adjust(obs, spec.corner_points(), 0, R0, t0, Rb0, tb0, K, D[:, :5])
    assert result.n_dropped == 0
    # exact corners: exact up to where the solver stops (see the floor-frame test below)
    assert np.abs(result.residuals).max() < 1e-4  # px
    assert np.abs(result.t_cam - t_w).max() < 1e-5  # m
    assert rotation_angle_deg(result.R_cam, R_w).max() < 1e-4


def test_bundle_adjustment_drops_the_corners_far_from_their_projection():
    """One corner in forty detected 15-40 px off (a marker misread): after the first pass the
    adjustment drops every such corner and solves again, which gives the exact rig back. The
    robust loss alone only bounds their pull: the rig it leaves is millimetres off."""
    rig = make_rig(3, 320, 240)
    spec = BoardSpec()
    rng = np.random.default_rng(3)
    obs, R_board, t_board = _synthetic(rig, spec, rng)
    K, R, t, D = rig.arrays()
    R_w = R @ R[0].T
    t_w = t - np.einsum("kij,j->ki", R_w, t[0])
    Rb = np.einsum("ij,pjk->pik", R[0], R_board)
    tb = t_board @ R[0].T + t[0]
    bad = rng.choice(len(obs.pixels), size=len(obs.pixels) // 40, replace=False)
    offset = rng.normal(size=(len(bad), 2))
    offset *= rng.uniform(15.0, 40.0, (len(bad), 1)) / np.linalg.norm(offset, axis=1, keepdims=True)
    pixels = obs.pixels.copy()
    pixels[bad] += offset
    misread = Observations(obs.camera, obs.pose, obs.corner, pixels, obs.n_cameras, obs.n_poses)
    result = bundle_adjust(misread, spec.corner_points(), 0, R_w, t_w, Rb, tb, K, D[:, :5])
    assert result.n_dropped == len(bad)
    assert np.abs(result.residuals).max() < 1e-4  # px
    assert np.abs(result.t_cam - t_w).max() < 1e-5  # m
    assert rotation_angle_deg(result.R_cam, R_w).max() < 1e-4


def test_floor_frames_as_one_board_pose_give_the_room_frame():
    rig = make_rig(4, 640, 480)
    spec = BoardSpec()
    obs, R_board, _ = _synthetic(rig, spec, np.random.default_rng(5), floor_seconds=2.0)
    floor = np.flatnonzero(np.all(np.isclose(R_board, FLOOR_ROTATION), axis=(1, 2)))
    assert len(floor) == 4 and len(np.unique(obs.camera[np.isin(obs.pose, floor)])) >= 2
    # All floor frames become board pose 0, as ``hmocap calibrate`` groups them.
    pose = np.full(obs.n_poses, -1)
    pose[floor] = 0
    carried = np.setdiff1d(np.arange(obs.n_poses), floor)
    pose[carried] = np.arange(1, len(carried) + 1)
    obs = Observations(obs.camera, pose[obs.pose], obs.corner, obs.pixels, obs.n_cameras,
                       len(carried) + 1)
    K, R, t, D = rig.arrays()
    solution = calibrate_rig(obs, spec.corner_points(), K, D[:, :5], list(rig.names), floor_pose=0)
    assert solution.cameras == [0, 1, 2, 3]
    # Noise-free corners: the solution is exact up to where the solver stops. The bundle
    # adjustment's inner LSMR steps and finite-difference Jacobian stop at a relative step of
    # about 1e-10, which lands within ~1e-6 deg / 1e-8 m of the truth, by an amount that
    # depends on the CPU's rounding. The bounds below hold that precision with a factor of
    # 100, and are still a thousand times finer than a calibration from real (0.1 px) corners.
    assert np.abs(solution.bundle.residuals).max() < 1e-4  # px
    assert np.abs(solution.t - t).max() < 1e-5  # m
    assert rotation_angle_deg(solution.R, R).max() < 1e-4
    assert rotation_angle_deg(solution.R_board[0], FLOOR_ROTATION) < 1e-4
    assert np.abs(solution.t_board[0]).max() < 1e-5


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    bag = tmp_path_factory.mktemp("cal") / "cal.mcap"
    assert hmocap(["sim", "calibration", "--cameras", "3", "--seconds", "10", "--fps", "2",
                   "--width", "320", "--height", "240", "--out", str(bag), "--quiet", *BOARD]) == 0
    return bag


def test_rendered_session_calibrates(session, tmp_path):
    out = tmp_path / "rig.yaml"
    assert hmocap(["calibrate", str(session), "--out", str(out), *BOARD]) == 0
    truth = load_rig(session.with_name("cal_rig.yaml"))
    estimated = load_rig(out)
    assert estimated.names == truth.names
    for cam in estimated:
        # a 10 s session at 320x240 places each camera within 2.5 cm: 11-13 mm measured with
        # OpenCV 5's ChArUco detector, 14-20 mm with OpenCV 4.6's older aruco functions
        assert np.linalg.norm(cam.position - truth[cam.name].position) < 0.025
        assert rotation_angle_deg(cam.R, truth[cam.name].R) < 1.0
    assert (tmp_path / "rig.report.txt").is_file() and (tmp_path / "rig.png").is_file()


def _rewrite(src: Path, dst: Path, image_for) -> None:
    """Copy a bag, with each camera image replaced by ``image_for(topic, rgb)``."""
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.bag_writer import LATCHED, VOLATILE, whole_bag
    from hmocap_ros.io.images import image_to_rgb, numpy_to_image
    from hmocap_ros.io.msg_factory import RosbagsFactory, stamp_to_ns
    from hmocap_ros.io.typestore import hmocap_typestore

    factory = RosbagsFactory(hmocap_typestore())
    with BagReader(src) as reader, whole_bag(dst) as bag:
        for name, info in reader.topics().items():
            bag.add_topic(name, info.msgtype, LATCHED if info.latched else VOLATILE)
        for item in reader.messages():
            if item.topic.endswith("/image_raw"):
                msg = item.msg
                msg = numpy_to_image(image_for(item.topic, image_to_rgb(msg)), "rgb8",
                                     stamp_to_ns(msg.header.stamp), msg.header.frame_id, factory)
                bag.write(item.topic, msg, item.log_time_ns)
            else:
                bag.write(item.topic, item.msg, item.log_time_ns)


def _fails(args, capsys, tmp_path) -> str:
    out = tmp_path / "rig.yaml"
    assert hmocap(["calibrate", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("rig")) == []
    return err


def test_bag_without_board(session, tmp_path, capsys):
    blank = tmp_path / "blank.mcap"
    _rewrite(session, blank, lambda topic, rgb: np.full_like(rgb, 128))
    assert "no ChArUco marker" in _fails([str(blank), *BOARD], capsys, tmp_path)


def test_board_of_other_dimensions(session, tmp_path, capsys):
    err = _fails([str(session), "--board", "7x5", "--square", "0.3", "--marker", "0.21"], capsys, tmp_path)
    assert "does not fit a 7x5" in err


def test_camera_never_seeing_the_board(session, tmp_path, capsys):
    blind = tmp_path / "blind.mcap"
    _rewrite(session, blind, lambda topic, rgb: np.full_like(rgb, 128) if topic == "/cam_1/image_raw" else rgb)
    out = tmp_path / "est.yaml"
    assert hmocap(["calibrate", str(blind), "--out", str(out), *BOARD]) == 0
    assert "cam_1: left out of the rig: never sees the board" in capsys.readouterr().out
    assert load_rig(out).names == ("cam_2", "cam_3")
    blind2 = tmp_path / "blind2.mcap"
    _rewrite(blind, blind2, lambda topic, rgb: np.full_like(rgb, 128) if topic == "/cam_2/image_raw" else rgb)
    for p in tmp_path.glob("est*"):
        p.unlink()
    err = _fails([str(blind2), *BOARD], capsys, tmp_path)
    assert "a rig needs 2" in err


def test_session_rendered_in_the_cameras_of_a_given_rig(tmp_path):
    from hmocap_ros.geometry.rig import save_rig

    given = make_rig(2, 160, 120)
    save_rig(given, tmp_path / "given.yaml")
    bag = tmp_path / "s.mcap"
    assert hmocap(["sim", "calibration", "--rig", str(tmp_path / "given.yaml"), "--cameras", "5",
                   "--seconds", "1", "--fps", "1", "--out", str(bag), "--quiet", *BOARD]) == 0
    truth = load_rig(tmp_path / "s_rig.yaml")
    assert truth.names == given.names and truth[0].width == 160
    for a, b in zip(truth, given):
        assert np.abs(a.position - b.position).max() < 1e-9 and np.abs(a.R - b.R).max() < 1e-12
    assert hmocap(["sim", "calibration", "--rig", str(tmp_path / "none.yaml"), "--seconds", "1",
                   "--out", str(tmp_path / "t.mcap"), "--quiet"]) == 2
