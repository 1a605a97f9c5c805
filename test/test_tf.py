"""tf2 frames: the rotation and transform maths of hmocap_ros.io.tf, the tf2_msgs interfaces the
environment provides (the type hash of ROS 2 Jazzy's), and camera_rig_publisher's /tf_static
over DDS: a late listener gets room -> every camera's optical frame (centre and orientation as
in the rig file), and a rig changed at run time is published again."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hmocap_ros.geometry.rig import Rig, load_rig, save_rig
from hmocap_ros.geometry.rotations import quaternion_to_matrix
from hmocap_ros.io import tf
from hmocap_ros.io.msg_factory import RclpyFactory, RosbagsFactory, stamp_to_ns
from hmocap_ros.io.typestore import hmocap_typestore
from hmocap_ros.processes import NodeProcess, loopback_dds_env

ROOT = Path(__file__).resolve().parents[1]
RIG = ROOT / "config" / "rig_example.yaml"
#: RIHS01 type hash of tf2_msgs/msg/TFMessage in ROS 2 Jazzy (`ros2 topic info -v /tf`).
JAZZY_TFMESSAGE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"


def test_rotation_to_quaternion_matches_scipy_and_round_trips():
    for seed in range(300):
        rotation = Rotation.random(random_state=seed)
        q = np.array(tf.rotation_to_quaternion(rotation.as_matrix()))
        assert q[3] >= 0 and np.isclose(np.linalg.norm(q), 1.0)
        np.testing.assert_allclose(np.abs(q @ rotation.as_quat()), 1.0, atol=1e-12)  # same rotation
        np.testing.assert_allclose(quaternion_to_matrix(q), rotation.as_matrix(), atol=1e-12)
    for axis in np.eye(3):  # half turns: w = 0, the branch of the largest diagonal element
        matrix = Rotation.from_rotvec(np.pi * axis).as_matrix()
        np.testing.assert_allclose(quaternion_to_matrix(tf.rotation_to_quaternion(matrix)), matrix, atol=1e-12)
    assert tf.rotation_to_quaternion(np.eye(3)) == (0.0, 0.0, 0.0, 1.0)


@pytest.mark.parametrize("bad", [np.diag([1.0, 1.0, -1.0]), 2 * np.eye(3), np.ones((3, 3)), np.eye(4),
                                 np.full((3, 3), np.nan)])
def test_rotation_to_quaternion_refuses_what_is_not_a_rotation(bad):
    with pytest.raises(ValueError):
        tf.rotation_to_quaternion(bad)


def test_camera_transforms_put_the_optical_frame_at_the_camera():
    rig = load_rig(RIG)
    transforms = tf.rig_transforms(rig, fixed_frame="")
    assert [(t.parent, t.child) for t in transforms] == [("room", f"{n}_optical_frame") for n in rig.names]
    for t, camera in zip(transforms, rig.cameras):
        np.testing.assert_allclose(t.apply([0.0, 0.0, 0.0]), camera.position, atol=1e-12)
        np.testing.assert_allclose(t.apply([0.0, 0.0, 1.0]) - camera.position, camera.optical_axis, atol=1e-12)
        points = np.random.default_rng(0).normal(size=(5, 3))
        np.testing.assert_allclose(t.apply(points), camera.camera_to_world(points), atol=1e-9)
        # an optical-frame point of the camera projects where the camera model says
        pixel, _ = camera.project(t.apply([[0.3, -0.2, 2.0]]), distort=False)
        np.testing.assert_allclose(pixel[0], camera.K[:2, :2] @ [0.15, -0.1] + camera.K[:2, 2], atol=1e-6)


def test_the_fixed_frame_is_the_z_up_root_with_the_room_floor_on_xy():
    rig = load_rig(RIG)
    assert tf.rig_transforms(rig)[0].parent == tf.DEFAULT_FIXED_FRAME == "world"
    first, *cameras = tf.rig_transforms(rig, fixed_frame="map")
    assert (first.parent, first.child) == ("map", "room") and len(cameras) == len(rig)
    np.testing.assert_allclose(first.apply([0.0, 1.0, 0.0]), [0.0, 0.0, 1.0], atol=1e-12)  # room up = +Z
    np.testing.assert_allclose(first.apply([1.0, 0.0, 0.0]), [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(first.apply([0.0, 0.0, 1.0]), [0.0, -1.0, 0.0], atol=1e-12)
    for camera, t in zip(rig.cameras, cameras):  # a camera's height above the floor is its map z
        assert np.isclose((first.matrix @ t.matrix)[2, 3], camera.position[1])


def test_frame_transform_refuses_bad_frames():
    with pytest.raises(ValueError, match="parent"):
        tf.FrameTransform("", "cam", (0, 0, 0), (0, 0, 0, 1))
    with pytest.raises(ValueError, match="both"):
        tf.FrameTransform("room", "room", (0, 0, 0), (0, 0, 0, 1))
    with pytest.raises(ValueError, match="unit quaternion"):
        tf.FrameTransform("room", "cam", (0, 0, 0), (0, 0, 0, 2))
    with pytest.raises(ValueError, match="translation"):
        tf.FrameTransform("room", "cam", (0, np.inf, 0), (0, 0, 0, 1))


@pytest.mark.parametrize("flavour", ["rclpy", "rosbags"])
def test_tf_message_fields(flavour):
    factory = RclpyFactory() if flavour == "rclpy" else RosbagsFactory(hmocap_typestore())
    rig = load_rig(RIG)
    transforms = tf.rig_transforms(rig)
    msg = tf.tf_message(transforms, 1_700_000_000_123_456_789, factory)
    assert len(msg.transforms) == len(rig) + 1
    for stamped, t in zip(msg.transforms, transforms):
        assert stamp_to_ns(stamped.header.stamp) == 1_700_000_000_123_456_789
        assert tf.from_transform_stamped(stamped) == t


def test_tf2_msgs_is_jazzys():
    """The environment's tf2_msgs (a ROS install's, or msg_defs_tf2 built by make setup) has the
    type hash of ROS 2 Jazzy's, so tf2, RViz and bags of other machines read our /tf_static."""
    import tf2_msgs
    from tf2_msgs.msg import TFMessage  # noqa: F401 (the message module must import)

    share = [Path(p).parents[3] / "share" / "tf2_msgs" / "msg" / "TFMessage.json" for p in tf2_msgs.__path__]
    found = [p for p in share if p.is_file()]
    if not found:
        pytest.skip(f"no type description next to tf2_msgs ({share})")
    description = json.loads(found[0].read_text())
    assert description["type_hashes"][0]["hash_string"] == JAZZY_TFMESSAGE_HASH


