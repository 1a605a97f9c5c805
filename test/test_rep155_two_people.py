"""REP-155 with two people over DDS: body_tracker (``max_people:=2``) on a bag of two people.

The bag is made here: exact silhouettes of the tracking body (as in ``test_people_tracker``) of
a subject performing a CMU clip and a bystander standing elsewhere in the room, in the cameras
of ``config/rig_example.yaml`` at 320x240, five frame sets on ``/<camera>/foreground`` with the
rig on ``/camera_rig``. The tracker follows both: ``humans/bodies/tracked`` lists two ids, each
body has its ``joint_states`` and (latched) ``body_shape`` topics, and ``/tf`` holds the frames
of both bodies, each joint where that body's skeleton has it. The one-person case is
``test_body_tracker_node.test_rep155_topics_body_frames_and_confidence_of_one_body``.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_body_tracking import STAMP0, clip_poses, render_masks, subject_shape

from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.bag_writer import LATCHED, BagWriter
from hmocap_ros.io.conversions import numpy_to_image
from hmocap_ros.io.msg_factory import RosbagsFactory, stamp_to_ns
from hmocap_ros.io.rig_messages import rig_to_msg
from hmocap_ros.io.tf import from_transform_stamped
from hmocap_ros.processes import loopback_dds_env, replay_through_nodes
from hmocap_ros.tracking.body_frames import body_frame, joint_frame

FRAMES = 5
SMALL = ["-p", "method:=hpf", "-p", "filter.particles:=120", "-p", "filter.layers:=0",
         "-p", "startup.particles:=60", "-p", "startup.frames:=2", "-p", "startup.working_width:=160"]
IDS = ("b0", "b1")


def _two_people_bag(path, model, rig) -> np.ndarray:
    """Write the bag (module docstring); returns the two people's pelvis per frame (F, 2, 3)."""
    shape = subject_shape()
    params = clip_poses(model, 60, FRAMES, shape, position=(-0.4, 0.3), heading=-1.0)
    subject, joints = render_masks(model, rig, params, shape)
    bystander = model.rest_pose(None).copy()
    bystander[model.skeleton.translation_dofs[[0, 2]]] = [1.0, -0.8]  # seen whole by 3 views
    other, other_joints = render_masks(model, rig, bystander[None])
    masks = np.maximum(subject, other[0][None])
    factory = RosbagsFactory()
    with BagWriter(path) as bag:
        bag.add_topic("/camera_rig", "hmocap_interfaces/msg/CameraRig", LATCHED)
        bag.write("/camera_rig", rig_to_msg(rig, STAMP0, factory), STAMP0)
        for f in range(FRAMES):
            stamp = STAMP0 + (f + 1) * 40_000_000
            for k, cam in enumerate(rig):
                bag.write(f"/{cam.name}/foreground",
                          numpy_to_image(masks[f, k], "mono8", stamp, cam.frame_id, factory), stamp)
    pelvis = model.joint_index("pelvis")
    return np.stack([joints[:, pelvis], np.repeat(other_joints[:, pelvis], FRAMES, axis=0)], axis=1)


@pytest.mark.slow
def test_two_people_get_rep155_topics_and_frames_each(tmp_path, model, rig):
    bag = tmp_path / "two_people.mcap"
    truth = _two_people_bag(bag, model, rig)
    node = ("body_tracker", "hmocap_ros.nodes.body_tracker",
            ["--ros-args", "-p", "max_people:=2", "-p", "latest_only:=false", "-p", "queue_depth:=100",
             *SMALL], "waiting for the rig")
    per_body = [f"/humans/bodies/{b}/{t}" for b in IDS for t in ("joint_states", "body_shape")]
    out = tmp_path / "out.mcap"
    result = replay_through_nodes(
        bag, [node], ["/humans/bodies/tracked", "/skeleton", "/tf", *per_body], out, loopback_dds_env(),
        tmp_path / "logs", replay_rate=0.25, settle=3.0,
        expect={"/humans/bodies/tracked": FRAMES, "/humans/bodies/b1/joint_states": 2})
    log = result["body_tracker"].output()
    assert "Traceback" not in log, log
    with BagReader(out) as reader:
        topics = reader.topics()
        tracked = {stamp_to_ns(m.msg.header.stamp): list(m.msg.ids)
                   for m in reader.messages(["/humans/bodies/tracked"])}
        skeletons = {}
        for m in reader.messages(["/skeleton"]):
            skeletons.setdefault(stamp_to_ns(m.msg.header.stamp), {})[m.msg.body_id] = m.msg
        joints = {b: {stamp_to_ns(m.msg.header.stamp) for m in reader.messages([f"/humans/bodies/{b}/joint_states"])}
                  for b in IDS}
        shapes = {b: [m.msg for m in reader.messages([f"/humans/bodies/{b}/body_shape"])] for b in IDS}
        tf = {stamp_to_ns(m.msg.transforms[0].header.stamp): m.msg for m in reader.messages(["/tf"])}
    assert len(tracked) == FRAMES, (tracked, log)
    both = [s for s, ids in tracked.items() if sorted(ids) == list(IDS)]
    assert len(both) >= 2, tracked  # from the end of the start-up on, both bodies
    for body in IDS:
        assert set(both) <= joints[body], (body, joints[body])
        assert topics[f"/humans/bodies/{body}/body_shape"].latched and shapes[body]
        assert shapes[body][-1].body_id == body and 1.3 < shapes[body][-1].height < 2.3
    for stamp in both:
        frames = {t.child_frame_id: t for t in tf[stamp].transforms}
        pose = {"room": np.eye(4)}
        for t in tf[stamp].transforms:  # parents come before their children
            pose[t.child_frame_id] = pose[t.header.frame_id] @ from_transform_stamped(t).matrix
        for body in IDS:
            sk = skeletons[stamp][body]
            names = [body_frame(body)] + [joint_frame(n, body) for n in sk.joint_names[1:]]
            assert set(names) <= set(frames)
            np.testing.assert_allclose([pose[n][:3, 3] for n in names],
                                       [[p.x, p.y, p.z] for p in sk.positions], atol=1e-6)
        # one body on each person (on the floor, within 25 cm)
        f = (stamp - STAMP0) // 40_000_000 - 1
        pelvis = np.array([pose[f"body_{b}"][:3, 3] for b in IDS])
        gaps = np.linalg.norm((pelvis[:, None] - truth[f][None])[..., [0, 2]], axis=-1)
        assert sorted(np.argmin(gaps, axis=1).tolist()) == [0, 1] and gaps.min(axis=1).max() < 0.25, gaps
