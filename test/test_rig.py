"""Tests of hmocap_ros.geometry.rig: the rig YAML format, validation errors and the CameraRig message."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from hmocap_ros.geometry import PinholeCamera, look_at, project_points, triangulate
from hmocap_ros.geometry.rig import Rig, RigError, load_rig, rig_from_dict, rig_to_dict, save_rig
from hmocap_ros.io.rig_messages import rig_from_msg, rig_to_msg

EXAMPLE = Path(__file__).resolve().parents[1] / "config" / "rig_example.yaml"
ROOM_CENTRE = np.array([0.0, 1.0, 0.0])


def example_dict():
    return yaml.safe_load(EXAMPLE.read_text())


def assert_rig_dicts_close(a, b, atol=1e-12):
    """Same structure, strings and integers; numbers equal within ``atol`` (quaternion maths rounds)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b)
        for key in a:
            assert_rig_dicts_close(a[key], b[key], atol)
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b)
        for x, y in zip(a, b):
            assert_rig_dicts_close(x, y, atol)
    elif isinstance(a, float):
        assert a == pytest.approx(b, abs=atol)
    else:
        assert a == b and type(a) is type(b)


def test_example_rig_geometry():
    rig = load_rig(EXAMPLE)
    assert rig.frame_id == "room" and len(rig) == 4
    assert rig.names == ("cam_1", "cam_2", "cam_3", "cam_4")
    for camera in rig:
        assert camera.size == (640, 480) and camera.distortion_model == "plumb_bob"
        assert 515 < camera.fx < 525 and 515 < camera.fy < 525 and -0.06 < camera.D[0] < -0.04
        # 2.5 m high in a corner of the 6 x 5 m room, looking at the room centre at 1 m height.
        x, y, z = camera.position
        assert y == pytest.approx(2.5) and 2.5 < abs(x) <= 3.0 and 2.0 < abs(z) <= 2.5
        pixel, depth = camera.project(ROOM_CENTRE)
        np.testing.assert_allclose(pixel, (camera.cx, camera.cy), atol=1e-6)
        assert depth > 3.0
        assert camera.frame_id == f"{camera.name}_optical_frame"
    # A standing person (feet to head) near the centre is seen by every camera.
    body = np.array([[0.3, 0.0, 0.2], [0.3, 1.8, 0.2], [-0.4, 0.0, -0.3], [-0.4, 1.8, -0.3]])
    assert rig.project(body).visible.all()
    # The image of the room's up axis points up in every image.
    pixels = rig.project(np.array([[0.0, 0.5, 0.0], [0.0, 1.5, 0.0]])).pixels
    assert np.all(pixels[:, 1, 1] < pixels[:, 0, 1])


def test_example_rig_matches_look_at():
    rig = load_rig(EXAMPLE)
    for camera in rig:
        rebuilt = look_at(camera.name, camera.position, ROOM_CENTRE, fx=camera.fx, fy=camera.fy,
                          cx=camera.cx, cy=camera.cy, D=camera.D)
        assert rebuilt.isclose(camera, atol=1e-12)


def test_rig_lookup_and_sequence_behaviour():
    rig = load_rig(EXAMPLE)
    assert rig["cam_3"] is rig[2] and rig.index("cam_3") == 2
    assert "cam_2" in rig and "cam_9" not in rig
    assert [c.name for c in rig] == list(rig.names)
    with pytest.raises(KeyError, match="cam_9"):
        rig["cam_9"]
    small = rig.scaled(0.25)
    assert small.names == rig.names and all(c.size == (160, 120) for c in small)
    # Rig works wherever a camera list does.
    rng = np.random.default_rng(0)
    points = rng.uniform((-1, 0, -1), (1, 2, 1), size=(50, 3))
    np.testing.assert_allclose(triangulate(rig, project_points(rig, points).pixels), points, atol=1e-6)


def test_yaml_round_trip(tmp_path):
    rig = load_rig(EXAMPLE)
    path = tmp_path / "rig.yaml"
    save_rig(rig, path, header="my rig")
    assert path.read_text().startswith("# my rig\n")
    again = load_rig(path)
    assert again.isclose(rig, atol=1e-12)
    assert_rig_dicts_close(yaml.safe_load(path.read_text()), rig_to_dict(rig))


