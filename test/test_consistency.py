"""``hmocap eval consistency`` on the shipped demo bag, where the truth is known.

The bag's own ground truth, written as body_tracker's output (``/skeleton``, the body's joint
states and shape), is a tracked body that is right: its joints reproject onto the landmark
network's keypoints within the network's precision (a few pixels at 160x120), its rendered
silhouette covers the foreground, and its joints lie within the landmark-to-joint offsets
(hip and shoulder landmarks are not the skeleton's joint centres: about 5 cm) of the plain
triangulation. The same body moved 25 cm sideways must be told apart on all three checks.
"""
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from hmocap_ros.cli import main
from hmocap_ros.eval.consistency import consistency_report, silhouette_iou
from hmocap_ros.export.motion import read_motion
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.bag_writer import LATCHED, whole_bag

DEMO_BAG = Path(__file__).resolve().parents[1] / "hmocap_ros" / "data" / "demo" / "mocap_4cam.mcap"
#: 8 empty frames, then 8 with the subject
FRAMES = 16
KEYS = ("frames", "frames_with_pose", "reprojection_median_px", "reprojection_p90_px",
        "silhouette_iou_mean", "triangulation_gap_mm")


def test_silhouette_iou_counts_overlap_over_union():
    a = np.zeros((4, 5), np.uint8)
    b = np.zeros((4, 5), np.uint8)
    assert silhouette_iou(a, b) is None
    a[0:2, 0:2] = 255  # 4 pixels
    b[1:3, 0:2] = 1  # 4 pixels, 2 shared
    assert silhouette_iou(a, b) == pytest.approx(2 / 6)
    assert silhouette_iou(a, a) == 1.0


@pytest.fixture(scope="module")
def truth():
    return read_motion(DEMO_BAG, "truth")


def _moved(motion, dx: float):
    """The motion moved ``dx`` metres along the room's x axis (skeleton and root translation)."""
    points = motion.points + np.array([dx, 0.0, 0.0])
    dofs = motion.dofs.copy()
    dofs[:, list(motion.dof_names).index("root_tx")] += dx
    return dataclasses.replace(motion, points=points, dofs=dofs)


def test_the_true_body_is_consistent_and_a_moved_one_is_not(truth):
    right = consistency_report(DEMO_BAG, truth, max_frames=FRAMES)
    wrong = consistency_report(DEMO_BAG, _moved(truth, 0.25), max_frames=FRAMES)
    for report in (right, wrong):
        assert report["frames"] == FRAMES and report["frames_with_pose"] == FRAMES - 8
        assert report["keypoint_pairs"] > 100 and report["triangulated_points"] > 30
    assert right["reprojection_median_px"] < 3.0 and right["reprojection_p90_px"] < 6.0
    assert right["silhouette_iou_mean"] > 0.7
    assert right["triangulation_gap_mm"] < 80.0
    # 25 cm at 3-4 m from a 160-px-wide camera (fx about 140 px) is about 10 px across the view
    assert wrong["reprojection_median_px"] > 2.5 * right["reprojection_median_px"]
    assert wrong["silhouette_iou_mean"] < right["silhouette_iou_mean"] - 0.3
    assert 180.0 < wrong["triangulation_gap_mm"] < 320.0
    per_view = right["per_view"]
    assert set(per_view) == {"cam_1", "cam_2", "cam_3", "cam_4"}
    assert all(v["reprojection"]["count"] > 0 for v in per_view.values())
    assert set(right["per_joint"]) >= {"left_wrist", "right_knee"}


def _tracked_bag(path: Path) -> None:
    """The demo bag's ground truth on body_tracker's topics."""
    renamed = {"/ground_truth/skeleton": ["/skeleton"],
               "/ground_truth/joint_states": ["/humans/bodies/body_0/joint_states"],
               "/ground_truth/body_shape": ["/body_shape", "/humans/bodies/body_0/body_shape"]}
    with BagReader(DEMO_BAG) as reader, whole_bag(path) as writer:
        for topic in ("/body_shape", "/humans/bodies/body_0/body_shape"):
            writer.add_topic(topic, "hmocap_interfaces/msg/BodyShape", LATCHED)
        for item in reader.messages(list(renamed)):
            for topic in renamed[item.topic]:
                writer.write(topic, item.msg, item.log_time_ns)


def test_cli_checks_a_tracked_bag_and_writes_the_issue_keys(tmp_path, capsys, truth):
    tracked = tmp_path / "tracked.mcap"
    _tracked_bag(tracked)
    out = tmp_path / "report.json"
    picture = tmp_path / "consistency.png"
    assert main(["eval", "consistency", str(DEMO_BAG), "--tracked", str(tracked), "--json", str(out),
                 "--frames", str(FRAMES), "--picture", str(picture), "--quiet"]) == 0
    report = json.loads(out.read_text())
    assert all(key in report for key in KEYS)
    assert report["tracked"] == str(tracked)
    direct = consistency_report(DEMO_BAG, truth, max_frames=FRAMES)
    for key in KEYS:
        assert report[key] == pytest.approx(direct[key])
    assert picture.stat().st_size > 10_000
    assert "a pose on 8 of 16 frame sets" in capsys.readouterr().out


