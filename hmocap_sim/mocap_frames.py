"""The frame loop of a simulated recording: render every frame and write its messages.

Per frame (stamp ``stamps[i]``): the people are posed (all of them from frame
``n_background``), :class:`hmocap_sim.mocap_render.MocapRenderer` renders every camera with
sensor noise from a generator seeded by ``(seed, frame, camera)``, and the bag gets each
camera's image and ground-truth silhouette, then, while the people are present, each person's
skeleton and joint states. The subject's ground truth is on the topics of
:mod:`hmocap_ros.io.topics` with body id ``body_0``; person ``k`` >= 1's on the same topics under
``/ground_truth/body_<k>/`` with body id ``body_<k>``
(:func:`hmocap_ros.eval.people_truth.person_topic`). Every message of a frame has the frame's
stamp and is logged at it.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from hmocap_ros.eval.people_truth import person_body_id, person_topic
from hmocap_sim.mocap_rig import ROOM_FRAME

__all__ = ["FrameLoopResult", "Timeline", "write_frames", "write_latched"]

BODY_ID = person_body_id(0)
_POSE_CHUNK = 25  # frames posed together (one second at 25 fps)


@dataclass(frozen=True, eq=False)
class Timeline:
    """What changes over a recording, per frame.

    stamps: (N,) int64 nanoseconds; n_background: frames of the empty room before the subject
    appears; door: (N,) door angle (rad); balls: ball state or None per frame; window_gain,
    exposure, lamp_gain: (N,) light levels (:mod:`hmocap_sim.mocap_lighting`).
    """

    stamps: np.ndarray
    n_background: int
    door: np.ndarray
    balls: Sequence
    window_gain: np.ndarray
    exposure: np.ndarray
    lamp_gain: np.ndarray

    def state(self, i: int, people: Sequence):
        """The renderer's :class:`FrameState` of frame ``i`` with the posed ``people``."""
        from hmocap_sim.mocap_render import FrameState

        return FrameState(people=tuple(people), door_angle=float(self.door[i]),
                          ball=self.balls[i], window_gain=float(self.window_gain[i]),
                          exposure=float(self.exposure[i]), lamp_gain=float(self.lamp_gain[i]))


@dataclass(eq=False)
class FrameLoopResult:
    """Seconds spent rendering, summed per renderer stage, and the contact sheet's rows
    ``(frame, tiles)``."""

    render_seconds: float = 0.0
    stage_seconds: dict = field(default_factory=dict)
    sheet_rows: list = field(default_factory=list)


class _PoseCache:
    """Rendered-body vertices of each performer, posed ``_POSE_CHUNK`` frames at a time."""

    def __init__(self, full):
        self.full = full
        self.chunks: dict = {}

    def vertices(self, key, perf, j: int) -> np.ndarray:
        """(V, 3) vertices (hair included) of performer ``perf`` in its frame ``j``."""
        chunk = j // _POSE_CHUNK
        if self.chunks.get(key, (None,))[0] != chunk:
            res = self.full.forward(
                perf.full_params[chunk * _POSE_CHUNK:(chunk + 1) * _POSE_CHUNK], perf.shape)
            self.chunks[key] = (chunk, res.vertices)
        v = self.chunks[key][1][j - chunk * _POSE_CHUNK]
        return perf.look.with_hair(v, self.full.faces)


def _skeleton_msg(factory, stamp, names, parents, points, body_id: str = BODY_ID):
    from hmocap_ros.io.msg_factory import make_header

    return factory.make(
        "hmocap_interfaces/msg/Skeleton", header=make_header(factory, stamp, ROOM_FRAME),
        body_id=body_id, joint_names=list(names),
        positions=[factory.make("geometry_msgs/msg/Point", x=float(p[0]), y=float(p[1]),
                                z=float(p[2])) for p in points],
        parents=np.asarray(parents, np.int32), confidence=np.ones(len(names), np.float32),
        fit_error=float("nan"))


def _body_shape_msg(factory, stamp, shape, height, body_id: str = BODY_ID):
    from hmocap_ros.io.msg_factory import make_header

    return factory.make(
        "hmocap_interfaces/msg/BodyShape", header=make_header(factory, stamp, ROOM_FRAME),
        body_id=body_id, entity_names=list(shape.entity_names),
        bone_scale=np.asarray(shape.bone_scale, np.float32),
        radial_scale=np.asarray(shape.radial_scale, np.float32),
        global_scale=float(shape.global_scale), height=float(height))


