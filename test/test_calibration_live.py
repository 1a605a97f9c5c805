"""``hmocap calibrate --live``: frame sets grouped by stamp, and a simulated session replayed
over DDS calibrated from the topics, against the true rig and the same bag calibrated offline."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from hmocap_ros.calibration.live_collection import FrameSetCollector, enough_views
from hmocap_ros.cli import main as hmocap
from hmocap_ros.geometry.rig import load_rig
from hmocap_ros.geometry.rotations import rotation_angle_deg
from hmocap_ros.processes import NodeProcess, loopback_dds_env

BOARD = ["--board", "5x4", "--square", "0.3", "--marker", "0.21"]
N_FRAMES = 22  # 1 s on the floor + 10 s carried, at 2 fps


def test_frame_sets_complete_in_any_order_and_keep_their_spacing():
    collector = FrameSetCollector(3, slop_ns=10, min_interval_ns=250)
    out = []
    # Stamps 0, 100, ..., 900; camera 2 misses stamp 300; images arrive a little out of order.
    arrivals = [(k, s + (k == 1) * 3) for s in range(0, 1000, 100) for k in (2, 0, 1)
                if not (k == 2 and s == 300)]
    arrivals[4], arrivals[5] = arrivals[5], arrivals[4]
    for k, s in arrivals:
        out += collector.add(k, s, f"img{k}@{s}")
    # 300 incomplete; 100, 200, 500, 600, 800 too close; 900 waits for the next frame (jitter)
    assert [s for s, _ in out] == [0, 400, 700]
    assert out[1][1] == ["img0@400", "img1@403", "img2@400"]
    assert collector.n_complete == 8 and collector.n_skipped == 5
    assert collector.n_dropped == 2  # the images of 300
    assert collector.add(0, 705, "late") == [] and collector.n_dropped == 3
    with pytest.raises(ValueError):
        collector.add(3, 1000, "no such camera")
    assert not enough_views(np.array([5, 4]), 5) and enough_views(np.array([5, 6]), 5)
    assert not enough_views(np.array([9, 9]), 0)


def test_live_needs_a_bag_or_live(capsys, tmp_path):
    assert hmocap(["calibrate", "--out", str(tmp_path / "rig.yaml")]) == 2
    assert "give a bag or --live" in capsys.readouterr().err


def test_live_without_images_is_one_line_and_writes_nothing(capsys, tmp_path):
    out = tmp_path / "rig.yaml"
    assert hmocap(["calibrate", "--live", "--cameras", "nobody_1,nobody_2", "--seconds", "1",
                   "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no frame set of nobody_1, nobody_2" in err, err
    assert "no image from nobody_1, nobody_2" in err
    assert list(tmp_path.iterdir()) == []
    assert hmocap(["calibrate", "--live", "--cameras", "cam_1", "--out", str(out)]) == 2
    assert "2 or more distinct cameras" in capsys.readouterr().err


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    bag = tmp_path_factory.mktemp("live") / "cal.mcap"
    assert hmocap(["sim", "calibration", "--cameras", "3", "--seconds", "10", "--fps", "2",
                   "--width", "320", "--height", "240", "--out", str(bag), "--quiet", *BOARD]) == 0
    return bag


def test_live_calibration_of_a_replayed_session(session, tmp_path):
    env = loopback_dds_env()
    out = tmp_path / "live.yaml"
    with NodeProcess.module("calibrate", "hmocap_ros.cli",
                            ["calibrate", "--live", "--cameras", "cam_1,cam_2,cam_3", "--seconds", "6",
                             "--fps", "10", "--out", str(out), *BOARD], env, tmp_path) as cal:
        assert cal.wait_for_output("collecting frame sets", 30), cal.output()
        with NodeProcess.module("play", "hmocap_ros.cli",
                                ["replay", str(session), "--rate", "2", "--wait-subscribers", "1",
                                 "--wait-timeout", "30"], env, tmp_path) as play:
            assert play.wait(60) == 0, play.output()
        assert cal.wait(60) == 0, cal.output()
        log = cal.output()
    # Progress while collecting, then every frame set of the bag (reliable on loopback).
    assert re.search(r"\d+ s: \d+ frame sets, board seen by cam_1 \d+", log), log
    assert f"collected {N_FRAMES} frame sets" in log, log
    assert "intrinsics from /camera_rig" in log
    truth = load_rig(session.with_name("cal_rig.yaml"))
    live = load_rig(out)
    assert live.names == truth.names
    for cam in live:
        assert np.linalg.norm(cam.position - truth[cam.name].position) < 0.03
        assert rotation_angle_deg(cam.R, truth[cam.name].R) < 1.0
    # The same images give the same rig as the bag calibrated offline.
    offline = tmp_path / "offline.yaml"
    assert hmocap(["calibrate", str(session), "--out", str(offline), *BOARD]) == 0
    for a, b in zip(live, load_rig(offline)):
        assert np.abs(a.position - b.position).max() < 1e-6
        assert rotation_angle_deg(a.R, b.R) < 1e-4
