"""``hmocap sim gestures``: a depth bag of people gesturing among clutter, with ground truth.

Renders takes of simulated subjects (``gesture_set``) in furnished rooms (``depth_scene``)
with a depth camera (Kinect v1 intrinsics, the noise, quantisation and holes of a sensor family
of ``depth_sensor``, ``--sensor``) and writes, per frame, with one shared ``header.stamp``
(frames ``1/fps`` apart from 1,700,000,000 s; a 1 s gap where the room changes):

==========================  ======================================  ==========================
topic                       type                                    content
==========================  ======================================  ==========================
``/depth/image_raw``        sensor_msgs/Image 16UC1                 millimetres, 0 = invalid
``/depth/camera_info``      sensor_msgs/CameraInfo                  fx = fy = 575 at 640x480
``/ground_truth/gestures``  hmocap_interfaces/GestureArray          zero or one Gesture
``/ground_truth/near_misses`` hmocap_interfaces/GestureArray        zero or one near miss
==========================  ======================================  ==========================

frame_id is ``depth_optical_frame`` everywhere.  A Gesture is present while a subject holds
one of the six gestures (``gesture_set.GESTURE_CLASSES``, class ids 1..6; score = volume = 1);
idle, walking, random or near-miss arm poses and the transitions between takes are
background (empty array).  ``u, v`` is the pixel of the gesture's reference point
(``gesture_set.REFERENCE_POINTS``: palm centre, finger on the lips, forearm crossing, hand
contact point), ``position`` the 3D point of the person's surface seen at that pixel (the
clean z-buffer depth, back-projected), in metres in the optical frame.  When the reference
point is hidden (by the person's own body, e.g. a hand turned away, or anything else) or
outside the image, the Gesture keeps its class and (u, v) but ``position_valid`` is false:
evaluators should neither reward nor penalise a detection in such frames. On a near-miss
frame (background), ``/ground_truth/near_misses`` holds one Gesture with the near-miss kind as
its name, the class of the gesture it misses and that gesture's reference pixel: the hand
that is almost the gesture, where training draws hard background samples.

Sequence: the frames are split evenly between ``--subjects`` subjects with identities
``--subject-offset`` .. ``+ subjects - 1`` (a subject's body and clothing depend on its id
only, so sets generated with disjoint id ranges never share a person; use them for train
and test).  Each subject performs takes in a random room (the room and the bystanders
change every few takes and with the seed; bystanders get identities >= 10^6, never a
subject's; ``--background close`` puts the back wall 0.15-0.85 m behind the person):
a short transition from the previous pose (1-3 frames, background), then
``--hold`` (default 5-10) frames holding a gesture with small motion, or as many frames of
a negative kind.  Takes follow shuffled blocks of the six gestures plus three negatives, so classes
are balanced and about half of the frames are background.  Same arguments, same bytes.

Side files next to the bag (``run.mcap`` -> ``run.labels.json``, ``run.contact.png``):

* labels JSON: ``{"format": "hmocap-gesture-labels/1", "seed", "classes": {id: name},
  "camera": {..., "sensor"}, "subjects": {id: {...}}, "layouts": {id: {...}}, "frames": [...]}``, one
  frame entry per depth image: ``index, stamp_ns, subject, layout, take, phase`` ("hold",
  "negative", "transition"), ``kind`` (gesture or negative kind), ``class_id`` (0 =
  background), ``name``, ``side``, ``u, v, position`` (null for background), ``visible``
  (= position_valid), ``distance_m`` (camera to pelvis);
* contact sheet PNG: a few frames per class, depth colour-mapped (0.5-4.5 m), with the GT
  point and class name drawn.

The takes are drawn in ``gesture_takes``, the labels made in ``gesture_labels`` and the
contact sheet in ``gesture_contact_sheet``; this module renders and writes the bag.
"""
from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hmocap_ros.body import load_body_model
from hmocap_ros.io import topics
from hmocap_ros.io.bag_writer import whole_bag
from hmocap_ros.io.conversions import dict_to_camera_info, numpy_to_image
from hmocap_ros.io.msg_factory import RosbagsFactory
from hmocap_sim import gesture_set as gs
from hmocap_sim.depth_scene import Layout, make_layout, render_depth
from hmocap_sim.depth_sensor import DEFAULT_ALBEDO, DEFAULT_SENSOR, sensor_by_name
from hmocap_sim.gesture_body import body_albedo
from hmocap_sim.gesture_contact_sheet import (
    TILE,
    colour_depth,
    contact_tile,
    select_sheet_frames,
    write_contact_sheet,
)
from hmocap_sim.gesture_labels import (
    SURFACE_TOLERANCE_M,
    GroundTruth,
    frame_record,
    gesture_array,
    ground_truth,
    near_miss_truth,
)
from hmocap_sim.gesture_takes import (
    HOLD_FRAMES,
    MAX_YAW_DEG,
    NEGATIVES_PER_BLOCK,
    TRANSITION_FRAMES,
    WALK_STEP_M,
    Actor,
    FrameState,
    bystander_pose,
    facing_yaw,
    lerp_pose,
    take_frames,
    take_schedule,
)

