"""The example apps driven from bags, every node and app its own process over DDS on loopback
(hmocap_examples.drive): the shipped depth recording through gesture_detection into
light_switch, and body_tracker's messages for a walk through the room's zones into presence.

Asserted: what each app published, on which input's stamp, and its reaction time, the DDS
publication time of its output minus that of the room's output it reacted to (target: under
200 ms); the scenes' bad input (a gesture without a 3D point, a skeleton short of a position, a
skeleton without its pelvis) and a zone file with an error are one log line each and the app
goes on. These tests wait on messages, never on the wall clock.

The light's rules without rclpy (:class:`hmocap_examples.light_switch.Light`, fed the room's
messages through :class:`~hmocap_ros.client.RoomState` in this process): the body named is the
one whose hand made the gesture, and the cool-down runs on the stamps at any replay rate (a
wall-clock pause between two holds changes nothing).
"""

import time
from pathlib import Path

import numpy as np

from hmocap_examples import scenes
from hmocap_examples.drive import drive_light_switch, drive_presence, light_reactions, reaction_ms
from hmocap_examples.light_switch import Light, LightSwitchConfig
from hmocap_ros.client import Gesture, PlacesFile, RoomState
from hmocap_ros.io.msg_factory import RosbagsFactory, make_header, stamp_to_ns
from hmocap_ros.io.tf import tf_message
from hmocap_ros.processes import loopback_dds_env

ROOT = Path(__file__).resolve().parents[1]
#: (ms) the issue's target for an app's reaction to the output it depends on
REACTION_TARGET_MS = 200.0


def _warnings(log: str, text: str) -> list[str]:
    return [line for line in log.splitlines() if "WARN" in line and text in line]


def test_light_switch_toggles_once_for_a_pause_held_at_the_lamp(tmp_path):
    bag = scenes.gesture_scene(tmp_path)
    run = drive_light_switch(bag, tmp_path / "run", loopback_dds_env())
    light = [n.msg.data for n in run.messages["/light"]]
    assert light == [False, True], run.logs["light_switch"]
    # the toggle answers the first depth frame with the pause (the hold's first detection)
    pause_stamps = [stamp_to_ns(n.msg.header) for n in run.messages["/gestures"]
                    if any(g.name == "pause" for g in n.msg.gestures)]
    assert len(pause_stamps) >= 3  # held over several frames, toggled once
    ((stamp, ms),) = light_reactions(run)
    assert stamp == min(pause_stamps)
    assert 0.0 <= ms < REACTION_TARGET_MS
    # the first second has no camera_info: its gestures come without a 3D point, one line, the app goes on
    assert len(_warnings(run.logs["light_switch"], "without a 3D point")) == 1
    # the scene has no skeleton: nobody's hand made the pause
    assert "light on: pause by someone near lamp" in run.logs["light_switch"]


F = RosbagsFactory()
S = 1_000_000_000
#: (m, world) a pause 0.15 m from the example room's lamp (config/places_example.yaml)
PAUSE_POINT = (0.75, 0.6, 1.2)


def _light(**config) -> Light:
    places = PlacesFile(ROOT / "config" / "places_example.yaml", "places", "world")
    return Light(LightSwitchConfig(**config), places)


def _room(world) -> list:
    """A world point (+Z up) in the scenes' room frame (+Y up)."""
    return [world[0], world[2], -world[1]]


def _skeleton(body_id: str, stamp: int, l_wrist, r_wrist):
    """A skeleton in the room frame: the body's pelvis and wrists (world points)."""
    names = ("pelvis", "l_wrist", "r_wrist")
    pelvis = (r_wrist[0], r_wrist[1] - 0.3, 1.0)
    return F.make("hmocap_interfaces/msg/Skeleton", header=make_header(F, stamp, scenes.ROOM), body_id=body_id,
                  joint_names=list(names),
                  positions=[F.make("geometry_msgs/msg/Point", **dict(zip("xyz", map(float, _room(p)))))
                             for p in (pelvis, l_wrist, r_wrist)],
                  parents=np.zeros(0, np.int32), confidence=np.ones(3, np.float32), fit_error=0.5)


def _pause_message(stamp: int, point):
    gesture = F.make("hmocap_interfaces/msg/Gesture", name="pause", class_id=1, score=2.0, volume=0.1, u=80.0,
                     v=60.0, position=F.make("geometry_msgs/msg/Point", **dict(zip("xyz", map(float, _room(point))))),
                     position_valid=True)
    return F.make("hmocap_interfaces/msg/GestureArray", header=make_header(F, stamp, scenes.ROOM),
                  gestures=[gesture])


def _log_of_a_pause(hands: dict) -> str | None:
    """The light's log line for a pause at :data:`PAUSE_POINT` made among bodies whose right
    wrists are ``hands`` (id -> world point; their left wrists hang 0.6 m below, out of reach)."""
    state = RoomState(log=print)
    state.on_tf_static(tf_message([scenes.room_to_world()], 0, F), 0)
    for body_id, wrist in hands.items():
        state.on_skeleton(_skeleton(body_id, S, (wrist[0], wrist[1], wrist[2] - 0.6), wrist), 0)
    ((_, gesture),) = state.on_gestures(_pause_message(S, PAUSE_POINT), 0)
    return _light().on_gesture(gesture, state)


