"""Two bags the example apps are shown and tested on, made from the package's shipped data.

Both are set in the example room of ``config/rig_example.yaml`` (6 x 5 m; in ``world``, +Z up,
it spans x -3..3 and y -2.5..2.5), whose places and zones are ``config/places_example.yaml``,
and both carry ``/tf_static`` as ``camera_rig_publisher`` publishes it (``world`` -> ``room``)
plus what else their sensors need:

- ``gestures_in_room.mcap`` (for ``light_switch``): the first room of the shipped depth
  recording (``hmocap_ros/data/demo/gestures_depth.mcap``, its 36 frames at 10 fps: a subject
  holds silence, ok and, from 3.2 s, pause), the depth camera hung on the example room's wall
  (its pose in the recording's room moved 2.45 m along the room's -Z, to y = 2.45 m in
  ``world``) by a transform ``room`` -> ``depth_optical_frame`` on ``/tf_static``; the depth
  topics ``/depth/image_raw`` and ``/depth/camera_info`` for ``gesture_detection``, without
  camera_info in the first second (the detector then has no 3D points: the silence
  gesture comes without one). The pause is held about 0.15 m from the place ``lamp``.
- ``walk_in_room.mcap`` (for ``presence``): what ``body_tracker`` publishes for two people
  (built by its own message code, :class:`~hmocap_ros.tracking.tracker_messages.TrackerMessages`),
  at 25 fps: ``b0`` walks across the room along y = -0.2 m from x = -2.6 m (CMU clip 07_01,
  a 2.6 s walk, retargeted onto the tracking body), ``b1`` stands by the sofa; then 0.4 s with
  nobody tracked. Two skeletons of ``b0`` are bad input: frame 20 has 18 positions for 19
  joints, frame 30 no pelvis (NaN).

    .venv/bin/python -m hmocap_examples.scenes OUT_DIR
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from hmocap_ros.geometry.rotations import quaternion_to_matrix
from hmocap_ros.io.bag_reader import BagReader
from hmocap_ros.io.bag_writer import LATCHED, BagWriter
from hmocap_ros.io.msg_factory import RosbagsFactory, make_header
from hmocap_ros.io.tf import (
    DEFAULT_FIXED_FRAME,
    TF_MESSAGE_TYPE,
    TF_STATIC_TOPIC,
    Y_UP_TO_Z_UP,
    FrameTransform,
    frame_transform,
    tf_message,
)

DATA = Path(__file__).resolve().parents[1] / "hmocap_ros" / "data"
DEPTH_BAG = DATA / "demo" / "gestures_depth.mcap"
DEPTH_LABELS = DATA / "demo" / "gestures_depth.labels.json"
WALK_BVH = DATA / "bvh" / "007_01.bvh"
ROOM = "room"
#: the recording's layout whose frames are used, and where its camera moves in the example room
DEPTH_LAYOUT = "0"
DEPTH_CAMERA_SHIFT = (0.0, 0.0, -2.45)
#: camera_info is withheld before this many nanoseconds from the first frame
NO_CAMERA_INFO_NS = 1_000_000_000
FPS = 25.0
#: (m) where b0's pelvis starts and ends (world x) and its world y; where b1 stands (world x, y)
WALK_FROM_X, WALK_Y = -2.6, -0.2
STAND_XY = (1.0, 2.0)
#: frames of nobody tracked after the walk
EMPTY_FRAMES = 10
#: frames of b0 whose skeleton is bad input: too few positions, and no pelvis
SHORT_FRAME, NO_PELVIS_FRAME = 20, 30


def room_to_world() -> FrameTransform:
    """``world`` -> ``room``, as camera_rig_publisher puts it on /tf_static."""
    return FrameTransform(DEFAULT_FIXED_FRAME, ROOM, (0.0, 0.0, 0.0), Y_UP_TO_Z_UP)


def depth_camera_transform() -> FrameTransform:
    """``room`` -> ``depth_optical_frame`` of the scene: the recording's layout pose, shifted."""
    layout = json.loads(DEPTH_LABELS.read_text())["layouts"][DEPTH_LAYOUT]
    position = np.asarray(layout["camera_position"]) + DEPTH_CAMERA_SHIFT
    rotation = quaternion_to_matrix(layout["camera_quaternion_xyzw"], tolerance=None)
    return frame_transform(ROOM, "depth_optical_frame", rotation, position)


def _write_tf_static(bag: BagWriter, factory, transforms, stamp_ns: int) -> None:
    bag.add_topic(TF_STATIC_TOPIC, TF_MESSAGE_TYPE, LATCHED)
    bag.write(TF_STATIC_TOPIC, tf_message(transforms, stamp_ns, factory), stamp_ns)