__all__ = [
    "HOLD_FRAMES",
    "LABELS_FORMAT",
    "MAX_YAW_DEG",
    "NEGATIVES_PER_BLOCK",
    "START_NS",
    "SURFACE_TOLERANCE_M",
    "TAKES_PER_LAYOUT",
    "TILE",
    "TRANSITION_FRAMES",
    "WALK_STEP_M",
    "Actor",
    "FrameState",
    "GroundTruth",
    "Summary",
    "colour_depth",
    "contact_tile",
    "facing_yaw",
    "generate",
    "gesture_array",
    "ground_truth",
    "select_sheet_frames",
    "sidecar_paths",
    "write_contact_sheet",
]

START_NS = 1_700_000_000_000_000_000
LABELS_FORMAT = "hmocap-gesture-labels/1"
TAKES_PER_LAYOUT = 8
# Random streams: one per purpose, so e.g. the noise never shifts the poses.
_STREAM_POSES, _STREAM_NOISE, _STREAM_LAYOUT = 1, 2, 3


def sidecar_paths(bag: str | Path) -> tuple:
    """(labels JSON, contact sheet PNG) paths next to a bag."""
    bag = Path(bag)
    stem = bag.with_suffix("") if bag.suffix == ".mcap" else bag
    return stem.with_name(stem.name + ".labels.json"), stem.with_name(stem.name + ".contact.png")


@dataclass(eq=False)
class _Scene:
    """One furnished layout with its bystanders and the random stream of their poses."""

    layout_id: int
    layout: Layout
    people: list
    rng: np.random.Generator

    @classmethod
    def make(cls, model, seed: int, layout_id: int, width: int, height: int, background: str,
             room: int | None = None) -> _Scene:
        if room is None:
            layout = make_layout(np.random.default_rng([seed, _STREAM_LAYOUT, layout_id]),
                                 layout_id, width, height, background=background)
        else:  # the simulated teacher's room (gesture_teacher.GestureTeacher, its seed, layout 0)
            layout = make_layout(np.random.default_rng([room, _STREAM_LAYOUT, 0]), layout_id, width, height,
                                 n_bystanders=0, background=background)
        rng = np.random.default_rng([seed, _STREAM_LAYOUT, layout_id, 1])
        # bystanders get identities >= 10^6, never a subject's
        people = [Actor(gs.make_subject(model, int(rng.integers(10**6, 10**9))))
                  for _ in layout.bystanders]
        return cls(layout_id, layout, people, rng)

    def info(self) -> dict:
        """The layout's entry in the labels JSON."""
        cam, layout = self.layout.camera, self.layout
        return {"camera_position": np.round(cam.position, 4).tolist(),
                "camera_quaternion_xyzw": np.round(cam.pose_quaternion(), 6).tolist(),
                "zone_xz_radius": [round(float(x), 4) for x in layout.zone],
                "furniture": [[kind, round(x, 3), round(z, 3)] for kind, x, z, _ in layout.items],
                "bystanders": len(self.people)}


def _subject_info(subject: gs.Subject) -> dict:
    """A subject's entry in the labels JSON."""
    return {"height_m": round(subject.height, 4),
            "bone_scale": np.round(subject.shape.bone_scale, 4).tolist(),
            "radial_scale": np.round(subject.shape.radial_scale, 4).tolist(),
            "global_scale": round(float(subject.shape.global_scale), 4),
            "entity_names": list(subject.shape.entity_names)}