def test_light_switch_names_the_body_whose_hand_made_the_pause():
    # both right hands within reach of the pause (0.5 m): the nearer made it, whichever id it has
    near, farther = (0.85, 0.6, 1.2), (0.75, 0.9, 1.2)  # 0.1 m and 0.3 m from the pause
    assert _log_of_a_pause({"b0": near, "b1": farther}) == "light on: pause by b0 near lamp"
    assert _log_of_a_pause({"b0": farther, "b1": near}) == "light on: pause by b1 near lamp"
    # no hand within reach: nobody is named
    assert _log_of_a_pause({"b0": (2.0, 0.6, 1.2)}) == "light on: pause by someone near lamp"


#: (s) the cool-down of the replay test, and the wall-clock pause of its slow replay (longer)
COOLDOWN_S, SLOW_PAUSE_S = 0.1, 0.25


def _pause(stamp: int) -> Gesture:
    return Gesture(name="pause", class_id=1, score=2.0, volume=0.1, u=80.0, v=60.0, stamp_ns=stamp,
                   source_frame="depth_optical_frame", point=np.array(PAUSE_POINT))


def _toggles(gap_ns: int, pause_s: float) -> int:
    """Toggles of the light for two holds of a pause, 3 frames at 100 fps each, the second
    ``gap_ns`` (stamps) after the first, replayed without waiting but for ``pause_s`` of wall
    time between the holds."""
    light = _light(cooldown_s=COOLDOWN_S)
    nobody = RoomState(log=print)
    hold = [k * S // 100 for k in range(3)]
    lines = [light.on_gesture(_pause(t), nobody) for t in hold]
    time.sleep(pause_s)
    lines += [light.on_gesture(_pause(hold[-1] + gap_ns + t), nobody) for t in hold]
    return sum(line is not None for line in lines)


def test_light_cooldown_counts_by_the_stamps_at_any_replay_rate():
    close, apart = int(0.5 * COOLDOWN_S * 1e9), int(3 * COOLDOWN_S * 1e9)
    # holds closer than the cool-down in the stamps are one hold, replayed faster or slower
    # than they were stamped; further apart they toggle twice
    assert [_toggles(close, pause) for pause in (0.0, SLOW_PAUSE_S)] == [1, 1]
    assert [_toggles(apart, pause) for pause in (0.0, SLOW_PAUSE_S)] == [2, 2]


#: the walk's zone changes in order: (zone, ids in it after the change)
WALK_CHANGES = [("door", "b0"), ("sofa", "b1"), ("door", ""), ("middle", "b0"), ("middle", ""), ("sofa", "")]


def test_presence_follows_a_walk_through_the_zones_in_order(tmp_path):
    bag = scenes.walk_scene(tmp_path)
    # the example room's zones and one with an error: a line, the other zones still work
    zones = tmp_path / "zones.yaml"
    zones.write_text((ROOT / "config" / "places_example.yaml").read_text()
                     + "  hall: {box: {min: [0.0, 0.0], max: [0.0, 1.0]}}\n")
    run = drive_presence(bag, tmp_path / "run", loopback_dds_env(), [f"zones_file:={zones}"],
                         changes=len(WALK_CHANGES))
    assert len(_warnings(run.logs["presence"], "zones hall:")) == 1
    states = [{s.name: s.message for s in n.msg.status} for n in run.messages["/presence"]]
    assert set(states[0]) == {"door", "middle", "by_the_window", "sofa"} and not any(states[0].values())
    changes = [next((zone, now[zone]) for zone in now if now[zone] != before[zone])
               for before, now in zip(states, states[1:])]
    assert changes == WALK_CHANGES, run.logs["presence"]
    stamps = [stamp_to_ns(n.msg.header) for n in run.messages["/presence"][1:]]
    assert stamps == sorted(stamps)
    # every change answers a body message of its stamp, within the target
    inputs = run.messages["/skeleton"] + run.messages["/humans/bodies/tracked"]
    reactions = reaction_ms(inputs, run.messages["/presence"][1:])
    assert [s for s, _ in reactions] == stamps
    assert all(0.0 <= ms < REACTION_TARGET_MS for _, ms in reactions), reactions
    # b1 leaves the sofa when the tracked list no longer holds it (the frames after the walk)
    nobody = [stamp_to_ns(n.msg.header) for n in run.messages["/humans/bodies/tracked"] if not n.msg.ids]
    assert stamps[-1] == min(nobody)
    # bad skeletons: one line each, and b0's later poses still move it through the zones
    assert len(_warnings(run.logs["presence"], "18 positions for 19 joint names")) == 1
    assert len(_warnings(run.logs["presence"], "without a position for pelvis")) == 1