TF_LISTENER = r"""
import json, sys, time, rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from tf2_msgs.msg import TFMessage
rclpy.init()
node = rclpy.create_node("tf_listener")
got = []
# tf2's static listener: reliable, transient local, keep last 100
qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
node.create_subscription(TFMessage, "/tf_static", got.append, qos)
def wait_for(n, timeout):
    end = time.monotonic() + timeout
    while len(got) < n and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.1)
    return len(got) >= n
def dump(msg):
    print("TF " + json.dumps([[t.header.frame_id, t.child_frame_id, t.header.stamp.sec, t.header.stamp.nanosec,
                               [t.transform.translation.x, t.transform.translation.y, t.transform.translation.z],
                               [t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
                                t.transform.rotation.w]] for t in msg.transforms]), flush=True)
if not wait_for(1, 60):
    print("no /tf_static", flush=True); sys.exit(1)
dump(got[0])
client = node.create_client(SetParameters, "/camera_rig_publisher/set_parameters")
assert client.wait_for_service(timeout_sec=30)
def set_rig(path):
    value = ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=path)
    future = client.call_async(SetParameters.Request(parameters=[Parameter(name="rig_file", value=value)]))
    rclpy.spin_until_future_complete(node, future, timeout_sec=30)
    return future.result().results[0]
r = set_rig("/nonexistent/rig.yaml")
print("refused" if not r.successful else "accepted", r.reason, flush=True)
r = set_rig(sys.argv[1])
print("changed" if r.successful else "failed " + r.reason, flush=True)
if not wait_for(2, 30):
    print("no second /tf_static", flush=True); sys.exit(1)
dump(got[-1])
print("done", flush=True)
"""


