"""``hmocap import videos`` on a tiny generated video set: a ball flying through a room, filmed by
three calibrated cameras whose calibration is written in another tool's format (Qualisys: Z-up,
millimetres), one video turned on its side, one started two frames late, one at twice the size.

The bag's rig must put the ball where it was: the ball's centre found in each imported image
(the centroid of a disc of a few pixels, JPEG-compressed: a pixel at 160 x 120 is 2.5 cm at
the ball) and triangulated with the bag's ``/camera_rig`` lies within 2.5 cm of the truth in
every frame set; a wrong world, unit, turn, scale or a frame's offset puts it 10 cm or more away.
"""
import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest

from hmocap_ros.calibration.formats import save_calibration_rig
from hmocap_ros.cli import main
from hmocap_ros.geometry import look_at, project_points, triangulate
from hmocap_ros.geometry.rig import Rig
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.image_codec import decoded_rgb
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_ros.io.rig_messages import rig_from_msg
from hmocap_ros.video_import.camera_fit import rotate_camera, upright_turns
from hmocap_ros.video_import.importer import BASE_STAMP_NS

FPS = 25.0
FRAMES = 12


def _rig() -> Rig:
    cameras = [look_at(f"cam{k + 1}", position, (0.0, 1.0, 0.0), width=160, height=120, fx=150.0)
               for k, position in enumerate([(2.5, 2.0, 2.0), (-2.5, 2.2, 1.5), (0.5, 2.4, -3.0)])]
    return Rig("room", tuple(cameras))


def _ball(i: int) -> np.ndarray:
    return np.array([-0.6 + 0.1 * i, 0.8 + 0.05 * i, 0.3 - 0.04 * i])


def _frames(camera, n: int, shift: int = 0) -> list[np.ndarray]:
    """BGR frames of the ball (a disc of 0.08 m radius) seen by ``camera``; frame ``j`` shows the
    ball of frame set ``j - shift``."""
    out = []
    for j in range(n):
        image = np.full((camera.height, camera.width, 3), 40, np.uint8)
        centre = _ball(j - shift)
        pixel = project_points([camera], centre[None])[0][0, 0]
        depth = float((camera.R @ centre + camera.t)[2])
        radius = max(2, int(round(camera.fx * 0.08 / depth)))
        cv2.circle(image, tuple(int(round(v)) for v in pixel), radius, (255, 255, 255), -1,
                   lineType=cv2.LINE_AA)
        out.append(image)
    return out


def _write_video(path: Path, frames: list[np.ndarray]) -> None:
    height, width = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), FPS, (width, height))
    assert writer.isOpened()
    for frame in frames:
        writer.write(frame)
    writer.release()


@pytest.fixture()
def recording(tmp_path):
    """Three videos and a Qualisys calibration of their cameras: cam1 as calibrated, cam2 turned
    90 deg clockwise and starting 2 frames late, cam3 at twice the calibrated size."""
    rig = _rig()
    cam1, cam2, cam3 = rig.cameras
    _write_video(tmp_path / "cam1.avi", _frames(cam1, FRAMES))
    turned = [cv2.rotate(f, cv2.ROTATE_90_CLOCKWISE) for f in _frames(cam2, FRAMES + 2, shift=2)]
    _write_video(tmp_path / "cam2.avi", turned)
    _write_video(tmp_path / "cam3.avi", _frames(cam3.scaled(2.0), FRAMES))
    save_calibration_rig(rig, tmp_path / "calib.qca", "qca")
    return tmp_path, rig


def _centroids(bag: Path):
    with BagReader(bag) as reader:
        rig = rig_from_msg(reader.first(topics.CAMERA_RIG))
        names = [topics.camera_image(n) for n in rig.names]
        sets = []
        for _, msgs in reader.frame_sets(names, 0):
            row = []
            for topic in names:
                grey = decoded_rgb(msgs[topic])[..., 0].astype(np.float64)
                weight = np.clip(grey - 100.0, 0.0, None)
                ys, xs = np.mgrid[:grey.shape[0], :grey.shape[1]]
                row.append([(weight * xs).sum() / weight.sum(), (weight * ys).sum() / weight.sum()])
            sets.append(row)
    return rig, np.array(sets)


