"""The client's rclpy-free part: frames from /tf_static, RoomState's bodies, losses and gestures,
the geometry helpers, places from YAML and the once-per-hold trigger (messages built with the
rosbags factory, as a bag holds them)."""

import numpy as np
import pytest

from hmocap_ros.client import (
    Body,
    BoxPlace,
    OncePerHold,
    PlacesFile,
    PointPlace,
    RoomState,
    joint_above,
    nearest_hand,
    pointing_angle,
    pointing_at,
    pointing_ray,
    read_places,
    zones_containing,
)
from hmocap_ros.client.frames import StaticFrames
from hmocap_ros.io.msg_factory import RosbagsFactory, make_header
from hmocap_ros.io.tf import Y_UP_TO_Z_UP, FrameTransform, tf_message

F = RosbagsFactory()
NAMES = ("pelvis", "head", "l_elbow", "l_wrist", "r_elbow", "r_wrist")
S = 1_000_000_000


def _point(p):
    return F.make("geometry_msgs/msg/Point", x=float(p[0]), y=float(p[1]), z=float(p[2]))


def skeleton(body_id, stamp, positions, frame="room", names=NAMES):
    return F.make("hmocap_interfaces/msg/Skeleton", header=make_header(F, stamp, frame), body_id=body_id,
                  joint_names=list(names), positions=[_point(p) for p in positions],
                  parents=np.zeros(0, np.int32), confidence=np.ones(len(names), np.float32), fit_error=0.5)


def tracked(stamp, ids):
    return F.make("hri_msgs/msg/IdsList", header=make_header(F, stamp, "room"), ids=list(ids))


def gestures(stamp, frame, items):
    """items: (name, point or None)."""
    return F.make("hmocap_interfaces/msg/GestureArray", header=make_header(F, stamp, frame), gestures=[
        F.make("hmocap_interfaces/msg/Gesture", name=name, class_id=1, score=2.0, volume=0.1, u=10.0, v=20.0,
               position=_point(p if p is not None else (np.nan,) * 3), position_valid=p is not None)
        for name, p in items])


def world_room_tf():
    return tf_message([FrameTransform("world", "room", (0.0, 0.0, 0.0), Y_UP_TO_Z_UP)], 0, F)


#: a standing body in the room frame (+Y up): pelvis 1 m up at room (x, -z) = (1, -2), i.e. world (1, 2)
ROOM_POSE = np.array([[1.0, 1.0, -2.0], [1.0, 1.7, -2.0], [1.2, 1.3, -2.0], [1.4, 1.3, -2.0],
                      [0.8, 1.3, -2.0], [0.8, 1.0, -2.0]])


class Log(list):
    def __call__(self, text):
        self.append(text)


# -- frames ----------------------------------------------------------------------------------


def test_world_room_transform_is_the_published_one():
    frames = StaticFrames()
    frames.add_message(world_room_tf())
    # the rig's room is +Y up; world is +Z up: room y -> world z, room -z -> world y
    np.testing.assert_allclose(frames.transform_points([[1.0, 2.0, -3.0]], "world", "room"), [[1.0, 3.0, 2.0]],
                               atol=1e-12)
    np.testing.assert_allclose(frames.transform_points([[1.0, 3.0, 2.0]], "room", "world"), [[1.0, 2.0, -3.0]],
                               atol=1e-12)
    frames.add(FrameTransform("room", "cam", (0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0)))
    np.testing.assert_allclose(frames.transform_points([0.0, 0.0, 0.0], "world", "cam"), [0.0, -1.0, 0.0],
                               atol=1e-12)
    assert frames.lookup("world", "elsewhere") is None


# -- RoomState --------------------------------------------------------------------------------


