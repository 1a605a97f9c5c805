"""Other tools' calibration files: round trips from a known rig, files those tools wrote, the room
frame, and ``hmocap rig convert``'s errors.

The files under ``test/data/calibration/`` were written by the tools themselves (``SOURCES.md``
there names each one's repository, commit and licence).
"""
import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest

from hmocap_ros.calibration.formats import (
    FORMATS,
    CalibrationFormatError,
    detect_format,
    load_calibration_rig,
    read_calibration,
    save_calibration_rig,
)
from hmocap_ros.calibration.formats.world_frame import (
    calibration_from_rig,
    calibration_to_rig,
    guess_up,
    up_rotation,
)
from hmocap_ros.cli import main
from hmocap_ros.geometry import look_at
from hmocap_ros.geometry.rig import Rig, load_rig

DATA = Path(__file__).parent / "data" / "calibration"
ROOT = Path(__file__).resolve().parents[1]


def _known_rig(rational: bool = True) -> Rig:
    """The example rig plus a rotated portrait camera with rational distortion (or only
    ``k1, k2, p1, p2, k3``): every field a format can hold, none at a round value."""
    rig = load_rig(ROOT / "config" / "rig_example.yaml")
    portrait = look_at("cam_side", (2.1, 1.7, 0.3), (0.2, 0.9, -0.4), up=(0.3, 1.0, 0.1),
                       width=1088, height=1920, fx=1681.2, fy=1680.9, cx=533.0, cy=948.1,
                       D=[-0.046, 0.14, 6e-4, 7e-4, 0.003, 0.01, -0.02, 0.004][:8 if rational else 5],
                       distortion_model="rational_polynomial" if rational else "plumb_bob")
    return Rig("room", (*rig.cameras, portrait))


def _written(tmp_path, fmt: str) -> Path:
    return {"rig": tmp_path / "rig.yaml", "toml": tmp_path / "Calib.toml",
            "qca": tmp_path / "Calib.qca.txt", "opencv": tmp_path / "easymocap",
            "ros": tmp_path / "camera_info"}[fmt]


@pytest.mark.parametrize("fmt", sorted(FORMATS))
def test_every_format_gives_back_the_rig_it_wrote(tmp_path, fmt):
    rig = _known_rig(rational=fmt != "qca")
    path = _written(tmp_path, fmt)
    if fmt == "qca":
        with pytest.raises(CalibrationFormatError, match="rational"):
            save_calibration_rig(_known_rig(), path, fmt)
    files = save_calibration_rig(rig, path, fmt)
    assert all(Path(f).is_file() for f in files)
    assert detect_format(path) == fmt
    back, notes = load_calibration_rig(path)
    assert back.names == rig.names
    for a, b in zip(rig, back):
        assert (a.width, a.height) == (b.width, b.height)
        np.testing.assert_allclose(b.K, a.K, atol=1e-9)
        np.testing.assert_allclose(np.pad(b.D, (0, 8 - b.D.size)), np.pad(a.D, (0, 8 - a.D.size)),
                                   atol=1e-12)
        np.testing.assert_allclose(b.R, a.R, atol=1e-12)
        np.testing.assert_allclose(b.position, a.position, atol=1e-9)
    # the file's world is the format's: a Z-up world's cameras have their image-up along +Z
    if FORMATS[fmt].up == "+Z":
        assert guess_up(read_calibration(path).cameras)[0] == "+Z"


def test_a_rig_written_in_another_world_comes_back_given_or_guessed(tmp_path):
    rig = _known_rig()
    save_calibration_rig(rig, tmp_path / "c.toml", "toml", up="-Y", units="mm")
    given, notes = load_calibration_rig(tmp_path / "c.toml", up="-Y", units="mm")
    assert notes == []
    guessed, notes = load_calibration_rig(tmp_path / "c.toml")
    assert any("millimetres" in n for n in notes) and any("up axis -Y" in n for n in notes)
    for back in (given, guessed):
        for a, b in zip(rig, back):
            np.testing.assert_allclose(b.position, a.position, atol=1e-9)
            np.testing.assert_allclose(b.R, a.R, atol=1e-12)
    wrong, _ = load_calibration_rig(tmp_path / "c.toml", up="+Y", units="mm")
    assert not np.allclose(wrong[0].position, rig[0].position, atol=0.1)