class _FrameWriter:
    """Renders frames into the open bag (depth image, camera info and ground truth under one
    stamp) and keeps the stamp, the frame index and the labels records."""

    def __init__(self, bag, model, noise_rng: np.random.Generator, period: int, bar, sensor: str) -> None:
        self.bag, self.model, self.noise_rng, self.period, self.bar = bag, model, noise_rng, period, bar
        self.sensor = sensor_by_name(sensor)
        self.factory = RosbagsFactory()
        self.stamp = START_NS
        self.index = 0
        self.records: list = []

    def cut(self) -> None:
        """A 1 s gap (at 10 fps) where the room changes; none before the first frame."""
        if self.index:
            self.stamp += 10 * self.period

    def write(self, scene: _Scene, actor: Actor, state: FrameState, subject_id: int) -> None:
        model, layout, cam, stamp, factory = self.model, scene.layout, scene.layout.camera, self.stamp, self.factory
        meshes = [(layout.vertices, layout.faces)]
        meshes += [(p.vertices(model), model.faces) for p in scene.people]
        meshes.append((actor.vertices(model), model.faces))
        albedo = [DEFAULT_ALBEDO] + [body_albedo(model, p.subject.subject_id) for p in scene.people + [actor]]
        render = render_depth(cam, meshes, self.noise_rng, self.sensor, albedo)
        face_range = (int(render.face_offsets[-2]), int(render.face_offsets[-1]))
        gt = ground_truth(model, actor, state, layout, render, face_range)
        self.bag.write(topics.DEPTH_IMAGE, numpy_to_image(render.depth_mm, "16UC1", stamp, cam.frame_id, factory),
                       stamp)
        self.bag.write(topics.DEPTH_INFO, dict_to_camera_info(cam.to_camera_info_dict(), stamp, factory), stamp)
        self.bag.write(topics.GT_GESTURES, gesture_array(factory, stamp, cam.frame_id, gt), stamp)
        near = near_miss_truth(model, actor, state, layout)
        self.bag.write(topics.GT_NEAR_MISSES, gesture_array(factory, stamp, cam.frame_id, near), stamp)
        self.records.append(frame_record(model, self.index, stamp, subject_id, scene.layout_id, state, gt, cam))
        self.index += 1
        self.stamp += self.period
        self.bar.update(1)


def _write_take(writer: _FrameWriter, scene: _Scene, actor: Actor, states: list, limit: int,
                subject_id: int) -> int:
    """Write up to ``limit`` frames of a take while the bystanders move to new poses during
    its transition; returns the number of frames written."""
    model = writer.model
    targets = [bystander_pose(model, person, spot, scene.layout, scene.rng)
               for person, spot in zip(scene.people, scene.layout.bystanders)]
    starts = [p.params if p.params is not None else t for p, t in zip(scene.people, targets)]
    n_trans = sum(s.phase == "transition" for s in states)
    states = states[:limit]
    for i, state in enumerate(states):
        t = min(1.0, (i + 1) / (n_trans + 1)) if n_trans else 1.0
        for person, a, b in zip(scene.people, starts, targets):
            person.params = lerp_pose(model, a, b, t)
        actor.params = state.params
        writer.write(scene, actor, state, subject_id)
    return len(states)


@dataclass
class Summary:
    frames: int
    per_class: dict
    visible: int
    seconds: float
    bag_bytes: int
    labels_path: Path
    contact_path: Path | None