def test_a_skeleton_before_the_transform_is_held_then_delivered_in_world():
    log = Log()
    state = RoomState(log=log)
    assert state.on_skeleton(skeleton("b0", 5 * S, ROOM_POSE), 0) == []
    assert len(log) == 1 and "no transform" in log[0]
    events = state.on_tf_static(world_room_tf(), 0)
    assert [kind for kind, _ in events] == ["body"]
    body = events[0][1]
    assert body.id == "b0" and body.stamp_ns == 5 * S and body.frame_id == "world"
    np.testing.assert_allclose(body.position, [1.0, 2.0, 1.0], atol=1e-12)
    assert joint_above(body, "head", "pelvis") is True and joint_above(body, "pelvis", "head") is False


def test_bodies_are_lost_by_the_tracked_list_by_stamps_going_back_and_by_silence():
    log = Log()
    state = RoomState(lost_after_ns=2 * S, log=log)
    state.on_tf_static(world_room_tf(), 0)
    state.on_skeleton(skeleton("b0", 10 * S, ROOM_POSE), 0)
    state.on_skeleton(skeleton("b1", 10 * S, ROOM_POSE + [0.0, 0.0, 1.0]), 0)
    # an older pose of b0 after a newer one is dropped
    assert state.on_skeleton(skeleton("b0", 9 * S, ROOM_POSE + 1.0), 0) == []
    assert state.bodies["b0"].stamp_ns == 10 * S
    assert state.on_tracked(tracked(11 * S, ["b1"]), 0) == [("lost", "b0")]
    assert set(state.bodies) == {"b1"}
    # a skeleton of the lost body not newer than its loss is dropped; a newer one brings it back
    assert state.on_skeleton(skeleton("b0", 11 * S, ROOM_POSE), 0) == []
    assert [k for k, _ in state.on_skeleton(skeleton("b0", 12 * S, ROOM_POSE), 0)] == ["body"]
    # the stamps go back by more than a second: the room starts over
    events = state.on_skeleton(skeleton("b1", 3 * S, ROOM_POSE), 1)
    assert sorted(events[:2]) == [("lost", "b0"), ("lost", "b1")] and events[2][0] == "body"
    assert any("went back" in line for line in log)
    # silence on the node's clock
    assert state.on_timer(1 + 2 * S) == []
    assert state.on_timer(2 + 2 * S) == [("lost", "b1")]
    assert state.bodies == {}


def test_bad_skeletons_are_one_log_line_each_and_the_state_goes_on():
    log = Log()
    state = RoomState(log=log)
    state.on_tf_static(world_room_tf(), 0)
    short = skeleton("b0", S, ROOM_POSE[:-1], names=NAMES)  # 5 positions for 6 names
    for _ in range(3):
        assert state.on_skeleton(short, 0) == []
    assert len(log) == 1 and "5 positions for 6 joint names" in log[0]
    no_pelvis = ROOM_POSE.copy()
    no_pelvis[0] = np.nan
    for k in range(3):
        events = state.on_skeleton(skeleton("b0", (2 + k) * S, no_pelvis), 0)
        body = events[0][1]
        assert body.joint("pelvis") is None and body.missing_joints == ("pelvis",)
        # where the body is without its root: the mean of the joints it has
        np.testing.assert_allclose(body.position, state.frames.transform_points(ROOM_POSE[1:].mean(0), "world", "room"))
    assert len(log) == 2 and "without a position for pelvis" in log[1]


def test_gestures_in_world_and_without_a_point():
    log = Log()
    state = RoomState(log=log)
    state.on_tf_static(world_room_tf(), 0)
    state.frames.add(FrameTransform("room", "depth", (0.0, 1.0, 0.0), (0.0, 0.0, 0.0, 1.0)))
    events = state.on_gestures(gestures(S, "depth", [("pause", (1.0, 0.5, -2.0)), ("silence", None)]), 0)
    assert [(k, g.name) for k, g in events] == [("gesture", "pause"), ("gesture", "silence")]
    pause, silence = (g for _, g in events)
    np.testing.assert_allclose(pause.point, [1.0, 2.0, 1.5], atol=1e-12)
    assert pause.stamp_ns == S and pause.source_frame == "depth" and silence.point is None
    state.on_gestures(gestures(2 * S, "depth", [("silence", None)]), 0)
    assert len(log) == 1 and "without a 3D point" in log[0]
    # a depth camera the room has no transform for: the point is None, one line
    events = state.on_gestures(gestures(3 * S, "other", [("pause", (0.0, 0.0, 1.0))] * 2), 0)
    assert [g.point for _, g in events] == [None, None]
    assert len(log) == 2 and "'other'" in log[1]