def test_up_rotations_are_proper_and_take_the_axis_to_room_y():
    for axis in ("+X", "-X", "+Y", "-Y", "+Z", "-Z"):
        A = up_rotation(axis)
        np.testing.assert_allclose(A @ A.T, np.eye(3), atol=1e-15)
        assert np.linalg.det(A) == pytest.approx(1.0)
        vector = np.zeros(3)
        vector["XYZ".index(axis[1])] = 1.0 if axis[0] == "+" else -1.0
        np.testing.assert_allclose(A @ vector, [0.0, 1.0, 0.0], atol=1e-15)


def test_floor_offset_puts_the_floor_at_room_y_zero(tmp_path):
    # the known rig's cameras in a Z-up millimetre world whose floor lies at Z = 750 mm
    rig = _known_rig(rational=False)  # a .qca holds no rational distortion
    floor_mm = 750.0
    world = calibration_from_rig(rig, up="+Z", metres_per_unit=0.001)
    raised = dataclasses.replace(world, cameras=tuple(
        dataclasses.replace(c, t=c.t - c.R @ [0.0, 0.0, floor_mm]) for c in world.cameras))
    back, _ = calibration_to_rig(raised, floor=floor_mm)
    floor_point = np.array([1200.0, -800.0, floor_mm])  # a point on the floor, in the file's world
    for foreign, camera in zip(raised.cameras, back):
        in_camera = 0.001 * (foreign.R @ floor_point + foreign.t)  # metres
        room = camera.R.T @ (in_camera - camera.t)
        assert room[1] == pytest.approx(0.0, abs=1e-9)
    for a, b in zip(rig, back):
        np.testing.assert_allclose(b.position, a.position, atol=1e-9)
        np.testing.assert_allclose(b.R, a.R, atol=1e-12)
    # hmocap rig convert --floor: the cameras stand as high above the floor as in the known rig;
    # without it the origin is on the floor, 0.75 m below it
    FORMATS["qca"].write(raised, tmp_path / "raised.qca")
    assert main(["rig", "convert", str(tmp_path / "raised.qca"), str(tmp_path / "floor.yaml"),
                 "--floor", str(floor_mm)]) == 0
    assert main(["rig", "convert", str(tmp_path / "raised.qca"), str(tmp_path / "origin.yaml")]) == 0
    on_floor, on_origin = load_rig(tmp_path / "floor.yaml"), load_rig(tmp_path / "origin.yaml")
    for a, b, c in zip(rig, on_floor, on_origin):
        np.testing.assert_allclose(b.position, a.position, atol=1e-6)
        np.testing.assert_allclose(c.position - a.position, [0.0, 0.75, 0.0], atol=1e-6)


def _relative(cameras, i, j):
    a, b = cameras[i], cameras[j]
    rotation = b.R @ a.R.T
    return rotation, np.linalg.norm(a.centre - b.centre)