def _two_body_bag(path: Path) -> None:
    """The demo bag's ground truth as body_0 and, 25 cm along the room's x axis, as body_1; a
    third slot, body_2, that never tracked anybody."""
    import copy

    with BagReader(DEMO_BAG) as reader, whole_bag(path) as writer:
        writer.add_topic("/body_shape", "hmocap_interfaces/msg/BodyShape", LATCHED)
        for body in ("body_0", "body_1", "body_2"):
            writer.add_topic(f"/humans/bodies/{body}/body_shape", "hmocap_interfaces/msg/BodyShape",
                             LATCHED)
            writer.add_topic(f"/humans/bodies/{body}/joint_states", "sensor_msgs/msg/JointState")
        for item in reader.messages(["/ground_truth/skeleton", "/ground_truth/joint_states",
                                     "/ground_truth/body_shape"]):
            moved = copy.deepcopy(item.msg)
            if item.topic.endswith("skeleton"):
                moved.body_id = "body_1"
                for p in moved.positions:
                    p.x += 0.25
                writer.write("/skeleton", item.msg, item.log_time_ns)
                writer.write("/skeleton", moved, item.log_time_ns)
            elif item.topic.endswith("joint_states"):
                moved.position[list(moved.name).index("root_tx")] += 0.25
                writer.write("/humans/bodies/body_0/joint_states", item.msg, item.log_time_ns)
                writer.write("/humans/bodies/body_1/joint_states", moved, item.log_time_ns)
            else:
                moved.body_id = "body_1"
                writer.write("/body_shape", item.msg, item.log_time_ns)
                writer.write("/humans/bodies/body_0/body_shape", item.msg, item.log_time_ns)
                writer.write("/humans/bodies/body_1/body_shape", moved, item.log_time_ns)


def test_every_tracked_body_is_checked_and_the_frame_sets_counted_by_bodies(tmp_path, truth):
    """Each body slot of the tracked bag gets its own figures under ``bodies`` (the first
    body's also at the top level); the displaced body disagrees with the images, the slot that
    tracked nobody has no pose; ``frames_with_bodies`` counts the frame sets by bodies posed."""
    tracked = tmp_path / "two.mcap"
    _two_body_bag(tracked)
    out = tmp_path / "report.json"
    assert main(["eval", "consistency", str(DEMO_BAG), "--tracked", str(tracked), "--json", str(out),
                 "--frames", str(FRAMES), "--quiet"]) == 0
    report = json.loads(out.read_text())
    bodies = report["bodies"]
    assert [b["body_id"] for b in bodies] == ["body_0", "body_1", "body_2"]
    direct = consistency_report(DEMO_BAG, truth, max_frames=FRAMES)
    for key in KEYS:
        assert report[key] == pytest.approx(direct[key]), key
    assert bodies[0]["reprojection_median_px"] == pytest.approx(direct["reprojection_median_px"])
    assert bodies[1]["frames_with_pose"] == bodies[0]["frames_with_pose"] == FRAMES - 8
    assert bodies[1]["reprojection_median_px"] > 2.5 * bodies[0]["reprojection_median_px"]
    assert bodies[2]["frames_with_pose"] == 0 and bodies[2]["reprojection_median_px"] is None
    assert report["frames_with_bodies"] == {"0": 8, "2": FRAMES - 8}


def test_triangulated_points_fall_as_min_views_rises(tmp_path):
    # a point seen by 4 views is seen by 2: --min-views 4 keeps fewer points than 2, as some of
    # the body's joints are hidden from one or two of the 4 cameras (about 60 and 96 here)
    tracked = tmp_path / "tracked.mcap"
    _tracked_bag(tracked)
    counts = []
    for min_views in (2, 4):
        out = tmp_path / f"report{min_views}.json"
        assert main(["eval", "consistency", str(DEMO_BAG), "--tracked", str(tracked), "--json", str(out),
                     "--frames", str(FRAMES), "--min-views", str(min_views), "--quiet"]) == 0
        report = json.loads(out.read_text())
        assert report["min_views"] == min_views
        counts.append(report["triangulated_points"])
    assert counts[1] < counts[0], counts


def test_cli_tracks_on_the_fly_without_tracked(tmp_path):
    out = tmp_path / "report.json"
    assert main(["eval", "consistency", str(DEMO_BAG), "--json", str(out), "--frames", "10",
                 "--quiet"]) == 0
    report = json.loads(out.read_text())
    assert report["frames"] == 10 and report["tracked"] is None
    assert report["tracking"]["frame_sets"] == 10
    assert report["frames_with_pose"] == report["tracking"]["with_pose"]


@pytest.mark.parametrize("case, expected", [
    ("missing", "does not exist"),
    ("untracked", "not body_tracker's output"),
    ("min_views", "--min-views must be >= 2"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, case, expected):
    args = ["eval", "consistency", str(DEMO_BAG), "--json", str(tmp_path / "r.json"), "--quiet"]
    if case == "missing":
        args[2] = str(tmp_path / "nothere.mcap")
    elif case == "untracked":
        args += ["--tracked", str(DEMO_BAG)]
    else:
        args += ["--min-views", "1"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert expected in err and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "r.json").exists()