def _parse(line: str) -> dict:
    return {child: (parent, sec * 1_000_000_000 + nsec, np.array(t), np.array(q))
            for parent, child, sec, nsec, t, q in json.loads(line[3:])}


def _check_against_rig(transforms: dict, rig: Rig) -> None:
    for camera in rig.cameras:
        parent, stamp, translation, rotation = transforms[camera.frame_id]
        assert parent == rig.frame_id and stamp > 0
        np.testing.assert_allclose(translation, camera.position, atol=1e-9)       # camera centre
        np.testing.assert_allclose(quaternion_to_matrix(rotation), camera.R_wc, atol=1e-9)  # orientation


def test_rig_publisher_publishes_static_transforms(tmp_path):
    rig = load_rig(RIG)
    # the changed rig: two cameras, one moved and renamed frame
    moved = load_rig(RIG)
    from hmocap_ros.geometry.pinhole_camera import PinholeCamera

    c1, c2 = moved[0], moved[1]
    c2 = PinholeCamera.from_pose(name=c2.name, width=c2.width, height=c2.height, K=c2.K,
                                 position=c2.position + [0.5, 0.0, -0.25], quaternion_xyzw=c2.pose_quaternion(),
                                 D=c2.D, distortion_model=c2.distortion_model, frame_id="cam_2_colour_optical_frame")
    changed = Rig("room", (c1, c2))
    changed_path = tmp_path / "changed_rig.yaml"
    save_rig(changed, changed_path)

    env = loopback_dds_env()
    node = NodeProcess.module("rig", "hmocap_ros.nodes.camera_rig_publisher",
                              ["--ros-args", "-p", f"rig_file:={RIG}", "-p", "fixed_frame:=map"], env, tmp_path)
    try:
        assert node.wait_for_output("serving rig", 60), node.output()
        # started after the node published: transient local delivers it all the same
        listener = NodeProcess("listener", [sys.executable, "-c", TF_LISTENER, str(changed_path)], env, tmp_path)
        assert listener.wait_for_output("done", 120), listener.output() + node.output()
        listener.stop()
        assert node.proc.poll() is None, node.output()
    finally:
        node.stop()
    lines = [line for line in listener.output().splitlines() if line.startswith("TF ")]
    first, second = _parse(lines[0]), _parse(lines[1])
    assert set(first) == {"room", *(c.frame_id for c in rig.cameras)}
    assert first["room"][0] == "map"
    np.testing.assert_allclose(first["room"][3], tf.Y_UP_TO_Z_UP, atol=1e-12)
    _check_against_rig(first, rig)
    assert "refused cannot load the rig: /nonexistent/rig.yaml" in listener.output(), listener.output()
    assert "changed" in listener.output(), listener.output()
    assert set(second) == {"room", "cam_1_optical_frame", "cam_2_colour_optical_frame"}
    _check_against_rig(second, changed)
    log = node.output()
    assert "Traceback" not in log and "room -> cam_2_colour_optical_frame" in log, log


def test_rig_publisher_refuses_a_fixed_frame_named_as_the_room(free_domain_id):
    import subprocess

    exe = Path(sys.executable).parent / "camera_rig_publisher"
    assert exe.exists(), f"{exe} is not installed: make setup installs the package's executables"
    res = subprocess.run([str(exe), "--ros-args", "-p", f"rig_file:={RIG}", "-p", "fixed_frame:=room"],
                         capture_output=True, text=True, timeout=60,
                         env=loopback_dds_env(domain_id=free_domain_id))
    assert res.returncode == 2
    assert "parent and child are both 'room'" in res.stderr + res.stdout
    assert "Traceback" not in res.stderr