def test_qualisys_file_agrees_with_pose2sims_own_calibration_of_the_same_cameras():
    """Pose2Sim's demo ships its four cameras calibrated twice: by Qualisys (``.qca``, mm, Z-up,
    Qualisys' camera axes) and by Pose2Sim's scene calibration (TOML, m, OpenCV's axes, another
    world). The cameras' poses relative to each other must agree: a wrong sign, transpose or
    unit in the ``.qca`` reading puts them tens of degrees or metres apart."""
    qca = read_calibration(DATA / "pose2sim_Calib.qca.txt")
    toml = read_calibration(DATA / "pose2sim_Calib_scene.toml")
    assert (qca.up, qca.metres_per_unit) == ("+Z", 0.001)
    assert [c.size for c in qca.cameras] == [(1088, 1920)] * 4 == [c.size for c in toml.cameras]
    for i in range(4):
        for j in range(i + 1, 4):
            rq, dq = _relative(qca.cameras, i, j)
            rt, dt = _relative(toml.cameras, i, j)
            angle = np.degrees(np.arccos(np.clip((np.trace(rq.T @ rt) - 1) / 2, -1, 1)))
            assert angle < 5.0, (i, j, angle)
            assert abs(dq * 0.001 - dt) < 0.15, (i, j, dq, dt)
    # the same lenses: focal lengths within 1 %, radial distortion of the same size and sign
    for a, b in zip(qca.cameras, toml.cameras):
        assert a.K[0, 0] == pytest.approx(b.K[0, 0], rel=0.01)
        assert np.sign(a.D[0]) == np.sign(b.D[0]) and 0.5 < a.D[1] / b.D[1] < 20


def test_qualisys_cameras_stand_in_the_room_frame():
    rig, notes = load_calibration_rig(DATA / "pose2sim_Calib.qca.txt")
    assert notes == [] and rig.names == ("cam01", "cam02", "cam03", "cam04")
    heights = np.array([c.position[1] for c in rig])
    assert np.all((heights > 1.5) & (heights < 2.5))  # on tripods, floor at the origin
    centre = np.mean([c.position for c in rig], axis=0)
    for camera in rig:
        assert camera.optical_axis[1] < -0.2  # looking down ...
        towards = centre - camera.position
        towards[1] = 0
        axis = camera.optical_axis.copy()
        axis[1] = 0
        assert axis @ towards / np.linalg.norm(axis) / np.linalg.norm(towards) > 0.8  # ... inwards
        assert camera.R[1] @ np.array([0.0, -1.0, 0.0]) > 0.8  # upright: image up is room up


def test_aniposelib_file_projects_as_aniposelib_does():
    """aniposelib's ``Camera.project`` is ``cv2.projectPoints(p, rvec, tvec, matrix, dist)`` in the
    file's unit (its board's, millimetres here) with the first camera at the origin."""
    import tomllib

    table = tomllib.loads((DATA / "aniposelib_calibration.toml").read_text())
    rig, notes = load_calibration_rig(DATA / "aniposelib_calibration.toml", up="-Y")
    assert rig.names == ("cam088", "cam091")
    assert any("millimetres" in n for n in notes)
    rng = np.random.default_rng(0)
    points_mm = rng.uniform(-40, 40, (50, 3)) + np.array([0.0, 0.0, 150.0])  # near the cameras' target
    A = up_rotation("-Y")
    for key, camera in zip(("cam_0", "cam_1"), rig):
        entry = table[key]
        expected, _ = cv2.projectPoints(points_mm, np.array(entry["rotation"]),
                                        np.array(entry["translation"]), np.array(entry["matrix"]),
                                        np.array(entry["distortions"]))
        pixels, _ = camera.project((A @ points_mm.T).T * 0.001)
        np.testing.assert_allclose(pixels, expected[:, 0], atol=1e-6)
    assert detect_format(DATA / "aniposelib_calibration.toml") == "toml"


def test_easymocap_pair_reads_its_rotations_and_needs_a_size():
    path = DATA / "easymocap"
    assert detect_format(path) == detect_format(path / "extri.yml") == "opencv"
    with pytest.raises(CalibrationFormatError, match="no image size"):
        load_calibration_rig(path)
    rig, notes = load_calibration_rig(path, sizes={"2": (1920, 1080), "3": (1920, 1080)})
    assert any("up axis +Z" in n for n in notes) and any("metres" in n for n in notes)
    storage = cv2.FileStorage(str(path / "extri.yml"), cv2.FILE_STORAGE_READ)
    A = up_rotation("+Z")
    world = np.array([[0.3, -0.2, 1.0], [0.0, 0.4, 0.1], [-0.5, 0.0, 1.6]])  # near the origin, Z-up
    for camera in rig:
        rvec, tvec = storage.getNode(f"R_{camera.name}").mat(), storage.getNode(f"T_{camera.name}").mat()
        expected, _ = cv2.projectPoints(world, rvec, tvec, camera.K, camera.D)
        pixels, _ = camera.project((A @ world.T).T)
        np.testing.assert_allclose(pixels, expected[:, 0], atol=1e-6)
        assert 4.0 < np.linalg.norm(camera.position) < 7.0


