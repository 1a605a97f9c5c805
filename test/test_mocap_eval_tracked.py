"""``hmocap eval mocap BAG --tracked TRACKED``: the bodies of a bag of ``hmocap track`` scored
against BAG's truth, on bags written here: two people with truth, two tracked bodies at known
offsets from them that swap people part-way, one body missing in a frame set, a frame set the
tracked bag lacks, and the bad inputs (no ``/skeleton``, stamps of another bag, a missing file,
a tracker's option).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hmocap_ros.cli import main as cli_main
from hmocap_ros.eval.metrics import LIMB_JOINTS
from hmocap_ros.geometry.rig import Rig, load_rig
from hmocap_ros.io import topics
from hmocap_ros.io.bag_writer import LATCHED, BagWriter
from hmocap_ros.io.msg_factory import default_factory, make_header
from hmocap_ros.io.rig_messages import rig_to_msg

ROOT = Path(__file__).resolve().parents[1]
STAMP0 = 1_700_000_000_000_000_000
PERIOD = 40_000_000
NAMES = ("pelvis", *LIMB_JOINTS)
#: frame sets with truth; the tracked bag has the first TRACKED_SETS of them
FRAME_SETS, TRACKED_SETS = 11, 10
#: the frame set from which the two bodies follow each other's person
SWAP = 6
#: each body's offset (m) from the person it follows: 30 mm along x, 40 mm along y
OFFSETS = {"b0": np.array([0.03, 0.0, 0.0]), "b1": np.array([0.0, 0.04, 0.0])}


def stamp(k: int) -> int:
    return STAMP0 + (k + 1) * PERIOD


def people(k: int) -> np.ndarray:
    """(2, J, 3) the two people in frame set ``k``: 2 m apart on x, walking along z."""
    rng = np.random.default_rng(0)
    base = rng.normal(0.0, 0.3, (2, len(NAMES), 3)) + np.array([0.0, 1.0, 0.0])
    base[1, :, 0] += 2.0
    return base + np.array([0.0, 0.0, 0.02 * k])


def skeleton(factory, topic_stamp: int, body_id: str, joints: np.ndarray):
    return factory.make(
        "hmocap_interfaces/msg/Skeleton", header=make_header(factory, topic_stamp, "room"),
        body_id=body_id, joint_names=list(NAMES),
        positions=[factory.make("geometry_msgs/msg/Point", x=float(p[0]), y=float(p[1]),
                                z=float(p[2])) for p in joints],
        parents=np.zeros(len(NAMES), np.int32))


def write_truth_bag(path: Path) -> None:
    """A rig and two people's truth (``/ground_truth/skeleton``, ``/ground_truth/body_1/
    skeleton``) over FRAME_SETS frame sets; no images."""
    full = load_rig(ROOT / "config" / "rig_example.yaml")
    rig = Rig(full.frame_id, tuple(full.cameras[:2]))
    factory = default_factory()
    with BagWriter(path) as bag:
        bag.add_topic(topics.CAMERA_RIG, "hmocap_interfaces/msg/CameraRig", LATCHED)
        bag.write(topics.CAMERA_RIG, rig_to_msg(rig, STAMP0, factory), STAMP0)
        for k in range(FRAME_SETS):
            for p, joints in enumerate(people(k)):
                topic = topics.GT_SKELETON if p == 0 else f"/ground_truth/body_{p}/skeleton"
                bag.write(topic, skeleton(factory, stamp(k), f"body_{p}", joints), stamp(k))


def write_tracked_bag(path: Path, shift_ns: int = 0) -> None:
    """What ``hmocap track`` writes of the bodies: ``/humans/bodies/tracked`` per frame set and a
    ``/skeleton`` per body with a pose. Body b0 follows person 0 and b1 person 1 until SWAP,
    then the other way round; b1 has no pose in the last tracked frame set; b0 has one in a
    frame set before the truth (an empty room)."""
    factory = default_factory()
    with BagWriter(path) as bag:
        bag.write("/humans/bodies/tracked", factory.make(
            "hri_msgs/msg/IdsList", header=make_header(factory, STAMP0 + shift_ns, "room"),
            ids=["b0"]), STAMP0 + shift_ns)
        bag.write("/skeleton", skeleton(factory, STAMP0 + shift_ns, "b0", people(0)[0]),
                  STAMP0 + shift_ns)
        for k in range(TRACKED_SETS):
            t = stamp(k) + shift_ns
            follows = {"b0": 0, "b1": 1} if k < SWAP else {"b0": 1, "b1": 0}
            posed = ["b0"] if k == TRACKED_SETS - 1 else ["b0", "b1"]
            bag.write("/humans/bodies/tracked", factory.make(
                "hri_msgs/msg/IdsList", header=make_header(factory, t, "room"), ids=posed), t)
            for body in posed:
                bag.write("/skeleton", skeleton(factory, t, body,
                                                people(k)[follows[body]] + OFFSETS[body]), t)


def run_eval(args: list[str]) -> int:
    return cli_main(["eval", "mocap", *args])


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tracked")
    truth, tracked = folder / "truth.mcap", folder / "tracked.mcap"
    write_truth_bag(truth)
    write_tracked_bag(tracked)
    return truth, tracked


def test_the_tracked_bodies_are_scored_per_person(bags, tmp_path, capsys):
    truth, tracked = bags
    out = tmp_path / "r.json"
    assert run_eval([str(truth), "--tracked", str(tracked), "--json", str(out)]) == 0
    captured = capsys.readouterr()
    assert "1 of the 11 frame sets with truth are not in the tracked bag" in captured.err
    assert "truth.mcap tracked: mean joint error" in captured.out and "body_1:" in captured.out
    report = json.loads(out.read_text())
    assert report["frame_sets"] == report["frames_with_truth"] == FRAME_SETS
    assert report["frame_sets_not_tracked"] == 1 and report["skeletons_elsewhere"] == 1
    assert report["body_ids"] == ["b0", "b1"] and list(report["methods"]) == ["tracked"]
    res = report["methods"]["tracked"]
    a, b = res["persons"]
    # person 0: b0 (30 mm) before the swap, b1 (40 mm) after it; b1 has no pose in frame set 9
    # and the tracked bag lacks frame set 10
    assert a["person_id"] == "body_0" and a["frames"] == FRAME_SETS
    assert a["frames_with_pose"] == 9 and a["frames_tracked"] == 9 and a["frames_seen"] == 11
    assert a["mean_mm"] == pytest.approx((SWAP * 30.0 + 3 * 40.0) / 9)
    assert a["id_switches"] == 1 and a["body_frames"] == {"b0": SWAP, "b1": 3}
    assert a["per_frame_mm"][9:] == [None, None] and a["seen_by"] == "truth"
    # person 1: b1 (40 mm), then b0 (30 mm) to the end of the tracked bag
    assert b["person_id"] == "body_1" and b["frames_with_pose"] == 10
    assert b["mean_mm"] == pytest.approx((SWAP * 40.0 + 4 * 30.0) / 10)
    assert b["limb_joints_mm"] == pytest.approx(b["mean_mm"])
    assert b["id_switches"] == 1 and b["body_frames"] == {"b1": SWAP, "b0": 4}
    # the subject on the body nearest it: b0, b1 after the swap, and in frame set 9 the only
    # body with a pose (b0, on person 1, 2 m off)
    assert res["frames"] == FRAME_SETS and res["frames_with_pose"] == 10
    assert res["per_frame_mm"][:9] == pytest.approx([30.0] * SWAP + [40.0] * 3)
    assert res["per_frame_mm"][9] > 1500.0 and res["per_frame_mm"][10] is None
    assert res["track_switches"] == 2
    # the same scores as the evaluation's own path gives for the same bodies
    from hmocap_ros.eval.mocap_frames import load_truth
    from hmocap_ros.eval.people_scores import score_tracks
    from hmocap_ros.eval.tracked_eval import read_tracked

    frames = load_truth(truth)
    found = read_tracked(tracked, frames.stamps)
    scores = score_tracks(frames, found.bodies, NAMES, np.arange(len(NAMES)), found.body_ids)
    assert scores.persons[0]["mean_mm"] == pytest.approx(a["mean_mm"])
    assert scores.subject_body == 0 and scores.subject_bodies.tolist()[:SWAP + 1] == [0] * SWAP + [1]


def test_the_frames_option_limits_the_frame_sets(bags, tmp_path):
    truth, tracked = bags
    out = tmp_path / "r.json"
    assert run_eval([str(truth), "--tracked", str(tracked), "--frames", "4", "--json", str(out)]) == 0
    res = json.loads(out.read_text())["methods"]["tracked"]
    assert res["frames"] == 4 and res["mean_mm"] == pytest.approx(30.0)
    assert [p["id_switches"] for p in res["persons"]] == [0, 0]


def test_bad_tracked_bags_and_options_are_refused_in_one_line(bags, tmp_path, capsys):
    truth, tracked = bags
    no_skeleton = tmp_path / "no_skeleton.mcap"
    with BagWriter(no_skeleton) as w:
        w.write("/chatter", default_factory().make("std_msgs/msg/String", data="hi"), STAMP0)
    shifted = tmp_path / "shifted.mcap"
    write_tracked_bag(shifted, shift_ns=1_000_000)
    cases = [
        ([str(truth), "--tracked", str(no_skeleton)], "no /skeleton"),
        ([str(truth), "--tracked", str(shifted)], "tracked another bag"),
        ([str(truth), "--tracked", str(tmp_path / "missing.mcap")], "does not exist"),
        ([str(tmp_path / "missing.mcap"), "--tracked", str(tracked)], "does not exist"),
        ([str(truth), "--tracked", str(tracked), "--method", "hpf", "--particles", "40"],
         "--method, --particles only apply when tracking"),
        ([str(truth), "--tracked", str(tracked), "--max-people", "2"], "--max-people"),
    ]
    for args, text in cases:
        capsys.readouterr()
        assert run_eval(args) == 2, args
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and text in err, (args, err)
        assert "Traceback" not in err


def test_the_tracker_options_defaults_are_the_parsers():
    import argparse

    from hmocap_ros.commands.eval_mocap import TRACKING_OPTIONS, add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    ns = parser.parse_args(["BAG"])
    for dest, (flag, default) in TRACKING_OPTIONS.items():
        assert getattr(ns, dest) == default, flag
        assert flag in parser._option_string_actions, flag
