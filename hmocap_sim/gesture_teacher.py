"""A simulated user who follows the interactive trainer's instructions (thesis sec. 3.4.1), closed loop.

:class:`GestureTeacher` renders, frame by frame, the depth image of a simulated person in a
furnished room of the gesture simulator (:mod:`~hmocap_sim.depth_scene`, people of
:mod:`~hmocap_sim.gesture_set`) doing what the last :class:`~hmocap_ros.gestures.trainer.TrainerStatus`
asks:

- ``do_gesture``: moves (a short blend) to a new spot of the zone (each round at another
  distance and angle) and into the taught gesture with its reference point at the box centre;
  ``update_positive`` and ``testing``: holds it there with small pose variations (two jittered
  solutions of the gesture blended back and forth, a new pair every ``VARIATION_S``);
- ``rehearse``: holds the known gesture the status names (``rehearsed``) in the box, as above;
- ``release``: blends back to standing;
- ``do_negatives``: takes of near misses of the taught gesture (a third of them:
  :data:`~hmocap_sim.gesture_set.NEAR_MISSES`, what the instruction asks for, with the
  missed gesture's reference point moved to the box centre as for a held gesture), of everyday
  motions (:data:`~hmocap_sim.gesture_set.NEGATIVE_KINDS`) and of the simulator's gestures
  the forest does not know, as the bag simulator draws them
  (:func:`~hmocap_sim.gesture_takes.take_frames`, poses at 10 fps blended to the
  frame rate);
- ``idle`` and ``done``: stands.

Design choices: to put the gesture in the box the person is moved parallel to the image plane
(at the depth the pose puts the reference point) so that the point projects on the box
centre; the body may then float or sink a few centimetres, which the camera rarely sees. The
frames are Kinect-like uint16 millimetres (0 = invalid), ``1 / fps`` apart from
``START_NS``. Every draw comes from Generators seeded by ``seed``: a run repeats bit for bit.

:func:`write_recording_bag` writes what a trainer recorded (``Trainer(..., record=True)``) as
an annotated gesture bag (the layout of ``hmocap sim gestures``), so that ``hmocap train
gestures`` trains offline on exactly the frames of a session (thesis sec. 3.4.2).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from hmocap_ros.body import load_body_model
from hmocap_ros.io import topics
from hmocap_ros.io.bag_writer import whole_bag
from hmocap_ros.io.conversions import dict_to_camera_info, numpy_to_image
from hmocap_ros.io.msg_factory import RosbagsFactory, make_header
from hmocap_sim import gesture_set as gs
from hmocap_sim.depth_scene import make_layout, render_depth
from hmocap_sim.depth_sensor import DEFAULT_ALBEDO, DEFAULT_SENSOR, sensor_by_name
from hmocap_sim.gesture_body import body_albedo
from hmocap_sim.gesture_takes import MAX_YAW_DEG, Actor, bystander_pose, facing_yaw, lerp_pose, take_frames

__all__ = ["NEAR_MISS_SHARE", "START_NS", "VARIATION_S", "GestureTeacher", "run_session", "write_recording_bag"]

START_NS = 1_700_000_000_000_000_000
VARIATION_S = 1.0
#: Share of the negative takes that are near misses of the taught gesture (the trainer asks for
#: them: "'{g}' done wrong").
NEAR_MISS_SHARE = 1.0 / 3.0
_BLEND_S = 0.3


class GestureTeacher:
    """A simulated user (module docstring): ``next_frame(status)`` -> (depth_mm, stamp_ns)."""

    def __init__(self, seed: int = 0, width: int = 320, height: int = 240, fps: float = 30.0,
                 subject_id: int = 0, layout_id: int = 0, bystanders: int = 0,
                 sensor: str = DEFAULT_SENSOR):
        self.model = load_body_model("hands")
        #: the depth sensor family (:data:`hmocap_sim.depth_sensor.SENSORS`)
        self.sensor = sensor_by_name(sensor)
        self.rng = np.random.default_rng([seed, 1])
        self.noise_rng = np.random.default_rng([seed, 2])
        self.layout = make_layout(np.random.default_rng([seed, 3, layout_id]), layout_id, width, height,
                                  n_bystanders=bystanders)
        self.camera = self.layout.camera
        self.actor = Actor(gs.make_subject(self.model, subject_id))
        rng = np.random.default_rng([seed, 4])
        self.people = [Actor(gs.make_subject(self.model, int(rng.integers(10**6, 10**9))))
                       for _ in self.layout.bystanders]
        for person, spot in zip(self.people, self.layout.bystanders):
            person.params = bystander_pose(self.model, person, spot, self.layout, rng)
        self.fps = float(fps)
        self.period = int(round(1e9 / self.fps))
        self.index = 0
        self.queue: list = []          # upcoming poses
        self.mode = None               # (what, gesture) being done
        self.held = None               # (a, b, x, z, yaw, side, frames) of the held gesture
        self.frames_in_mode = 0
        self.actor.params = self._standing()
        #: False: the user has left the room (the camera sees it empty), e.g. for an empty session.
        self.present = True

    @property
    def next_stamp(self) -> int:
        """The stamp of the next frame."""
        return START_NS + self.index * self.period

    @property
    def focal_px(self) -> float:
        return float(self.camera.fx)

    # ------------------------------------------------------------------ poses

    def _spot(self) -> tuple:
        x0, z0, r = self.layout.zone
        a, rad = self.rng.uniform(0, 2 * np.pi), 0.5 * r * np.sqrt(self.rng.random())
        x, z = x0 + rad * np.cos(a), z0 + rad * np.sin(a)
        yaw = facing_yaw(self.camera.position, x, z) + np.deg2rad(self.rng.uniform(-0.5, 0.5) * MAX_YAW_DEG)
        return x, z, yaw

    def _standing(self) -> np.ndarray:
        x, z, yaw = self._spot()
        cam = gs.world_to_body(x, z, yaw, self.camera.position)
        spec = gs.negative_spec(self.model, self.actor.subject, "idle", self.rng, camera_body=cam)
        return gs.place(self.model, gs.solve_spec(self.model, self.actor.subject, spec, restarts=0), x, z, yaw)

    def _new_hold(self, gesture: str, new_spot: bool = False) -> None:
        """Two jittered solutions of ``gesture`` at a spot of the zone (small pose variations); a
        new spot for another gesture or when ``new_spot``."""
        m, subj = self.model, self.actor.subject
        same = self.held is not None and self.held[6] == gesture and not new_spot
        x, z, yaw = self.held[2:5] if same else self._spot()
        cam = gs.world_to_body(x, z, yaw, self.camera.position)
        spec = gs.pose_spec(m, subj, gesture, self.rng, camera_body=cam)
        a = gs.solve_spec(m, subj, gs.jitter_spec(spec, self.rng, model=m))
        b = gs.solve_spec(m, subj, gs.jitter_spec(spec, self.rng, model=m), start=a, iterations=15, restarts=0)
        self.held = (a, b, x, z, yaw, spec.side, gesture)

    def _in_box(self, params: np.ndarray, gesture: str, side: str, box) -> np.ndarray:
        """``params`` moved parallel to the image plane so the gesture's reference point
        projects on the box centre."""
        kin = gs.kinematics(self.model, self.actor.subject, params)
        ref = gs.reference_point(self.model, kin, gesture, side)[0]
        pix, depth = self.camera.project(ref)
        d = float(depth)
        shift_cam = np.array([(box[0] - pix[0]) * d / self.camera.fx, (box[1] - pix[1]) * d / self.camera.fy, 0.0])
        p = np.array(params, dtype=np.float64, copy=True)
        p[self.model.skeleton.translation_dofs] += self.camera.R.T @ shift_cam
        return p

    def _held_pose(self, status) -> np.ndarray:
        a, b, x, z, yaw, side, g = self.held
        t = 0.5 - 0.5 * np.cos(2 * np.pi * self.frames_in_mode / (VARIATION_S * self.fps))
        pose = gs.place(self.model, lerp_pose(self.model, a, b, t), x, z, yaw)
        return self._in_box(pose, g, side, status.box)

    def _negative_take(self, known, taught: str, box) -> list:
        """Poses of one negative take at the frame rate (10 fps takes blended): a near miss of the
        taught gesture (one take in :data:`NEAR_MISS_SHARE`, when the simulator has them) in the
        box, else an everyday motion or a gesture the forest does not know."""
        near = gs.near_misses_of((taught,))
        in_box = bool(near) and self.rng.random() < NEAR_MISS_SHARE
        if in_box:
            kind = str(near[int(self.rng.integers(len(near)))])
        else:
            kinds = [k for k in gs.NEGATIVE_KINDS] + [g for g in gs.ALL_GESTURES if g not in known]
            kind = str(kinds[int(self.rng.integers(len(kinds)))])
        states = take_frames(self.model, self.actor, kind, self.layout, self.rng, 0, (8, 12))
        if in_box:
            states = [replace(s, params=self._in_box(s.params, taught, s.side, box)) if s.side else s
                      for s in states]
        k = max(1, int(round(self.fps / 10.0)))
        poses, prev = [], self.actor.params
        for s in states:
            poses += [lerp_pose(self.model, prev, s.params, (i + 1) / k) for i in range(k)]
            prev = s.params
        return poses

    def _blend_to(self, target: np.ndarray) -> list:
        n = max(1, int(round(_BLEND_S * self.fps)))
        return [lerp_pose(self.model, self.actor.params, target, (i + 1) / n) for i in range(n)]

    def _pose_for(self, status) -> np.ndarray:
        state, g = status.state, status.gesture
        if state == "rehearse":
            g = getattr(status, "rehearsed", "") or g
        mode = {"do_gesture": "hold", "update_positive": "hold", "testing": "hold", "rehearse": "hold",
                "release": "stand", "do_negatives": "negatives"}.get(state, "idle")
        if (mode, g) != self.mode:
            self.mode, self.frames_in_mode = (mode, g), 0
            if mode == "hold":
                if self.held is None or self.held[6] != g or state == "do_gesture":
                    self._new_hold(g, new_spot=state == "do_gesture")
                self.queue = self._blend_to(self._held_pose(status))
            elif mode == "stand":
                self.queue = self._blend_to(self._standing())
            elif mode == "negatives":
                self.queue = []
            else:
                self.queue = []
        else:
            self.frames_in_mode += 1
        if self.queue:
            return self.queue.pop(0)
        if mode == "hold":
            if self.frames_in_mode and self.frames_in_mode % int(round(VARIATION_S * self.fps)) == 0:
                a, b, x, z, yaw, side, gesture = self.held
                self.held = (b, a, x, z, yaw, side, gesture)
            return self._held_pose(status)
        if mode == "negatives":
            known = set(status.known_gestures) | {g}
            self.queue = self._negative_take(known, g, status.box)
            return self.queue.pop(0)
        return self.actor.params

    # ------------------------------------------------------------------ frames

    def next_frame(self, status) -> tuple[np.ndarray, int]:
        """The next depth frame (uint16 mm, 0 = invalid) of the user following ``status``, and its stamp."""
        self.actor.params = self._pose_for(status)
        meshes = [(self.layout.vertices, self.layout.faces)]
        meshes += [(p.vertices(self.model), self.model.faces) for p in self.people]
        people = self.people + ([self.actor] if self.present else [])
        if self.present:
            meshes.append((self.actor.vertices(self.model), self.model.faces))
        albedo = [DEFAULT_ALBEDO] + [body_albedo(self.model, p.subject.subject_id) for p in people]
        render = render_depth(self.camera, meshes, self.noise_rng, self.sensor, albedo=albedo)
        stamp = START_NS + self.index * self.period
        self.index += 1
        return render.depth_mm, stamp

    def holding(self, gesture: str, box, n: int, status=None) -> list:
        """``n`` frames holding ``gesture`` in ``box`` (u, v, half), outside any session (for checks)."""
        from types import SimpleNamespace
        st = SimpleNamespace(state="testing", gesture=gesture, box=tuple(box), known_gestures=())
        return [self.next_frame(st) for _ in range(int(n))]


def run_session(trainer, teacher: GestureTeacher, seconds: float) -> list:
    """Run ``trainer`` and ``teacher`` in a closed loop for ``seconds`` simulated seconds at the
    teacher's frame rate; returns the trainer's status after every frame."""
    cam = teacher.camera
    status = trainer.status(teacher.next_stamp, cam.width, cam.height)
    out = []
    for _ in range(int(round(seconds * teacher.fps))):
        depth, stamp = teacher.next_frame(status)
        status = trainer.on_frame(depth, stamp)
        out.append(status)
    return out


def write_recording_bag(path, recording, camera) -> int:
    """Write a trainer's recorded frames (:class:`~hmocap_ros.gestures.trainer.RecordedFrame`)
    seen by ``camera`` (a :class:`~hmocap_sim.depth_scene` camera) as an annotated bag:
    ``/depth/image_raw`` (16UC1 mm), ``/depth/camera_info`` and ``/ground_truth/gestures`` (the
    frame's gesture at the box centre, with the simulator's class id, :data:`ALL_GESTURES`;
    a name it does not have gets the next free id in order of appearance). Returns the number of
    frames written."""
    factory = RosbagsFactory()
    ids = {}
    n = 0
    with whole_bag(path) as bag:
        for f in recording:
            stamp = int(f.stamp_ns)
            gestures = []
            if f.gesture:
                if f.gesture not in ids:
                    ids[f.gesture] = (gs.class_id(f.gesture) if f.gesture in gs.ALL_GESTURES
                                      else len(gs.ALL_GESTURES) + 1 + sum(
                                          g not in gs.ALL_GESTURES for g in ids))
                gestures.append(factory.make(
                    "hmocap_interfaces/msg/Gesture", name=f.gesture, class_id=ids[f.gesture], score=1.0, volume=1.0,
                    u=float(f.u), v=float(f.v), position=factory.make("geometry_msgs/msg/Point", x=0.0, y=0.0, z=0.0),
                    position_valid=True))
            bag.write(topics.DEPTH_IMAGE, numpy_to_image(f.depth_mm, "16UC1", stamp, camera.frame_id, factory), stamp)
            bag.write(topics.DEPTH_INFO, dict_to_camera_info(camera.to_camera_info_dict(), stamp, factory), stamp)
            bag.write(topics.GT_GESTURES, factory.make("hmocap_interfaces/msg/GestureArray",
                                                       header=make_header(factory, stamp, camera.frame_id),
                                                       gestures=gestures), stamp)
            n += 1
    return n