def test_ros_camera_info_needs_a_pose_and_keeps_its_intrinsics(tmp_path):
    source = DATA / "image_common_test_calibration.yaml"
    assert detect_format(source) == "ros"
    with pytest.raises(CalibrationFormatError, match="no pose"):
        load_calibration_rig(source)
    with_pose = tmp_path / "cam.yaml"
    with_pose.write_text(source.read_text() + "pose:\n  position: [1.0, 2.0, 1.5]\n"
                         "  orientation: [-0.5, 0.5, -0.5, 0.5]\n")
    rig, _ = load_calibration_rig(with_pose)
    camera = rig["08144361026320a0"]
    np.testing.assert_allclose(camera.K, [[1168.68, 0, 295.015], [0, 1169.01, 252.247], [0, 0, 1]])
    np.testing.assert_allclose(camera.D, [-1.04482, 1.59252, -0.0196308, 0.0287906, 0])
    # REP-103 world (x forward, z up) -> room (+Y up): (1, 2, 1.5) -> (1, 1.5, -2)
    np.testing.assert_allclose(camera.position, [1.0, 1.5, -2.0], atol=1e-12)
    np.testing.assert_allclose(camera.optical_axis, [1.0, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("content, name", [
    ("just some text\n", "notes.txt"),
    ("<svg></svg>\n", "picture.xml"),
    ("a: 1\n", "other.yaml"),
    ("[cam]\nname = 'x'\n", "nocam.toml"),
])
def test_files_in_no_format_are_one_line_errors(tmp_path, capsys, content, name):
    path = tmp_path / name
    path.write_text(content)
    assert main(["rig", "convert", str(path), str(tmp_path / "out.yaml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("hmocap rig convert: ") and "Traceback" not in err
    assert not (tmp_path / "out.yaml").exists()


def test_rig_convert_writes_every_format_and_says_what_it_guessed(tmp_path, capsys):
    source = DATA / "pose2sim_Calib.qca.txt"
    assert main(["rig", "convert", str(source), str(tmp_path / "rig.yaml")]) == 0
    assert main(["rig", "convert", str(tmp_path / "rig.yaml"), str(tmp_path / "out"),
                 "--to", "opencv"]) == 0
    assert main(["rig", "convert", str(tmp_path / "out"), str(tmp_path / "again.qca")]) == 0
    captured = capsys.readouterr()
    assert "up axis +Z, from the cameras" in captured.err  # intri/extri say no up axis
    again = read_calibration(tmp_path / "again.qca")
    original = read_calibration(source)
    for a, b in zip(original.cameras, again.cameras):
        np.testing.assert_allclose(b.centre, a.centre, atol=1e-6)  # mm
        np.testing.assert_allclose(b.R, a.R, atol=1e-12)
    # an existing output, a missing size and an unknown output name are one line each
    for argv, text in ((["rig", "convert", str(source), str(tmp_path / "rig.yaml")], "exists"),
                       (["rig", "convert", str(DATA / "easymocap"), str(tmp_path / "x.yaml")],
                        "--size"),
                       (["rig", "convert", str(source), str(tmp_path / "x.bin")], "--to")):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and text in err
    assert main(["rig", "convert", str(DATA / "easymocap"), str(tmp_path / "x.yaml"),
                 "--size", "1920x1080"]) == 0