def gesture_scene(out: Path) -> Path:
    """Write ``gestures_in_room.mcap`` into ``out`` (module docstring); its path."""
    path = Path(out) / "gestures_in_room.mcap"
    labels = json.loads(DEPTH_LABELS.read_text())
    stamps = [f["stamp_ns"] for f in labels["frames"] if str(f["layout"]) == DEPTH_LAYOUT]
    first, last = min(stamps), max(stamps)
    factory = RosbagsFactory()
    with BagReader(DEPTH_BAG) as reader, BagWriter(path, flush_period_s=None) as bag:
        _write_tf_static(bag, factory, [room_to_world(), depth_camera_transform()], first)
        for m in reader.messages(["/depth/image_raw", "/depth/camera_info"], raw=True):
            early_info = m.topic == "/depth/camera_info" and m.log_time_ns < first + NO_CAMERA_INFO_NS
            if not first <= m.log_time_ns <= last or early_info:
                continue
            bag.write(m.topic, m.msg, m.log_time_ns, msgtype=m.msgtype)
    return path


def _placed(motion, rotation: np.ndarray, offset) -> tuple[np.ndarray, np.ndarray]:
    """The motion's local rotations and root path turned by ``rotation`` (room) and moved by ``offset``."""
    local = motion.local_rotations.copy()
    local[:, 0] = rotation @ local[:, 0]
    return local, motion.root_translation @ rotation.T + np.asarray(offset)


def walk_poses():
    """``(model, params (2, F, D), joints (2, F, J, 3))`` of b0 walking and b1 standing, room frame."""
    from hmocap_ros.body import load_body_model, local_rotations_to_pose
    from hmocap_ros.body.anthropometry import BodyShape, apply_shape
    from hmocap_sim.retarget import load_motion

    model = load_body_model("tracking")
    shape = BodyShape.neutral()
    rest = apply_shape(model, shape)
    motion = load_motion(WALK_BVH, rest.joints, model.parents, model.joint_names, rest.end_sites,
                         model.end_site_parents, model.end_site_names, fps=FPS)
    # the clip walks along the room's +Z; turned to walk along +X (world +X), then placed
    turn = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    start = motion.root_translation[0] @ turn.T
    walk_offset = np.array([WALK_FROM_X, 0.0, -WALK_Y]) - start * [1, 0, 1]
    local, root = _placed(motion, turn, walk_offset)
    walking = local_rotations_to_pose(model.skeleton, local, root)
    stand_offset = np.array([STAND_XY[0], 0.0, -STAND_XY[1]]) - start * [1, 0, 1]
    local, root = _placed(motion, turn, stand_offset)
    standing = np.repeat(local_rotations_to_pose(model.skeleton, local[:1], root[:1]), len(walking), axis=0)
    params = np.stack([walking, standing])
    joints = np.stack([model.forward(p, shape).joints for p in params])
    return model, params, joints


def _skeleton(factory, stamp: int, body: str, names, positions) -> object:
    return factory.make("hmocap_interfaces/msg/Skeleton", header=make_header(factory, stamp, ROOM), body_id=body,
                        joint_names=list(names),
                        positions=[factory.make("geometry_msgs/msg/Point", x=float(p[0]), y=float(p[1]), z=float(p[2]))
                                   for p in positions],
                        parents=np.zeros(0, np.int32), confidence=np.zeros(0, np.float32), fit_error=float("nan"))


def walk_scene(out: Path, start_ns: int = 1_700_000_000_000_000_000) -> Path:
    """Write ``walk_in_room.mcap`` into ``out`` (module docstring); its path."""
    from hmocap_ros.tracking.tracker_messages import TrackerMessages

    path = Path(out) / "walk_in_room.mcap"
    model, params, joints = walk_poses()
    factory = RosbagsFactory()
    messages = TrackerMessages(model, ("b0", "b1"), ROOM, factory, publish_tf=False)
    n = params.shape[1]
    period = int(round(1e9 / FPS))
    with BagWriter(path, flush_period_s=None) as bag:
        _write_tf_static(bag, factory, [room_to_world()], start_ns)
        for i in range(n + EMPTY_FRAMES):
            stamp = start_ns + i * period
            results = [SimpleNamespace(has_pose=i < n, params=params[k, min(i, n - 1)], joints=joints[k, min(i, n - 1)],
                                       joint_names=model.joint_names, confidence=np.ones(len(model.joint_names)),
                                       fit_cost=float("nan"), shape=None, transforms=None) for k in range(2)]
            for topic, msg in messages.frame_set(stamp, results, [model, model]).messages:
                if topic == "skeleton" and msg.body_id == "b0" and i in (SHORT_FRAME, NO_PELVIS_FRAME):
                    positions = joints[0, i].copy()
                    if i == NO_PELVIS_FRAME:
                        positions[model.joint_names.index("pelvis")] = np.nan
                    msg = _skeleton(factory, stamp, "b0", model.joint_names,
                                    positions[:-1] if i == SHORT_FRAME else positions)
                bag.write("/" + topic, msg, stamp)
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="folder for the two bags (made if missing)")
    ns = ap.parse_args(argv)
    for make, name in ((gesture_scene, "gestures_in_room.mcap"), (walk_scene, "walk_in_room.mcap")):
        if (ns.out / name).exists():
            print(f"scenes: {ns.out / name} exists; remove it first", file=sys.stderr)
            return 2
        print(make(ns.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