# -- geometry --------------------------------------------------------------------------------


def _body(joints: dict, body_id="b0") -> Body:
    names = tuple(joints)
    return Body(body_id, 0, "world", names, np.array([joints[n] for n in names], dtype=float))


def test_nearest_hand_names_the_body_and_side():
    a = _body({"l_wrist": [0.0, 0.0, 1.0], "r_wrist": [1.0, 0.0, 1.0]}, "b0")
    b = _body({"l_wrist": [2.0, 0.0, 1.0], "r_wrist": [np.nan] * 3}, "b1")
    body, side, distance = nearest_hand([a, b], [1.8, 0.0, 1.0], 0.5)
    assert (body.id, side) == ("b1", "left") and distance == pytest.approx(0.2)
    body, side, _ = nearest_hand([a, b], [1.1, 0.0, 1.0], 0.5)
    assert (body.id, side) == ("b0", "right")
    assert nearest_hand([a, b], [5.0, 0.0, 1.0], 0.5) is None
    assert joint_above(b, "r_wrist", "l_wrist") is None


def test_nearest_hand_is_the_nearer_of_two_bodies_hands_within_reach():
    # a right hand 0.1 m and a left hand 0.3 m from the gesture, both within reach (0.5 m), the
    # bodies' other hands out of it
    a = _body({"l_wrist": [0.0, 0.0, 0.6], "r_wrist": [1.1, 0.0, 1.2]}, "b0")
    b = _body({"l_wrist": [1.0, 0.3, 1.2], "r_wrist": [1.8, 0.3, 1.2]}, "b1")
    body, side, distance = nearest_hand([a, b], [1.0, 0.0, 1.2], 0.5)
    assert (body.id, side) == ("b0", "right") and distance == pytest.approx(0.1)
    # the gesture moved nearer the other body's hand: that body, in either order of the bodies
    for bodies in ([a, b], [b, a]):
        body, side, distance = nearest_hand(bodies, [1.0, 0.2, 1.2], 0.5)
        assert (body.id, side) == ("b1", "left") and distance == pytest.approx(0.1)


def _brute_force_angle(origin, direction, box: BoxPlace, n: int = 200) -> float:
    """The smallest angle to a dense grid on the box's surface (faces sampled n x n)."""
    s = np.linspace(0.0, 1.0, n)
    u, v = np.meshgrid(s, s)
    points = []
    for axis in range(3):
        a, b = [k for k in range(3) if k != axis]
        for side in (box.low[axis], box.high[axis]):
            p = np.empty((n * n, 3))
            p[:, axis] = side
            p[:, a] = box.low[a] + u.ravel() * (box.high[a] - box.low[a])
            p[:, b] = box.low[b] + v.ravel() * (box.high[b] - box.low[b])
            points.append(p)
    d = np.concatenate(points) - origin
    cosines = d @ direction / np.linalg.norm(d, axis=1)
    return float(np.degrees(np.arccos(np.clip(cosines.max(), -1, 1))))


def test_pointing_angle_against_a_box_matches_a_dense_search():
    rng = np.random.default_rng(47)
    box = BoxPlace([0.3, 0.45, 0.0], [0.6, 0.75, 1.6])
    for _ in range(20):
        origin = rng.uniform([-3, -2.5, 0.5], [3, 2.5, 2.0])
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        if np.all(box.contains(origin)):
            continue
        exact = pointing_angle(origin, direction, box)
        # a 200 x 200 grid on faces under 1.6 m: its points are within ~5 mm of the box's outline
        assert exact <= _brute_force_angle(origin, direction, box) + 1e-9
        assert exact == pytest.approx(_brute_force_angle(origin, direction, box), abs=0.5)
    # through the box: 0; straight away from a point: 180
    assert pointing_angle([0.45, -2.0, 1.0], [0.0, 1.0, 0.0], box) == 0.0
    assert pointing_angle([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], PointPlace([-1.0, 0.0, 0.0])) == pytest.approx(180.0)


