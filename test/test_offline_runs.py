"""``hmocap detect gestures`` and ``hmocap track``: the detector and the tracker on a bag, into a bag.

The written bags hold what the nodes publish (the builders the nodes use:
:mod:`hmocap_ros.gestures.gesture_messages`, :mod:`hmocap_ros.tracking.tracker_messages`), with
the input frames' stamps, and open with ``hmocap info`` and ``hmocap export``. The builders give
the same messages as rclpy objects (the nodes) and as rosbags dataclasses (the bags).
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
from fixtures.gesture_cli import tiny_gesture_bag

from hmocap_ros.cli import main as hmocap
from hmocap_ros.demo import DEMO_BAG
from hmocap_ros.eval import gesture_eval as ge
from hmocap_ros.eval.gesture_detection_bag import output_topics
from hmocap_ros.gestures import load_forest
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.msg_factory import RclpyFactory, RosbagsFactory, stamp_to_ns
from hmocap_ros.io.tf import from_transform_stamped
from hmocap_ros.tracking.body_frames import joint_frame

#: a small tracker budget (the figures of the README come from ``hmocap eval mocap``)
SMALL = ["--param", "filter.particles=60", "--param", "filter.layers=0", "--param", "startup.particles=40",
         "--param", "startup.frames=2"]
#: the demo bag's 8 empty-room frames and 4 with the subject: start-up, then tracking
TRACK_FRAMES = 12


@pytest.fixture(scope="module")
def tiny_bag(tmp_path_factory):
    return tiny_gesture_bag(tmp_path_factory.mktemp("gestures"))


def _by_stamp(reader, topic: str) -> dict:
    return {stamp_to_ns(m.msg.header.stamp): (m.log_time_ns, m.msg) for m in reader.messages([topic])}


def test_output_topics_follow_the_depth_topics_namespace():
    assert output_topics("/depth/image_raw") == ("/gestures", "/gestures/probability")
    assert output_topics("/kitchen/depth/image_raw") == ("/kitchen/gestures", "/kitchen/gestures/probability")
    assert output_topics("/sr305/depth") == ("/gestures", "/gestures/probability")


def test_detect_gestures_writes_what_the_node_publishes(tiny_bag, tmp_path, capsys):
    out = tmp_path / "detected.mcap"
    assert hmocap(["detect", "gestures", str(tiny_bag), "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr()
    assert "Traceback" not in printed.err and str(out) in printed.out
    expected = ge.detect_gestures(tiny_bag, load_forest(ge.DEFAULT_MODEL))  # the evaluator's JSON
    with BagReader(tiny_bag) as reader:
        depth = _by_stamp(reader, "/depth/image_raw")
        infos = _by_stamp(reader, "/depth/camera_info")
    with BagReader(out) as reader:
        topics = reader.topics()
        gestures = _by_stamp(reader, "/gestures")
        probability = _by_stamp(reader, "/gestures/probability")
        copied = _by_stamp(reader, "/depth/camera_info")
    assert set(topics) == {"/gestures", "/gestures/probability", "/depth/camera_info"}
    # one GestureArray and one density image per depth frame, stamped and logged at its stamp
    assert set(gestures) == set(probability) == set(depth) and set(copied) == set(infos)
    assert all(log == stamp for stamp, (log, _) in gestures.items())
    frame_id = next(iter(depth.values()))[1].header.frame_id
    assert all(msg.header.frame_id == frame_id for _, msg in gestures.values())
    _, image = next(iter(probability.values()))
    assert image.encoding == "mono8" and (image.width, image.height) == (160, 120)
    # the detections of the evaluator's run of the same detector, frame by frame
    found = {s: [(g.name, round(float(g.u), 2), round(float(g.v), 2)) for g in msg.gestures]
             for s, (_, msg) in gestures.items()}
    assert found == {f["stamp_ns"]: [(g["name"], g["u"], g["v"]) for g in f["gestures"]]
                     for f in expected["per_frame"]}
    assert sum(map(len, found.values())) > 0
    # with a camera_info, every gesture has its 3D point in the depth optical frame
    points = [g for _, msg in gestures.values() for g in msg.gestures]
    assert all(g.position_valid and g.position.z > 0 for g in points)
    assert hmocap(["info", str(out)]) == 0


def test_detect_gestures_refuses_an_existing_output_and_a_bag_without_depth(tiny_bag, tmp_path, capsys):
    out = tmp_path / "exists.mcap"
    out.write_bytes(b"")
    assert hmocap(["detect", "gestures", str(tiny_bag), "--out", str(out)]) == 2
    assert "exists already" in capsys.readouterr().err
    assert hmocap(["detect", "gestures", str(DEMO_BAG), "--out", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err
    assert "no /depth/image_raw" in err and "--depth-topic" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.mcap").exists()


@pytest.fixture(scope="module")
def tracked(tmp_path_factory):
    """The demo bag tracked with two body slots on its silhouettes: (out bag, stdout)."""
    out = tmp_path_factory.mktemp("track") / "tracked.mcap"
    argv = ["track", str(DEMO_BAG), "--out", str(out), "--method", "hpf-apo", "--silhouettes", "gt",
            "--max-people", "2", "--frames", str(TRACK_FRAMES), "--quiet", *SMALL]
    assert hmocap(argv) == 0
    return out


def test_track_writes_the_tracker_topics_with_the_frame_sets_stamps(tracked, tmp_path):
    with BagReader(DEMO_BAG) as reader:
        inputs = sorted(_by_stamp(reader, "/ground_truth/cam_1/silhouette"))[:TRACK_FRAMES]
    b0 = "/humans/bodies/b0"
    with BagReader(tracked) as reader:
        topics = reader.topics()
        ids = _by_stamp(reader, "/humans/bodies/tracked")
        joints = _by_stamp(reader, f"{b0}/joint_states")
        skeletons = _by_stamp(reader, "/skeleton")
        markers = {stamp_to_ns(m.msg.markers[0].header.stamp) for m in reader.messages(["/skeleton_markers"])}
        tf = {stamp_to_ns(m.msg.transforms[0].header.stamp): m.msg for m in reader.messages(["/tf"])}
        shapes = [m.msg for m in reader.messages([f"{b0}/body_shape"])]
        rep155 = {t: _by_stamp(reader, f"{b0}/{t}") for t in ("skeleton2d", "roi", "position", "velocity")}
    assert {"/humans/bodies/tracked", f"{b0}/joint_states", f"{b0}/body_shape", "/body_shape",
            "/skeleton", "/skeleton_markers", "/tf"} <= set(topics)
    assert topics[f"{b0}/body_shape"].latched and topics["/body_shape"].latched
    assert "/humans/bodies/b1/body_shape" in topics  # the second slot's topics exist
    # the list of tracked bodies for every frame set; a pose on the frames with the subject
    assert sorted(ids) == inputs and all(log == stamp for stamp, (log, _) in ids.items())
    posed = {s for s, (_, msg) in ids.items() if list(msg.ids) == ["b0"]}
    assert posed and posed == set(joints) == set(skeletons) == set(tf)
    assert all(list(msg.ids) in ([], ["b0"]) for _, msg in ids.values())
    # the URDF's joints first (robot_state_publisher's), then the tracker's 30 DoFs; and the
    # rest of REP-155's per-body outputs, as the node publishes them
    from hmocap_ros.body.human_description import urdf_joint_names
    urdf_joints = urdf_joint_names("b0")
    assert all(list(js.name[:len(urdf_joints)]) == urdf_joints and len(js.name) == len(urdf_joints) + 30
               and js.header.frame_id == "room" for _, js in joints.values())
    assert topics[f"{b0}/urdf"].latched and topics[f"{b0}/urdf"].count >= 1
    assert set(rep155["position"]) == posed
    assert all(rep155[t] and set(rep155[t]) <= posed for t in rep155), {t: len(v) for t, v in rep155.items()}
    # the body frames on /tf place every joint where the skeleton has it
    for stamp, (_, sk) in skeletons.items():
        pose = {"room": np.eye(4)}
        for t in tf[stamp].transforms:
            pose[t.child_frame_id] = pose[t.header.frame_id] @ from_transform_stamped(t).matrix
        names = [joint_frame(n, "b0") for n in sk.joint_names]
        np.testing.assert_allclose([pose[n][:3, 3] for n in names],
                                   [[p.x, p.y, p.z] for p in sk.positions], atol=1e-6)
    assert set(markers) == posed and shapes and 1.0 < shapes[-1].height < 2.3
    # the bag reads with the other tools
    assert hmocap(["info", str(tracked)]) == 0
    assert hmocap(["export", str(tracked), "--format", "csv", "--out", str(tmp_path / "body.csv")]) == 0
    assert len((tmp_path / "body.csv").read_text().splitlines()) == len(posed) + 1


def test_track_is_repeatable(tracked, tmp_path):
    again = tmp_path / "again.mcap"
    argv = ["track", str(DEMO_BAG), "--out", str(again), "--method", "hpf-apo", "--silhouettes", "gt",
            "--max-people", "2", "--frames", str(TRACK_FRAMES), "--quiet", *SMALL]
    assert hmocap(argv) == 0
    topic = "/humans/bodies/b0/joint_states"
    with BagReader(tracked) as a, BagReader(again) as b:
        first = [np.asarray(m.msg.position) for m in a.messages([topic])]
        second = [np.asarray(m.msg.position) for m in b.messages([topic])]
    assert first and len(first) == len(second)
    assert all(np.array_equal(x, y) for x, y in zip(first, second))


def test_track_answers_bad_input_in_one_line(tmp_path, tiny_bag, capsys):
    cases = [(["track", str(tiny_bag)], "no /camera_rig"),
             (["track", str(DEMO_BAG), "--silhouettes", "masks"], "/cam_1/foreground"),
             (["track", str(DEMO_BAG), "--max-people", "0"], "--max-people"),
             (["track", str(DEMO_BAG), "--param", "filter.nonsense=1"], "nonsense")]
    for k, (argv, text) in enumerate(cases):
        out = tmp_path / f"out{k}.mcap"
        assert hmocap([*argv, "--out", str(out), "--quiet"]) == 2, argv
        err = capsys.readouterr().err
        assert text in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, (argv, err)
        assert not out.exists()


def _fake_result(model, has_pose: bool = True):
    """A tracker result of the rest pose (what TrackerMessages reads of a TrackResult)."""
    from hmocap_ros.tracking.body_frames import joint_transforms

    params = np.asarray(model.rest_pose(None), float)
    transforms = joint_transforms(model, params, model.joints_rest)
    return SimpleNamespace(has_pose=has_pose, params=params, joints=transforms[:, :3, 3],
                           joint_names=tuple(model.joint_names), confidence=np.linspace(0, 1, len(model.joint_names)),
                           fit_cost=0.5, shape=None, transforms=transforms)


def _fields(msg):
    """A message as plain Python values, whatever its flavour (rclpy or rosbags)."""
    if hasattr(msg, "get_fields_and_field_types"):
        return {k: _fields(getattr(msg, k)) for k in msg.get_fields_and_field_types()}
    if hasattr(msg, "__dataclass_fields__"):
        # rosbags keeps the type name and the constants (upper case, as ROS names them) as fields
        return {f.name: _fields(getattr(msg, f.name)) for f in dataclasses.fields(msg)
                if f.name != "__msgtype__" and not f.name.isupper()}
    if isinstance(msg, (list, tuple)):
        return [_fields(m) for m in msg]
    if hasattr(msg, "tolist"):
        return _fields(msg.tolist())
    if hasattr(msg, "typecode"):  # array.array
        return list(msg)
    return msg


def test_node_and_offline_builders_give_the_same_messages(model):
    from hmocap_ros.gestures.gesture_messages import gesture_array, probability_image
    from hmocap_ros.tracking.tracker_messages import TrackerMessages, tracker_topics

    results = [_fake_result(model), _fake_result(model, has_pose=False)]
    built = {}
    for name, factory in (("rclpy", RclpyFactory()), ("rosbags", RosbagsFactory())):
        messages = TrackerMessages(model, ("b0", "b1"), "room", factory)
        built[name] = messages.frame_set(1_500_000_000, results, [model, model])
    assert not built["rclpy"].errors and not built["rosbags"].errors
    topics = [t for t, _ in built["rclpy"].messages]
    assert topics == [t for t, _ in built["rosbags"].messages]
    assert topics == ["humans/bodies/b0/joint_states", "skeleton", "skeleton_markers",
                      "humans/bodies/tracked", "/tf"]
    assert set(topics) <= set(tracker_topics(("b0", "b1")))
    for (_, a), (_, b) in zip(built["rclpy"].messages, built["rosbags"].messages):
        assert _fields(a) == _fields(b)
    markers = dict(built["rclpy"].messages)["skeleton_markers"].markers
    # kept until replaced: a pose may come seconds after the last
    assert [(m.ns, m.action, m.lifetime.sec, m.lifetime.nanosec) for m in markers] == [("b0", 0, 0, 0)] * 2
    det = SimpleNamespace(name="wave", class_id=2, score=0.7, volume=0.3, u=40.0, v=30.0, depth_m=1.5)
    for flavour in (RclpyFactory(), RosbagsFactory()):
        msg = gesture_array([det], 7, "depth_optical_frame", None, flavour)
        assert msg.gestures[0].name == "wave" and not msg.gestures[0].position_valid
    assert _fields(gesture_array([det], 7, "f", None, RclpyFactory())) == \
        _fields(gesture_array([det], 7, "f", None, RosbagsFactory()))
    image = probability_image(np.full((4, 4), 0.5), 7, "f", RosbagsFactory())
    assert bytes(image.data) == bytes([127]) * 16


def test_markers_are_deleted_when_a_body_is_lost(model):
    """b0 and b1 tracked, then b1 lost: one DELETEALL array first, then b0's markers again;
    nothing is deleted while every body keeps its pose."""
    from hmocap_ros.tracking.tracker_messages import DELETEALL, TrackerMessages

    messages = TrackerMessages(model, ("b0", "b1"), "room", RclpyFactory())

    def markers(results):
        built = messages.frame_set(1_500_000_000, results, [model, model])
        return [[(m.ns, m.action) for m in msg.markers] for t, msg in built.messages if t == "skeleton_markers"]

    both = [_fake_result(model), _fake_result(model)]
    assert markers(both) == [[("b0", 0), ("b0", 0)], [("b1", 0), ("b1", 0)]]
    assert markers(both) == [[("b0", 0), ("b0", 0)], [("b1", 0), ("b1", 0)]]
    one = [_fake_result(model), _fake_result(model, has_pose=False)]
    assert markers(one) == [[("", DELETEALL)], [("b0", 0), ("b0", 0)]]
    assert markers(one) == [[("b0", 0), ("b0", 0)]]
    none = [_fake_result(model, has_pose=False)] * 2
    assert markers(none) == [[("", DELETEALL)]]
    assert markers(none) == []


def test_track_subcommand_answers_help(capsys):
    with pytest.raises(SystemExit) as exit_info:
        hmocap(["track", "--help"])
    assert exit_info.value.code == 0 and "usage: hmocap track" in capsys.readouterr().out
