"""Several people with ground truth in the simulator (``hmocap sim mocap --people N``).

A tiny two-person recording (160x120, a few frames) has the subject's truth on the usual topics
and the second person's under ``/ground_truth/body_1/``, each with a body and a clip of its own;
the subject is the same as with ``--people 1``; ``hmocap eval mocap``'s reader sees both
people and the cameras that see them; ``--people`` outside 1-4 is a one-line error.
"""

from __future__ import annotations

import numpy as np
import pytest

from hmocap_ros.eval.mocap_frames import load_frames
from hmocap_ros.eval.people_truth import person_topic
from hmocap_ros.io import topics
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.conversions import image_to_numpy
from hmocap_ros.io.msg_factory import stamp_to_ns
from hmocap_sim.mocap_dataset import MocapSimConfig, generate, make_rig
from hmocap_sim.mocap_people import PEOPLE_BVH, person_clips, pingpong_frames
from hmocap_sim.mocap_subject import PERSON_GAP

N_BG, N_MOTION = 2, 6


def _config(out, people):
    return MocapSimConfig(out=out, width=160, height=120, start=2.0, seconds=N_MOTION / 25,
                          background_seconds=N_BG / 25, seed=5, contact_frames=1,
                          people=people, progress=False)


@pytest.fixture(scope="module")
def two_people(tmp_path_factory):
    return generate(_config(tmp_path_factory.mktemp("people") / "two.mcap", 2))


def _read(bag):
    """Everything in a bag by topic: [(stamp, msg)], and the topics' infos."""
    data: dict = {}
    with BagReader(bag) as reader:
        info = reader.topics()
        for m in reader.messages():
            data.setdefault(m.topic, []).append((stamp_to_ns(m.msg.header.stamp), m.msg))
    return info, data


def _points(msg):
    return np.array([[p.x, p.y, p.z] for p in msg.positions])


def test_two_people_have_truth_each(two_people):
    info, data = _read(two_people.bag)
    cams = make_rig(4, 160, 120).names
    for person, body_id in ((0, "body_0"), (1, "body_1")):
        skeletons = data[person_topic(topics.GT_SKELETON, person)]
        assert len(skeletons) == N_MOTION
        assert all(m.body_id == body_id for _, m in skeletons)
        assert len(data[person_topic(topics.GT_JOINT_STATES, person)]) == N_MOTION
        assert info[person_topic(topics.GT_BODY_SHAPE, person)].latched
        for cam in cams:
            assert len(data[person_topic(topics.gt_silhouette(cam), person)]) == N_BG + N_MOTION
    assert person_topic(topics.GT_SKELETON, 1) == "/ground_truth/body_1/skeleton"
    assert not any(t.startswith("/ground_truth/body_2/") for t in info)

    # two bodies of their own, apart, each doing something else
    shapes = [data[person_topic(topics.GT_BODY_SHAPE, p)][0][1] for p in (0, 1)]
    assert not np.allclose(shapes[0].bone_scale, shapes[1].bone_scale)
    a = np.stack([_points(m) for _, m in data[topics.GT_SKELETON]])
    b = np.stack([_points(m) for _, m in data[person_topic(topics.GT_SKELETON, 1)]])
    gaps = np.linalg.norm((a[:, 0] - b[:, 0])[:, [0, 2]], axis=-1)
    assert gaps.min() >= PERSON_GAP - 1e-9

    # silhouettes: each person's own pixels, never both; both seen by the cameras
    for cam in cams:
        for (_, m0), (_, m1) in zip(data[topics.gt_silhouette(cam)][N_BG:],
                                    data[person_topic(topics.gt_silhouette(cam), 1)][N_BG:]):
            s0, s1 = image_to_numpy(m0) > 0, image_to_numpy(m1) > 0
            assert not (s0 & s1).any()
        assert any((image_to_numpy(m) > 0).any()
                   for _, m in data[person_topic(topics.gt_silhouette(cam), 1)][N_BG:])


def test_the_subject_is_that_of_one_person(two_people, tmp_path):
    one = generate(_config(tmp_path / "one.mcap", 1))
    _, data1 = _read(one.bag)
    _, data2 = _read(two_people.bag)
    for (s1, m1), (s2, m2) in zip(data1[topics.GT_SKELETON], data2[topics.GT_SKELETON]):
        assert s1 == s2
        np.testing.assert_array_equal(_points(m1), _points(m2))
    np.testing.assert_array_equal(data1[topics.GT_BODY_SHAPE][0][1].bone_scale,
                                  data2[topics.GT_BODY_SHAPE][0][1].bone_scale)


def test_the_evaluation_reads_every_person(two_people):
    frames = load_frames(two_people.bag, "gt")
    assert frames.person_ids == ("body_0", "body_1")
    assert frames.people_truth.shape == (2, N_BG + N_MOTION, 24, 3)
    np.testing.assert_array_equal(frames.people_truth[0], frames.truth)
    assert np.isfinite(frames.people_truth[:, N_BG:]).all()
    assert np.isnan(frames.people_truth[:, :N_BG]).all()
    views = frames.people_views
    assert views is not None and views.shape == (2, N_BG + N_MOTION)
    assert (views[:, :N_BG] == 0).all() and (views[:, N_BG:] >= 2).all()


def test_clips_differ_from_the_subjects_and_repeat_with_the_seed():
    in_place, walks = PEOPLE_BVH
    for subject in in_place + walks:
        clips = person_clips(subject, 3, np.random.default_rng(3))
        assert subject not in clips and len(set(clips)) == 3
        assert clips == person_clips(subject, 3, np.random.default_rng(3))
        assert set(clips[:2]) <= set(in_place)  # the walks come last
    np.testing.assert_array_equal(pingpong_frames(3, 7), [0, 1, 2, 1, 0, 1, 2])
    np.testing.assert_array_equal(pingpong_frames(4, 4, first=2), [2, 3, 2, 1])


@pytest.mark.parametrize("people", ["0", "5"])
def test_people_outside_one_to_four_is_a_one_line_error(tmp_path, capsys, people):
    from hmocap_ros.cli import main

    out = tmp_path / "bad.mcap"
    assert main(["sim", "mocap", "--out", str(out), "--people", people, "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--people must be between 1 and 4" in err[0]
    assert not out.exists()
