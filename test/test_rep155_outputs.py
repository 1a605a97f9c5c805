"""REP-155's per-body outputs as ROS4HRI reads them (:mod:`hmocap_ros.rep155.body_outputs`).

The messages are checked against the released definitions of ros4hri/hri_msgs (its ROS 2
branch, humble-devel, 2.0.0: Skeleton2D, NormalizedPointOfInterest2D, NormalizedRegionOfInterest2D, field for field
below): the package's type store and the environment's hri_msgs (a ROS install's, or
``msg_defs_hri/`` built by ``make setup``) hash them as the released text, and every built
message serialises with the released definitions. A tracked pose seen by a rig gives a
skeleton2d in the camera that sees it best, a box around it, the pelvis as position, its
velocity from the second pose on, the URDF once per shape, joint_states led by the URDF's
joints, and /tf frames prefixed (only the body frames with ``joint_frames`` false).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from hmocap_ros.body.anthropometry import BodyShape, apply_shape
from hmocap_ros.body.human_description import URDF_JOINTS
from hmocap_ros.body.model import load_body_model
from hmocap_ros.geometry import look_at
from hmocap_ros.io.msg_factory import RosbagsFactory
from hmocap_ros.io.typestore import hmocap_typestore
from hmocap_ros.rep155.body_outputs import REP155_OUTPUT_TYPES, Rep155Outputs, rep155_topics
from hmocap_ros.tracking import body_frames as bf
from hmocap_ros.tracking.result import TrackerState, TrackResult
from hmocap_ros.tracking.tracker_messages import TrackerMessages

#: ros4hri/hri_msgs, ROS 2 branch (humble-devel, 2.0.0), the fields of the messages the package publishes
RELEASED = {
    "NormalizedPointOfInterest2D": "float32 x\nfloat32 y\nfloat32 c\n",
    "NormalizedRegionOfInterest2D": "std_msgs/Header header\nfloat32 xmin\nfloat32 ymin\nfloat32 xmax\n"
                                    "float32 ymax\nfloat32 c\n",
    "Skeleton2D": "std_msgs/Header header\nuint8 NOSE = 0\nuint8 NECK = 1\nuint8 RIGHT_SHOULDER = 2\n"
                  "uint8 RIGHT_ELBOW = 3\nuint8 RIGHT_WRIST = 4\nuint8 LEFT_SHOULDER = 5\nuint8 LEFT_ELBOW = 6\n"
                  "uint8 LEFT_WRIST = 7\nuint8 RIGHT_HIP = 8\nuint8 RIGHT_KNEE = 9\nuint8 RIGHT_ANKLE = 10\n"
                  "uint8 LEFT_HIP = 11\nuint8 LEFT_KNEE = 12\nuint8 LEFT_ANKLE = 13\nuint8 LEFT_EYE = 14\n"
                  "uint8 RIGHT_EYE = 15\nuint8 LEFT_EAR = 16\nuint8 RIGHT_EAR = 17\n"
                  "NormalizedPointOfInterest2D[18] skeleton\n",
}
T0 = 1_700_000_000_000_000_000
PERIOD = 40_000_000


def _released_store():
    store = get_typestore(Stores.ROS2_JAZZY)
    for name in ("NormalizedPointOfInterest2D", "NormalizedRegionOfInterest2D", "Skeleton2D"):
        store.register(get_types_from_msg(RELEASED[name], f"hri_msgs/msg/{name}"))
    return store


def test_the_package_types_hash_as_the_released_definitions():
    released, ours = _released_store(), hmocap_typestore()
    for name in RELEASED:
        assert ours.hash_rihs01(f"hri_msgs/msg/{name}") == released.hash_rihs01(f"hri_msgs/msg/{name}"), name


def test_the_environment_hri_msgs_hash_as_the_released_definitions():
    import hri_msgs

    released = _released_store()
    for name in RELEASED:
        share = [Path(p).parents[3] / "share" / "hri_msgs" / "msg" / f"{name}.json" for p in hri_msgs.__path__]
        found = [p for p in share if p.is_file()]
        assert found, f"no type description next to hri_msgs ({share}): the package was not built"
        description = json.loads(found[0].read_text())
        assert description["type_hashes"][0]["hash_string"] == released.hash_rihs01(f"hri_msgs/msg/{name}")


@pytest.fixture(scope="module")
def model():
    return load_body_model("tracking")


def _result(model, stamp_ns: int, shift: float, shape) -> TrackResult:
    params = model.rest_pose().copy()
    skel = model.skeleton
    params[list(skel.translation_dofs)] = [shift, 0.95, 0.0]
    names = list(skel.dof_names)
    params[names.index("l_elbow_flex")] = 0.8
    rest = apply_shape(model, shape).joints
    transforms = bf.joint_transforms(model, params, rest)
    return TrackResult(stamp_ns, TrackerState.TRACKING, params=params, joints=transforms[:, :3, 3],
                       joint_names=tuple(skel.joint_names), shape=shape, transforms=transforms)


def _rig():
    # cam_near sees the whole body large; cam_far small; cam_away looks away from it
    return [look_at("cam_near", (0.0, 1.0, 2.5), (0.0, 1.0, 0.0), width=320, height=240, fx=200.0),
            look_at("cam_far", (0.0, 1.2, 7.0), (0.0, 1.0, 0.0), width=320, height=240, fx=200.0),
            look_at("cam_away", (0.0, 1.0, 3.0), (0.0, 1.0, 8.0), width=320, height=240, fx=200.0)]


def test_a_tracked_pose_gives_every_rep155_output(model):
    shape = BodyShape.neutral()
    factory = RosbagsFactory(hmocap_typestore())
    cameras = _rig()
    outputs = Rep155Outputs(["b0"], "room", cameras, factory, frame_prefix="room_1/", joint_frames=False)
    tracker = TrackerMessages(model, ["b0"], "room", factory)
    released = _released_store()
    height = float(shape.height(model))
    sent = []
    for i in range(3):
        result = _result(model, T0 + i * PERIOD, 0.01 * i, shape)
        built = tracker.frame_set(result.stamp_ns, [result], [model]).messages
        sent.append(dict(outputs.messages(result.stamp_ns, [result], [height], built)))
    assert set(rep155_topics("b0").values()) == set(REP155_OUTPUT_TYPES.values())
    first, second = sent[0], sent[1]
    # the URDF goes out with the first shape only
    assert "humans/bodies/b0/urdf" in first and "humans/bodies/b0/urdf" not in second
    assert first["humans/bodies/b0/urdf"].data.startswith("<?xml")
    # joint_states: the URDF's joints first, then the tracker's degrees of freedom
    js = first["humans/bodies/b0/joint_states"]
    assert list(js.name[:len(URDF_JOINTS)]) == [f"{n}_b0" for n in URDF_JOINTS]
    assert list(js.name[len(URDF_JOINTS):]) == list(model.skeleton.dof_names)
    joints, names = _result(model, T0, 0.0, shape).joints, list(model.skeleton.joint_names)
    upper, fore = (joints[names.index(b)] - joints[names.index(a)] for a, b in (("l_shoulder", "l_elbow"),
                                                                                  ("l_elbow", "l_wrist")))
    bend = np.arccos(upper @ fore / np.linalg.norm(upper) / np.linalg.norm(fore))
    assert js.position[list(js.name).index("l_elbow_b0")] == pytest.approx(bend, abs=1e-9)
    # skeleton2d and roi in the camera that sees the body best, normalised
    skel2d, roi = first["humans/bodies/b0/skeleton2d"], first["humans/bodies/b0/roi"]
    assert skel2d.header.frame_id == roi.header.frame_id == "cam_near_optical_frame"
    points = np.array([[p.x, p.y, p.c] for p in skel2d.skeleton])
    assert points.shape == (18, 3) and (points[:, :2] >= 0).all() and (points[:, :2] <= 1).all()
    assert (points[14:, 2] == 0).all() and (points[:14, 2] == 1).all()
    assert points[2, 0] < points[5, 0]  # the person faces the camera: the right shoulder on the left
    assert roi.xmin <= points[:14, 0].min() and roi.xmax >= points[:14, 0].max()
    assert roi.ymin <= points[:14, 1].min() and roi.ymax >= points[:14, 1].max() and roi.c == pytest.approx(1.0)
    # position: the pelvis in the room; velocity from the second pose on
    pelvis = _result(model, T0, 0.0, shape).joints[0]
    position = first["humans/bodies/b0/position"]
    assert position.header.frame_id == "room"
    np.testing.assert_allclose([position.point.x, position.point.y, position.point.z], pelvis, atol=1e-9)
    assert "humans/bodies/b0/velocity" not in first
    assert second["humans/bodies/b0/velocity"].twist.linear.x == pytest.approx(0.01 / (PERIOD * 1e-9))
    # /tf: the body frame only, prefixed, under the room frame
    tf = first["/tf"] if "/tf" in first else first["tf"]
    assert [(t.header.frame_id, t.child_frame_id) for t in tf.transforms] == [("room", "room_1/body_b0")]
    # every message serialises with the released definitions
    for msg in first.values():
        kind = msg.__msgtype__
        if kind.startswith("hri_msgs/") and kind in released.fielddefs:
            released.serialize_cdr(msg, kind)


def test_joint_frames_keep_every_frame_prefixed(model):
    shape = BodyShape.neutral()
    factory = RosbagsFactory(hmocap_typestore())
    outputs = Rep155Outputs(["b0"], "room", _rig(), factory, frame_prefix="r/")
    tracker = TrackerMessages(model, ["b0"], "room", factory)
    result = _result(model, T0, 0.0, shape)
    built = tracker.frame_set(T0, [result], [model]).messages
    tf = dict(outputs.messages(T0, [result], [1.7], built))
    tf = tf.get("/tf", tf.get("tf"))
    frames = [(t.header.frame_id, t.child_frame_id) for t in tf.transforms]
    assert frames[0] == ("room", "r/body_b0")
    assert len(frames) == len(model.skeleton.joint_names)
    assert all(parent.startswith("r/") and child.startswith("r/") for parent, child in frames[1:])


def test_no_camera_sees_the_body_no_image_outputs(model):
    factory = RosbagsFactory(hmocap_typestore())
    away = [look_at("cam_away", (0.0, 1.0, 3.0), (0.0, 1.0, 8.0), width=320, height=240, fx=200.0)]
    outputs = Rep155Outputs(["b0"], "room", away, factory)
    result = _result(model, T0, 0.0, BodyShape.neutral())
    topics = {t for t, _ in outputs.frame_set(T0, [result], [1.7])}
    assert topics == {"humans/bodies/b0/urdf", "humans/bodies/b0/position"}


def test_body_tracker_publishes_rep155_in_a_namespace(tmp_path):
    """The node in namespace /room_1 with ``frame_prefix:=room_1/`` and ``joint_frames:=false``:
    the per-body REP-155 topics under the namespace, /tf holding only the prefixed body frame,
    /diagnostics absolute; the URDF's joints are those of the joint_states."""
    import xml.etree.ElementTree as ET

    from hmocap_ros.demo import DEMO_BAG, DEMO_RIG
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.msg_factory import stamp_to_ns
    from hmocap_ros.processes import loopback_dds_env, replay_through_nodes

    cameras = ["cam_1", "cam_2", "cam_3", "cam_4"]
    remaps = [a for c in cameras for a in ("-r", f"/room_1/{c}/foreground:=/ground_truth/{c}/silhouette")]
    node = ("body_tracker", "hmocap_ros.nodes.body_tracker",
            ["--ros-args", "-r", "__ns:=/room_1", "-p", f"rig_file:={DEMO_RIG}", "-p", "method:=hpf-apo",
             "-p", "latest_only:=false", "-p", "queue_depth:=100", "-p", "filter.particles:=120",
             "-p", "filter.layers:=0", "-p", "startup.particles:=60", "-p", "startup.frames:=2",
             "-p", "frame_prefix:=room_1/", "-p", "joint_frames:=false", *remaps], "kernels ready")
    body = "/room_1/humans/bodies/b0"
    topics = [f"{body}/{name}" for name in ("urdf", "skeleton2d", "roi", "position", "velocity", "joint_states")]
    topics += ["/room_1/skeleton", "/tf", "/diagnostics"]
    with BagReader(DEMO_BAG) as reader:
        person = {stamp_to_ns(m.msg.header.stamp) for m in reader.messages(["/ground_truth/skeleton"])}
    out = tmp_path / "out.mcap"
    result = replay_through_nodes(DEMO_BAG, [node], topics, out, loopback_dds_env(), tmp_path / "logs",
                                  replay_topics=[f"/ground_truth/{c}/silhouette" for c in cameras],
                                  replay_rate=0.5, expect={"/room_1/skeleton": len(person) - 1}, settle=2.0)
    log = result["body_tracker"].output()
    assert "Traceback" not in log, log
    def stamp(msg) -> int:
        if hasattr(msg, "transforms"):
            return stamp_to_ns(msg.transforms[0].header.stamp)
        return stamp_to_ns(msg.header.stamp) if hasattr(msg, "header") else 0  # the URDF has none

    with BagReader(out) as reader:
        got = {t: {stamp(m.msg): m.msg for m in reader.messages([t])} for t in topics if t in reader.topics()}
    skeletons = got["/room_1/skeleton"]
    assert len(skeletons) >= len(person) - 1
    for name in ("skeleton2d", "roi", "position", "joint_states"):
        assert set(got[f"{body}/{name}"]) == set(skeletons), name
    assert len(got[f"{body}/velocity"]) >= len(skeletons) - 1
    assert got["/diagnostics"]
    assert all([(t.header.frame_id, t.child_frame_id) for t in msg.transforms] == [("room", "room_1/body_b0")]
               for msg in got["/tf"].values())
    urdf = ET.fromstring(next(iter(got[f"{body}/urdf"].values())).data)
    movable = {j.get("name") for j in urdf.findall("joint") if j.get("type") == "revolute"}
    names = list(next(iter(got[f"{body}/joint_states"].values())).name)
    assert movable == set(names[:len(URDF_JOINTS)])
    for msg in got[f"{body}/skeleton2d"].values():
        assert msg.header.frame_id.endswith("_optical_frame") and len(msg.skeleton) == 18