def test_calibration_file_can_be_pasted(tmp_path):
    """A camera_calibration_parsers file plus name and pose is a rig camera (rational model too)."""
    calibration = """
image_width: 1280
image_height: 720
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [910.1, 0, 641.2, 0, 909.7, 362.5, 0, 0, 1]
distortion_model: rational_polynomial
distortion_coefficients:
  rows: 1
  cols: 8
  data: [0.1, -0.02, 0.001, 0.0005, 0.003, 0.4, -0.01, 0.006]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [905.0, 0, 640.0, 0, 0, 905.0, 360.0, 0, 0, 0, 1, 0]
"""
    entry = yaml.safe_load(calibration)
    entry.update(name="door_cam", pose={"position": [0.0, 2.2, -2.5], "orientation": [0.0, 0.0, 0.0, 1.0]})
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump({"frame_id": "room", "cameras": [entry]}))
    camera = load_rig(path)["door_cam"]
    assert camera.size == (1280, 720) and camera.distortion_model == "rational_polynomial"
    np.testing.assert_allclose(camera.D, entry["distortion_coefficients"]["data"])
    np.testing.assert_allclose(camera.projection[0, 0], 905.0)  # P is kept, not recomputed
    np.testing.assert_allclose(camera.position, (0.0, 2.2, -2.5))
    np.testing.assert_allclose(camera.optical_axis, (0.0, 0.0, 1.0))


def _bad(mutate):
    data = example_dict()
    mutate(data)
    return data


@pytest.mark.parametrize(
    "mutate,message",
    [
        (lambda d: d.pop("frame_id"), r"missing top-level field 'frame_id'"),
        (lambda d: d.update(cameras=[]), r"'cameras' must be a non-empty list"),
        (lambda d: d["cameras"][1].pop("camera_matrix"), r"camera 'cam_2': missing field 'camera_matrix'"),
        (lambda d: d["cameras"][1].pop("pose"), r"camera 'cam_2': missing field 'pose'"),
        (lambda d: d["cameras"][2].pop("name"), r"camera #2: field 'name'"),
        (lambda d: d["cameras"][0]["camera_matrix"].update(rows=2),
         r"camera 'cam_1': field 'camera_matrix' must be 3x3, got 2x3"),
        (lambda d: d["cameras"][0]["camera_matrix"]["data"].pop(),
         r"camera 'cam_1': field 'camera_matrix' has 8 values"),
        (lambda d: d["cameras"][0]["projection_matrix"].update(cols=3), r"field 'projection_matrix' must be 3x4"),
        (lambda d: d["cameras"][3]["distortion_coefficients"].update(cols=8, data=[0.0] * 8),
         r"camera 'cam_4': field 'distortion_coefficients' has 8 values, plumb_bob takes 5"),
        (lambda d: d["cameras"][3].update(distortion_model="fisheye"), r"camera 'cam_4': field 'distortion_model'"),
        (lambda d: d["cameras"][0]["pose"].update(orientation=[0.0, 0.0, 0.0, 2.0]),
         r"camera 'cam_1': field 'pose.orientation' is not a unit quaternion"),
        (lambda d: d["cameras"][0]["pose"].update(position=[0.0, 1.0]),
         r"camera 'cam_1': field 'pose.position' must be a list of 3"),
        (lambda d: d["cameras"][2].update(name="cam_1"), r"camera 'cam_1': field 'name' is duplicated"),
        (lambda d: d["cameras"][0].update(postion=[0, 0, 0]), r"camera 'cam_1': unknown field\(s\) 'postion'"),
        (lambda d: d["cameras"][0].update(image_width=-640),
         r"camera 'cam_1': field 'image_width' must be a positive integer"),
        (lambda d: d["cameras"][0]["camera_matrix"].update(data=[0, 0, 320, 0, 500, 240, 0, 0, 1]),
         r"camera 'cam_1': .*fx, fy > 0"),
    ],
)
def test_bad_rig_files_name_file_camera_and_field(tmp_path, mutate, message):
    path = tmp_path / "bad_rig.yaml"
    path.write_text(yaml.safe_dump(_bad(mutate)))
    with pytest.raises(RigError, match=message) as info:
        load_rig(path)
    assert str(path) in str(info.value)
    assert isinstance(info.value, ValueError)