def generate(out: str | Path, *, seed: int = 0, subjects: int = 2, frames: int = 200,
             width: int = 640, height: int = 480, subject_offset: int = 0, fps: float = 10.0,
             contact: bool = True, progress: bool = True, per_class: int = 4,
             hold: tuple = HOLD_FRAMES, background: str = "room", gestures: tuple = gs.GESTURE_CLASSES,
             negatives: int = NEGATIVES_PER_BLOCK, near_misses: int = 0, near_of: tuple | None = None,
             room: int | None = None, sensor: str = DEFAULT_SENSOR) -> Summary:
    """Render and write the bag, its labels JSON and (optionally) its contact sheet.

    ``gestures`` (default the six classes), ``negatives`` and ``near_misses`` (of the gestures
    ``near_of``, default ``gestures``): the takes of each shuffled block
    (:func:`~hmocap_sim.gesture_takes.take_schedule`); ``room``: every take in
    the room of the simulated teacher of that seed instead of a room per few takes; ``sensor``:
    the depth sensor family (:data:`~hmocap_sim.depth_sensor.SENSORS`)."""
    if subjects < 1 or frames < 1 or width < 16 or height < 16 or fps <= 0:
        raise ValueError("subjects and frames must be >= 1, the image at least 16x16, fps > 0")
    if not 1 <= hold[0] <= hold[1]:
        raise ValueError(f"hold frames must satisfy 1 <= min <= max, got {hold}")
    unknown = [g for g in tuple(gestures) + tuple(near_of or ()) if g not in gs.ALL_GESTURES]
    if unknown:
        raise ValueError(f"unknown gesture(s) {', '.join(unknown)}; choose among {', '.join(gs.ALL_GESTURES)}")
    if negatives < 0 or near_misses < 0:
        raise ValueError("negatives and near misses per block must be >= 0")
    sensor_by_name(sensor)
    from tqdm import tqdm

    t0 = time.perf_counter()
    out = Path(out)
    labels_path, contact_path = sidecar_paths(out)
    model = load_body_model("hands")
    rng = np.random.default_rng([seed, _STREAM_POSES])
    noise_rng = np.random.default_rng([seed, _STREAM_NOISE])
    schedule = take_schedule(rng, tuple(gestures), negatives, near_misses, near_of)
    splits = np.diff(np.linspace(0, frames, subjects + 1).round().astype(int))
    layouts_info, subjects_info = {}, {}
    take = 0
    layout_id = -1
    bar = tqdm(total=frames, file=sys.stderr, disable=not progress, unit="frame", desc="gestures")
    with whole_bag(out) as bag:
        writer = _FrameWriter(bag, model, noise_rng, int(round(1e9 / fps)), bar, sensor)
        for k, n_frames in enumerate(splits):
            subject_id = subject_offset + k
            actor = Actor(gs.make_subject(model, subject_id))
            subjects_info[str(subject_id)] = _subject_info(actor.subject)
            done = 0
            takes_here = TAKES_PER_LAYOUT
            while done < n_frames:
                if takes_here >= TAKES_PER_LAYOUT:
                    layout_id += 1
                    scene = _Scene.make(model, seed, layout_id, width, height, background, room)
                    layouts_info[str(layout_id)] = scene.info()
                    actor.params = None
                    takes_here = 0
                    writer.cut()
                kind = next(schedule)
                states = take_frames(model, actor, kind, scene.layout, rng, take, hold)
                done += _write_take(writer, scene, actor, states, n_frames - done, subject_id)
                take += 1
                takes_here += 1
    bar.close()
    records = writer.records
    classes = gs.GESTURE_CLASSES + tuple(g for g in gs.NEW_GESTURES if g in gestures)
    per_cls = {name: sum(r["class_id"] == (gs.class_id(name) if name in gs.ALL_GESTURES else 0) for r in records)
               for name in ("background",) + classes}
    cam = scene.layout.camera
    cam_info = {"frame_id": cam.frame_id, "width": width, "height": height,
                "K": np.round(cam.K, 6).tolist(), "depth_unit": "mm", "invalid": 0, "sensor": sensor}
    labels = {"format": LABELS_FORMAT, "bag": out.name, "seed": seed, "subject_offset": subject_offset,
              "fps": fps, "background": background, "classes": {str(gs.class_id(n)): n for n in classes},
              "reference_points": {n: gs.REFERENCE_POINTS[n] for n in classes}, "camera": cam_info,
              "subjects": subjects_info, "layouts": layouts_info, "counts": per_cls, "frames": records}
    labels_path.write_text(json.dumps(labels, indent=1) + "\n")
    if contact:
        write_contact_sheet(out, records, contact_path, per_class)
    return Summary(len(records), per_cls, sum(r["visible"] for r in records), time.perf_counter() - t0,
                   out.stat().st_size if out.is_file() else sum(p.stat().st_size for p in out.rglob("*")),
                   labels_path, contact_path if contact else None)