def write_latched(bag, factory, rig, tracking, people: Sequence, stamp: int) -> None:
    """The latched topics: the camera rig and the body shape of each person with ground truth
    (``people``: their performers, the subject first)."""
    from hmocap_ros.io import topics
    from hmocap_ros.io.bag_writer import LATCHED
    from hmocap_ros.io.rig_messages import rig_to_msg

    bag.add_topic(topics.CAMERA_RIG, "hmocap_interfaces/msg/CameraRig", LATCHED)
    for k in range(len(people)):
        bag.add_topic(person_topic(topics.GT_BODY_SHAPE, k), "hmocap_interfaces/msg/BodyShape",
                      LATCHED)
    bag.write(topics.CAMERA_RIG, rig_to_msg(rig, stamp, factory), stamp)
    for k, person in enumerate(people):
        bag.write(person_topic(topics.GT_BODY_SHAPE, k),
                  _body_shape_msg(factory, stamp, person.shape,
                                  float(person.shape.height(tracking)), person_body_id(k)),
                  stamp)


def _write_views(bag, factory, rig, frame, stamp: int) -> None:
    """Each camera's image and the ground-truth silhouette of each person."""
    from hmocap_ros.io import topics
    from hmocap_ros.io.conversions import numpy_to_image

    for k, cam in enumerate(rig):
        bag.write(topics.camera_image(cam.name),
                  numpy_to_image(frame.images[k], "rgb8", stamp, cam.frame_id, factory), stamp)
        bag.write(topics.gt_silhouette(cam.name),
                  numpy_to_image(frame.silhouettes[k], "mono8", stamp, cam.frame_id, factory),
                  stamp)
        for p, mask in enumerate(frame.people_silhouettes[k][1:], start=1):
            bag.write(person_topic(topics.gt_silhouette(cam.name), p),
                      numpy_to_image(mask, "mono8", stamp, cam.frame_id, factory), stamp)


def _sheet_tiles(rig, frame, points: np.ndarray, parents: np.ndarray) -> list:
    """Contact-sheet tiles of a frame: every view, skeleton projected, silhouette outlined."""
    from hmocap_ros.geometry import project_points
    from hmocap_sim.contact_sheet import Tile

    cams = list(rig.names)
    proj = project_points(rig.cameras, points)
    return [Tile(frame.images[k], mask=frame.silhouettes[k], points=proj.pixels[k],
                 parents=parents, point_valid=proj.visible[k], label=cams[k])
            for k in range(len(rig))]


def write_frames(bag, factory, renderer, tracking, full, performers: Sequence, n_people: int,
                 timeline: Timeline, seed: int, sheet_frames: set, progress) -> FrameLoopResult:
    """Render and write every frame of ``timeline`` (module docstring).

    ``performers``: the subject first, then the other people with ground truth (``n_people``
    in all), then the people among the distractors. ``sheet_frames``: frames kept for the
    contact sheet. ``progress``: a tqdm bar, updated once per frame.
    """
    from hmocap_ros.io import topics
    from hmocap_ros.io.conversions import make_joint_state

    rig = renderer.rig
    names = tuple(tracking.joint_names) + tuple(tracking.end_site_names)
    parents = np.concatenate([tracking.parents, tracking.end_site_parents]).astype(np.int32)
    dof_names = tracking.skeleton.dof_names
    poses = _PoseCache(full)
    result = FrameLoopResult()
    for i in range(len(timeline.stamps)):
        stamp = int(timeline.stamps[i])
        j = i - timeline.n_background
        present = j >= 0
        state = timeline.state(i, [poses.vertices(k, p, j) if present else None
                                   for k, p in enumerate(performers)])
        rngs = [np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(1, i, k)))
                for k in range(len(rig))]
        t0 = time.perf_counter()
        frame = renderer.render(state, rngs)
        result.render_seconds += time.perf_counter() - t0
        for key, val in frame.timings.items():
            result.stage_seconds[key] = result.stage_seconds.get(key, 0.0) + val
        _write_views(bag, factory, rig, frame, stamp)
        if present:
            for p, person in enumerate(performers[:n_people]):
                points = np.concatenate([person.joints[j], person.end_sites[j]])
                bag.write(person_topic(topics.GT_SKELETON, p),
                          _skeleton_msg(factory, stamp, names, parents, points,
                                        person_body_id(p)), stamp)
                bag.write(person_topic(topics.GT_JOINT_STATES, p),
                          make_joint_state(dof_names, person.params[j], stamp, ROOM_FRAME,
                                           factory=factory), stamp)
            if i in sheet_frames:  # every person's skeleton, the subject's silhouette
                points = np.concatenate([np.concatenate([p.joints[j], p.end_sites[j]])
                                         for p in performers[:n_people]])
                offsets = len(parents) * np.arange(n_people)[:, None]
                links = np.where(parents[None] >= 0, parents[None] + offsets, -1).ravel()
                result.sheet_rows.append((i, _sheet_tiles(rig, frame, points, links)))
        progress.update(1)
    return result
