"""Extremity detection on the shipped bag (keypoints and skin), scored against its ground truth
and against a baseline computed here that never looks at the images after the first frame;
the pipeline's bad input; the message conversion; ``hmocap eval extremities``."""
from __future__ import annotations

import json

import numpy as np
import pytest

from hmocap_ros.cli import main as cli_main
from hmocap_ros.demo import DEMO_BAG
from hmocap_ros.detection.detections import Detections, detections_from_msg, fill_msg
from hmocap_ros.detection.extremity_pipeline import ExtremityDetectionParams, ExtremityPipeline, skeleton_labels
from hmocap_ros.detection.keypoint_network import ModelFileError
from hmocap_ros.eval.extremity_eval import frame_truths, score_detections, true_extremities
from hmocap_ros.eval.mocap_frames import load_frames

HEAD_AND_HANDS = ("head", "left_hand", "right_hand")


@pytest.fixture(scope="module")
def keypoint_frames():
    return load_frames(DEMO_BAG, "gt", detector=ExtremityDetectionParams(detector="keypoints"))


def test_keypoints_find_head_and_hands_where_a_held_detection_does_not(keypoint_frames):
    frames = keypoint_frames
    truths = frame_truths(frames, true_extremities(DEMO_BAG, frames.stamps))
    scores = score_detections(frames.detections, truths)["labels"]
    # the person waves at 160x120: hands within 10 cm in most frames
    for label in HEAD_AND_HANDS:
        assert scores[label]["recall"] >= 0.7 and scores[label]["precision"] >= 0.7, scores[label]
    assert scores["head"]["median_error_mm"] < 50, scores["head"]
    # baseline: the first frame's detections held for the whole bag (a detector that stopped
    # looking); the waving hands leave them
    first = next(d for d, t in zip(frames.detections, truths) if t and d is not None and len(d))
    held = score_detections([first if d is not None else None for d in frames.detections],
                            truths)["labels"]
    hands = ("left_hand", "right_hand")
    assert np.mean([scores[h]["median_error_mm"] for h in hands]) < 0.6 * np.mean(
        [held[h]["median_error_mm"] for h in hands]), (scores, held)
    # the limb joints are labelled too
    assert {"left_elbow", "right_knee", "left_shoulder"} <= set(scores)


def test_skin_candidates_are_unlabelled_without_a_skeleton_and_labelled_with_one(keypoint_frames):
    rig = keypoint_frames.rig
    pipe = ExtremityPipeline(rig.cameras, ExtremityDetectionParams(detector="skin"))
    from hmocap_ros.io.bag_reader import BagReader
    from hmocap_ros.io.conversions import image_to_rgb

    k = len(keypoint_frames.stamps) - 3
    stamp = int(keypoint_frames.stamps[k])
    images = {}
    with BagReader(DEMO_BAG) as reader:
        for m in reader.messages([f"/{n}/image_raw" for n in rig.names]):
            if m.msg.header.stamp.sec * 10**9 + m.msg.header.stamp.nanosec == stamp:
                images[m.topic.split("/")[1]] = image_to_rgb(m.msg)
    masks = [m * np.uint8(255) for m in keypoint_frames.mask_list(k)]
    det = pipe.detect([images[n] for n in rig.names], masks)
    assert det.detector == "skin" and len(det) > 0 and set(det.labels) == {"unknown"}
    assert len(det.points) == len(det.probability) > 0
    truth = keypoint_frames.truth[k]
    previous = skeleton_labels(keypoint_frames.joint_names, truth)
    labelled = pipe.detect([images[n] for n in rig.names], masks, previous)
    assert set(labelled.labels) - {"unknown"} <= {"head", "left_hand", "right_hand"}
    assert set(labelled.labels) != {"unknown"}, labelled.labels


def test_pipeline_bad_input_and_model_file(tmp_path, keypoint_frames, caplog):
    rig = keypoint_frames.rig
    pipe = ExtremityPipeline(rig.cameras, ExtremityDetectionParams(detector="keypoints"))
    cams = rig.cameras
    with pytest.raises(ValueError):
        pipe.detect([None], [None])
    # a view of another size, a grey image, no views at all: left out, logged, no exception
    wrong = [np.zeros((c.height + 2, c.width, 3), np.uint8) for c in cams]
    grey = [np.zeros((c.height, c.width), np.uint8) for c in cams]
    assert len(pipe.detect(wrong, [None] * len(cams))) == 0
    assert len(pipe.detect(grey, [None] * len(cams))) == 0
    assert len(pipe.detect([None] * len(cams), [None] * len(cams))) == 0
    assert "view left out" in caplog.text
    # the model file missing or corrupt: one error naming the file
    for path in (tmp_path / "missing.tflite", tmp_path / "corrupt.tflite"):
        if path.name.startswith("corrupt"):
            path.write_bytes(b"not a model")
        with pytest.raises(ModelFileError, match=path.name):
            ExtremityPipeline(cams, ExtremityDetectionParams(detector="keypoints"), path)
    with pytest.raises(ValueError, match="detector"):
        ExtremityDetectionParams(detector="magic")


def test_detections_message_round_trip():
    from geometry_msgs.msg import Point, Vector3
    from hmocap_interfaces.msg import Extremities

    det = Detections("keypoints", ("head", "left_elbow"), np.array([[0, 1.7, 0], [0.3, 1.2, 0.1]]),
                     np.array([0.9, 0.5]))
    back = detections_from_msg(fill_msg(Extremities(), det, Point, Vector3))
    assert back.detector == "keypoints" and back.labels == det.labels
    np.testing.assert_allclose(back.positions, det.positions)
    np.testing.assert_allclose(back.scores, det.scores, rtol=1e-6)
    assert back.position("left_elbow")[0] == pytest.approx(0.3)
    with pytest.raises(ValueError):
        Detections("skin", ("head",), np.zeros((2, 3)), np.zeros(2))


def test_eval_extremities_cli(tmp_path, capsys):
    out = tmp_path / "ext.json"
    assert cli_main(["eval", "extremities", str(DEMO_BAG), "--detector", "skin",
                     "--silhouettes", "gt", "--frames", "4", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["detector"] == "skin" and report["frame_sets"] >= 4
    assert "left_hand" in report["labels"] and "precision" in report["labels"]["left_hand"]
    assert "precision" in capsys.readouterr().out
    assert cli_main(["eval", "extremities", str(tmp_path / "missing.mcap")]) == 2