def test_imported_bag_triangulates_the_ball_where_it_flew(recording, capsys):
    folder, truth_rig = recording
    bag = folder / "ball.mcap"
    argv = ["import", "videos", str(folder / "cam1.avi"), str(folder / "cam2.avi"),
            str(folder / "cam3.avi"), "--calibration", str(folder / "calib.qca"), "--out", str(bag),
            "--rotate", "cam2=90", "--offsets", "0,2,0", "--quiet"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "cam3: scaled by 2" in captured.err and "cam2: turned 90 deg clockwise" in captured.err
    assert f"{FRAMES} frame sets x 3 cameras" in captured.out
    rig, pixels = _centroids(bag)
    assert rig.names == ("cam1", "cam2", "cam3")
    assert [(c.width, c.height) for c in rig] == [(160, 120), (160, 120), (320, 240)]
    for i in range(FRAMES):
        point = triangulate(list(rig.cameras), pixels[i][:, None, :])[0]
        assert np.linalg.norm(point - _ball(i)) < 0.025, (i, point, _ball(i))
    with BagReader(bag) as reader:
        available = reader.topics()
        assert available["/tf_static"].latched and available[topics.CAMERA_RIG].latched
        assert available["/cam2/camera_info"].count == FRAMES
        stamps = [item.log_time_ns for item in reader.messages(["/cam1/image_raw"])]
    assert np.allclose(np.diff(stamps), 1e9 / FPS, atol=1)


def test_scale_and_start_pick_the_frames_and_shrink_the_cameras(recording, capsys):
    folder, _ = recording
    bag = folder / "half.mcap"
    assert main(["import", "videos", str(folder / "cam1.avi"), str(folder / "cam3.avi"),
                 "--calibration", str(folder / "calib.qca"), "--out", str(bag), "--scale", "0.5",
                 "--start", str(4 / FPS), "--seconds", str(5 / FPS), "--quiet"]) == 0
    capsys.readouterr()
    rig, pixels = _centroids(bag)
    assert [(c.width, c.height) for c in rig] == [(80, 60), (160, 120)]
    assert len(pixels) == 5
    for i in range(5):
        point = triangulate(list(rig.cameras), pixels[i][:, None, :])[0]
        assert np.linalg.norm(point - _ball(4 + i)) < 0.04


def test_stamps_are_the_frames_times_in_the_videos_from_their_start(recording, capsys):
    # --start 4 frames in: frame set k is the videos' frame 4 + k, stamped at its time in them
    folder, _ = recording
    bag = folder / "late.mcap"
    assert main(["import", "videos", str(folder / "cam1.avi"), "--calibration", str(folder / "calib.qca"),
                 "--out", str(bag), "--start", str(4 / FPS), "--seconds", str(5 / FPS), "--quiet"]) == 0
    capsys.readouterr()
    expected = [BASE_STAMP_NS + round((4 + k) * 1e9 / FPS) for k in range(5)]
    with BagReader(bag) as reader:
        for topic in ("/cam1/image_raw", "/cam1/camera_info"):
            items = list(reader.messages([topic]))
            assert [item.log_time_ns for item in items] == expected, topic
            assert [stamp_to_ns(item.msg.header) for item in items] == expected, topic
        assert stamp_to_ns(reader.first(topics.CAMERA_RIG).header) == expected[0]


def test_a_turned_camera_projects_where_the_turned_image_shows(recording):
    _, rig = recording
    camera = rig["cam2"]
    camera = dataclasses.replace(camera, D=np.array([-0.1, 0.02, 3e-3, -2e-3, 0.01]))
    points = np.array([[0.2, 1.1, 0.1], [-0.4, 0.6, 0.5], [0.5, 1.6, -0.3]])
    pixels, _ = camera.project(points)
    for turns in (1, 2, 3):
        turned = rotate_camera(camera, turns)
        expected = pixels.copy()
        width, height = camera.width, camera.height
        for _ in range(turns):  # (u, v) -> (H - 1 - v, u) per clockwise turn
            expected = np.column_stack([height - 1 - expected[:, 1], expected[:, 0]])
            width, height = height, width
        got, _ = turned.project(points)
        np.testing.assert_allclose(got, expected, atol=1e-9)
    assert upright_turns(camera) == 0
    assert upright_turns(rotate_camera(camera, 1)) == 3


def _run(argv, capsys):
    code = main(argv)
    err = capsys.readouterr().err
    return code, err


@pytest.mark.parametrize("case, expected", [
    ("names", "no camera 'camX'"),
    ("count", "3 videos and 2 names"),
    ("size", "the video is 120x160, the calibration 160x120 (turned): give --rotate"),
    ("unreadable", "not a video"),
    ("missing_calibration", "no such file"),
    ("no_format", "not a calibration in any known format"),
    ("calibration_lacks_camera", "name no camera of the calibration"),
])
def test_bad_input_is_one_line_and_exit_2(recording, capsys, case, expected):
    folder, rig = recording
    videos = [str(folder / f"cam{k}.avi") for k in (1, 2, 3)]
    calibration = str(folder / "calib.qca")
    extra = []
    if case == "names":
        extra = ["--names", "cam1,camX,cam3"]
    elif case == "count":
        extra = ["--names", "cam1,cam2"]
    elif case == "unreadable":
        (folder / "broken.avi").write_bytes(b"\x00" * 4096)
        videos[0] = str(folder / "broken.avi")
    elif case == "missing_calibration":
        calibration = str(folder / "nowhere.qca")
    elif case == "no_format":
        (folder / "notes.txt").write_text("hello\n")
        calibration = str(folder / "notes.txt")
    elif case == "calibration_lacks_camera":
        save_calibration_rig(Rig("room", rig.cameras[:2]), folder / "two.qca", "qca")
        calibration = str(folder / "two.qca")
    code, err = _run(["import", "videos", *videos, "--calibration", calibration, "--out",
                      str(folder / "out.mcap"), "--quiet", *extra], capsys)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("hmocap import videos: "), err
    assert expected in err and "Traceback" not in err
    assert not (folder / "out.mcap").exists()


def test_videos_of_different_lengths_import_to_the_shortest_with_a_warning(recording, capsys):
    folder, _ = recording
    bag = folder / "short.mcap"
    code, err = _run(["import", "videos", str(folder / "cam1.avi"), str(folder / "cam2.avi"),
                      "--calibration", str(folder / "calib.qca"), "--out", str(bag),
                      "--rotate", "cam2=90", "--quiet"], capsys)
    assert code == 0
    assert "warning: the videos have different lengths (cam1.avi 12, cam2.avi 14" in err
    assert "imported to the shortest (cam1.avi)" in err
    with BagReader(bag) as reader:
        assert reader.topics(compressed_as_raw=True)["/cam1/image_raw"].count == FRAMES


def test_views_a_few_pixels_larger_are_cut_to_the_others_size(tmp_path, capsys):
    """The tracker stacks a frame set's silhouettes: a camera calibrated (and filmed) 8x6 pixels
    larger than the other is cut at its right and bottom, its intrinsics kept, so the ball
    still lands where the camera projects it (a resize would move it by up to 8 px)."""
    cam1, big = _rig().cameras[:2]
    big = dataclasses.replace(big, width=168, height=126)
    _write_video(tmp_path / "cam1.avi", _frames(cam1, FRAMES))
    _write_video(tmp_path / "cam2.avi", _frames(big, FRAMES))
    save_calibration_rig(Rig("room", (cam1, big)), tmp_path / "calib.qca", "qca")
    bag = tmp_path / "cut.mcap"
    assert main(["import", "videos", str(tmp_path / "cam1.avi"), str(tmp_path / "cam2.avi"),
                 "--calibration", str(tmp_path / "calib.qca"), "--out", str(bag), "--quiet"]) == 0
    assert "cam2: cut to 160x120 at the right and bottom" in capsys.readouterr().err
    rig, pixels = _centroids(bag)
    assert [(c.width, c.height) for c in rig] == [(160, 120), (160, 120)]
    for i in range(FRAMES):
        expected = project_points([rig.cameras[1]], _ball(i)[None])[0][0, 0]
        assert np.linalg.norm(pixels[i, 1] - expected) < 1.0, (i, pixels[i, 1], expected)
        point = triangulate(list(rig.cameras), pixels[i][:, None, :])[0]
        assert np.linalg.norm(point - _ball(i)) < 0.025


def test_images_are_jpeg_compressed_unless_raw(recording, capsys):
    folder, _ = recording
    videos = [str(folder / "cam1.avi"), "--calibration", str(folder / "calib.qca")]
    jpeg, raw = folder / "jpeg.mcap", folder / "raw.mcap"
    assert main(["import", "videos", *videos, "--out", str(jpeg), "--quiet"]) == 0
    assert main(["import", "videos", *videos, "--out", str(raw), "--raw", "--quiet"]) == 0
    with BagReader(jpeg) as reader:
        stored = reader.topics()
        assert "/cam1/image_raw" not in stored
        assert stored["/cam1/image_raw/compressed"].msgtype == "sensor_msgs/msg/CompressedImage"
        formats = {m.msg.format for m in reader.messages(["/cam1/image_raw/compressed"])}
        compressed = [decoded_rgb(m.msg) for m in reader.messages(["/cam1/image_raw"])]
    with BagReader(raw) as reader:
        assert reader.topics()["/cam1/image_raw"].msgtype == "sensor_msgs/msg/Image"
        plain = [decoded_rgb(m.msg) for m in reader.messages(["/cam1/image_raw"])]
    assert formats == {"rgb8; jpeg compressed bgr8"} and len(compressed) == len(plain) == FRAMES
    assert max(np.abs(a.astype(int) - b).mean() for a, b in zip(compressed, plain)) < 2.0
    capsys.readouterr()
    code = main(["import", "videos", *videos, "--out", str(folder / "bad.mcap"), "--jpeg-quality", "0", "--quiet"])
    assert code == 2 and "JPEG quality must be 1 to 100" in capsys.readouterr().err
    assert not (folder / "bad.mcap").exists()