def test_pointing_at_uses_the_forearm_ray():
    tv = BoxPlace([-0.7, 2.4, 0.8], [0.7, 2.5, 1.6])
    body = _body({"l_elbow": [0.0, 0.0, 1.2], "l_wrist": [0.0, 0.3, 1.25],      # towards the tv
                  "r_elbow": [0.3, 0.0, 1.2], "r_wrist": [0.6, 0.0, 1.2]})      # sideways
    origin, direction = pointing_ray(body, "left")
    np.testing.assert_allclose(origin, [0.0, 0.3, 1.25])
    assert np.linalg.norm(direction) == pytest.approx(1.0)
    assert pointing_at(body, tv) == "left"
    assert pointing_at(body, BoxPlace([2.0, -0.2, 1.0], [2.2, 0.2, 1.4])) == "right"
    assert pointing_at(body, BoxPlace([0.0, -3.0, 0.0], [0.2, -2.8, 0.2])) is None
    assert pointing_ray(_body({"l_elbow": [0.0, 0.0, 1.0], "l_wrist": [0.0, 0.01, 1.0]}), "left") is None


# -- places and triggers ----------------------------------------------------------------------


def test_places_file_reports_each_error_and_keeps_the_good_entries(tmp_path):
    path = tmp_path / "places.yaml"
    path.write_text("frame_id: world\nplaces:\n  tv: {point: [0, 2.45, 1.1]}\n  bad: {point: [0, 1]}\n"
                    "  lamp: {box: {min: [0, 0, 0], max: [1, 1, 1]}}\n  flat: {box: {min: [1, 1], max: [0, 2]}}\n")
    places, errors = read_places(path, "places", "world")
    assert set(places) == {"tv", "lamp"} and len(errors) == 2
    assert all(str(path) in e and "left out" in e for e in errors)
    assert read_places(path, "places", "map")[0] == {}
    assert "no 'zones:'" in read_places(path, "zones", "world")[1][0]
    (tmp_path / "broken.yaml").write_text("places: {tv: [\n")
    places, errors = read_places(tmp_path / "broken.yaml", "places", "world")
    assert places == {} and len(errors) == 1 and "cannot read" in errors[0]
    assert read_places(tmp_path / "missing.yaml", "places", "world")[0] == {}


def test_places_file_is_read_again_when_it_changes(tmp_path):
    path = tmp_path / "zones.yaml"
    path.write_text("zones:\n  door: {box: {min: [0, 0], max: [1, 1]}}\n")
    zones = PlacesFile(path, "zones", "world")
    assert list(zones.places) == ["door"] and not zones.reload_if_changed()
    path.write_text("zones:\n  door: {box: {min: [0, 0], max: [1, 1]}}\n  sofa: {box: {min: [2, 2], max: [3, 3]}}\n")
    assert zones.reload_if_changed() and list(zones.places) == ["door", "sofa"]
    path.unlink()
    assert not zones.reload_if_changed() and len(zones) == 2


def test_zones_keep_a_body_within_the_margin_and_the_trigger_counts_a_hold_once():
    zones = {"door": BoxPlace([0.0, 0.0], [1.0, 1.0])}
    assert zones_containing([0.5, 0.5, 1.0], zones) == {"door"}
    assert zones_containing([1.1, 0.5, 1.0], zones) == set()
    assert zones_containing([1.1, 0.5, 1.0], zones, inside={"door"}, margin=0.15) == {"door"}
    assert zones_containing(None, zones) == set()
    trigger = OncePerHold(S)
    assert [trigger(t) for t in (0, S // 10, S // 2, S, 3 * S, 3 * S + 1, S)] == \
        [True, False, False, False, True, False, True]