def test_unreadable_files(tmp_path):
    with pytest.raises(RigError, match="cannot read"):
        load_rig(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("frame_id: room\ncameras: [\n")
    with pytest.raises(RigError, match="invalid YAML"):
        load_rig(bad)
    with pytest.raises(RigError, match="must be a mapping"):
        rig_from_dict(["not", "a", "rig"])


def test_rig_rejects_duplicates_in_code():
    camera = load_rig(EXAMPLE)[0]
    with pytest.raises(RigError, match="duplicate camera names"):
        Rig("room", (camera, camera))


# --------------------------------------------------------------------------------------------
# CameraRig message (rosbags dataclasses, as stored in bags)
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def typestore():
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    msg = Path(__file__).resolve().parents[1] / "msg_defs" / "msg" / "CameraRig.msg"
    store.register(get_types_from_msg(msg.read_text(), "hmocap_interfaces/msg/CameraRig"))
    return store


@pytest.fixture(scope="module")
def factory(typestore):
    from hmocap_ros.io.msg_factory import RosbagsFactory

    return RosbagsFactory(typestore)


def test_msg_round_trip_through_cdr(tmp_path, typestore, factory):
    rig = load_rig(EXAMPLE)
    stamp_ns = 1_700_000_000_123_456_789
    msg = rig_to_msg(rig, stamp_ns, factory)
    assert msg.__msgtype__ == "hmocap_interfaces/msg/CameraRig"
    assert msg.header.frame_id == "room"
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    assert list(msg.camera_names) == list(rig.names)
    assert msg.camera_info[1].header.frame_id == "cam_2_optical_frame"
    assert msg.camera_info[1].distortion_model == "plumb_bob"
    np.testing.assert_allclose(msg.camera_poses[2].position.x, rig[2].position[0])
    raw = typestore.serialize_cdr(msg, "hmocap_interfaces/msg/CameraRig")
    decoded = typestore.deserialize_cdr(raw, "hmocap_interfaces/msg/CameraRig")
    again = rig_from_msg(decoded)
    assert again.isclose(rig, atol=1e-12)
    # YAML -> Rig -> msg -> Rig -> YAML gives the same file content.
    path = tmp_path / "again.yaml"
    save_rig(again, path)
    assert_rig_dicts_close(yaml.safe_load(path.read_text()), example_dict())


def test_bad_msg(factory):
    rig = load_rig(EXAMPLE)
    msg = rig_to_msg(rig, 0, factory)
    msg.camera_names.pop()
    with pytest.raises(RigError, match="same length"):
        rig_from_msg(msg)
    msg = rig_to_msg(rig, 0, factory)
    msg.camera_poses[0].orientation.w = 3.0
    with pytest.raises(RigError, match="camera 'cam_1'.*unit quaternion"):
        rig_from_msg(msg)


def test_single_camera_from_camera_info_msg(factory):
    """A CameraInfo message + pose gives the same camera (the path the nodes use)."""
    from hmocap_ros.io.conversions import camera_info_to_dict, dict_to_camera_info

    camera = load_rig(EXAMPLE)["cam_4"]
    info = dict_to_camera_info(camera.to_camera_info_dict(), stamp_ns=5, factory=factory)
    again = PinholeCamera.from_camera_info(camera_info_to_dict(info), "cam_4", camera.position,
                                           camera.pose_quaternion())
    assert again.isclose(camera, atol=1e-12)


def test_default_factory_knows_camera_rig():
    """Without a factory, rig_to_msg uses the package typestore (hmocap_interfaces registered)."""
    from hmocap_ros.io.typestore import hmocap_typestore

    rig = load_rig(EXAMPLE)
    msg = rig_to_msg(rig, 42)
    raw = hmocap_typestore().serialize_cdr(msg, "hmocap_interfaces/msg/CameraRig")
    assert rig_from_msg(hmocap_typestore().deserialize_cdr(raw, "hmocap_interfaces/msg/CameraRig")).isclose(rig,
                                                                                                            atol=1e-12)
