"""The example apps driven from bags, every node and app its own process over DDS on loopback
(hmocap_examples.drive): the shipped depth recording through gesture_detection into
light_switch, and body_tracker's messages for a walk through the room's zones into presence.

Asserted: what each app published, on which input's stamp, and its reaction time, the DDS
publication time of its output minus that of the room's output it reacted to (target: under
200 ms); the scenes' bad input (a gesture without a 3D point, a skeleton short of a position, a
skeleton without its pelvis) and a zone file with an error are one log line each and the app
goes on. The tests wait on
messages, never on the wall clock.
"""

import re
from pathlib import Path

from hmocap_examples import scenes
from hmocap_examples.drive import drive_light_switch, drive_presence, light_reactions, reaction_ms
from hmocap_ros.io.msg_factory import stamp_to_ns
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
    assert re.search(r"light on: pause by .* near lamp", run.logs["light_switch"])


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
