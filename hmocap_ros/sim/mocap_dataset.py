"""``hmocap sim mocap``: a multi-view RGB recording of a retargeted BVH clip, with ground truth.

A seeded, deterministic synthetic smart-room recording (design sec. 5): a subject whose body
shape is drawn from the anthropometric priors (:func:`hmocap_ros.body.sample_shape`) performs
a real CMU motion-capture clip (retargeted onto the body, :mod:`hmocap_ros.sim.retarget`) in a
furnished room (:mod:`hmocap_ros.sim.room`) seen by N calibrated colour cameras at 25 fps;
:mod:`hmocap_ros.sim.mocap_render` renders every view with its exact ground-truth silhouette.
The same seed gives the same bytes in every image; a different seed gives another subject,
look, room variation, placement and noise.

Output, next to each other (``BAG`` = ``--out``, e.g. ``run.mcap``):

- ``BAG``: an MCAP bag in the documented layout (:mod:`hmocap_ros.io.topics`):
  ``/camera_rig`` (latched ``hmocap_interfaces/CameraRig``), ``/cam_k/image_raw`` (rgb8),
  ``/ground_truth/cam_k/silhouette`` (mono8 0/255: pixels whose nearest surface is the
  subject), ``/ground_truth/skeleton`` (``hmocap_interfaces/Skeleton``: the 19 body joints,
  then the 5 end sites head_top, l/r_hand_tip, l/r_toe, with parents, in metres in the room
  frame), ``/ground_truth/joint_states`` (``sensor_msgs/JointState``: the tracking body
  model's 30 DoFs, ``hmocap_ros.body.load_body_model("tracking")``; posing that model with
  them and the body shape reproduces the skeleton exactly), ``/ground_truth/body_shape``
  (latched ``hmocap_interfaces/BodyShape``). Every message of a frame has the same
  ``header.stamp`` and is logged at it; room-frame data has frame id ``room``, images the
  camera's optical frame id.
- ``<stem>_rig.yaml``: the rig (``hmocap_ros.rig.load_rig`` format).
- ``<stem>.contact.png``: a contact sheet (all views of a few frames, ground-truth skeleton
  projected, silhouette outlined).

The recording starts with ``--background-seconds`` of the empty room (for background
models to learn; those frames have images and empty silhouettes but no skeleton or joint
states), then the subject appears and performs ``--seconds`` of the clip from ``--start``.
The subject is placed (position and heading searched with the seed) so that all joints stay
inside every camera's image and away from the furniture; a motion that travels farther than
the cameras' common view (a run) is placed to stay in view as long as it can, with a warning.
``--distractors`` adds a door that opens and closes, a ball rolling across the floor and a
second person at the side of the room, which all cause foreground that is not the subject (and
may occlude it: the silhouettes stay exact). ``--lighting-changes`` adds sudden lighting
events during the motion (on top of the small drifts of daylight and exposure every recording
has): the ceiling lamp dims to about a third and comes back, the cameras' auto-exposure follows
with a lag, and a cloud darkens the window light for a second.

The rendered mesh is the finer ``hands`` body (12,000 triangles, relaxed fingers, hair volume)
posed with the same parameters as the tracking body, so joints coincide exactly and the
silhouettes are those of the finer surface.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

__all__ = ["MocapSimConfig", "SimResult", "make_rig", "generate", "add_arguments",
           "main_from_args", "views_seeing", "placement_report", "DEFAULT_BVH",
           "BASE_STAMP_NS"]

DATA_DIR = Path(__file__).resolve().parents[1] / "data"
DEFAULT_BVH = DATA_DIR / "bvh" / "13_26.bvh"
DISTRACTOR_BVH = DATA_DIR / "bvh" / "14_19_first1201.bvh"
BASE_STAMP_NS = 1_700_000_000_000_000_000
BODY_ID = "body_0"
ROOM_FRAME = "room"
# Relaxed hand: flexion (rad) of the finger joints of the rendered body.
FINGER_CURL = {"1_flex": 0.25, "2_flex": 0.35, "3_flex": 0.25}
THUMB_CURL = {"thumb1_flex": 0.15, "thumb2_flex": 0.2, "thumb3_flex": 0.2}
_TARGET = (0.0, 1.0, 0.0)  # where the rig's cameras look


@dataclass(frozen=True)
class MocapSimConfig:
    """Everything that defines a recording (the CLI options)."""

    out: Path
    bvh: Path = DEFAULT_BVH
    cameras: int = 4
    width: int = 640
    height: int = 480
    fps: float = 25.0
    start: float = 0.0
    seconds: float = 4.0
    background_seconds: float = 1.0
    seed: int = 0
    distractors: bool = False
    lighting_changes: bool = False
    shadows: bool = True
    noise: bool = True
    supersample: int = 0
    rig: Path | None = None
    contact_frames: int = 4
    force: bool = False
    progress: bool = True


@dataclass(frozen=True, eq=False)
class SimResult:
    """What :func:`generate` wrote and how long it took."""

    bag: Path
    rig_yaml: Path
    contact_sheet: Path
    n_frames: int
    n_motion_frames: int
    n_cameras: int
    width: int
    height: int
    bag_bytes: int
    render_seconds_per_frame: float
    total_seconds: float
    stamps_ns: tuple = field(default=())
    timings: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------- the rig


def _perimeter_point(p: float, hx: float, hz: float) -> np.ndarray:
    """Point at perimeter parameter ``p`` in [0, 4) of the rectangle ``|x| <= hx, |z| <= hz``:
    integers are the corners (-hx,-hz), (hx,-hz), (hx,hz), (-hx,hz), linear in between."""
    corners = np.array([(-hx, -hz), (hx, -hz), (hx, hz), (-hx, hz)], float)
    i = int(math.floor(p)) % 4
    f = p - math.floor(p)
    return corners[i] + f * (corners[(i + 1) % 4] - corners[i])


def make_rig(n_cameras: int = 4, width: int = 640, height: int = 480):
    """The room's camera rig at ``width x height``.

    Four cameras at 4:3 are ``config/rig_example.yaml`` (upper corners, 2.5 m high, looking at
    the room centre at 1 m) scaled to the resolution; any other count or aspect ratio is a
    ring of cameras 2.5 m high spread evenly along the walls (corners first), looking at the
    same point, with intrinsics like the example's (focal length 0.81 x width, principal
    point within a few pixels of the centre, mild barrel distortion), drawn from a fixed
    seed per camera count: a calibrated installation does not change between recordings.
    """
    from hmocap_ros.camera_model import look_at
    from hmocap_ros.config_files import find_config_file
    from hmocap_ros.rig import Rig, load_rig

    if not 1 <= n_cameras <= 8:
        raise ValueError(f"--cameras must be between 1 and 8, got {n_cameras}")
    if width < 16 or height < 16:
        raise ValueError(f"image size {width}x{height} is too small")
    example = find_config_file("rig_example.yaml")
    if n_cameras == 4 and width * 3 == height * 4 and example is not None:
        rig = load_rig(example)
        if rig[0].width != width:
            rig = rig.scaled(width / rig[0].width)
        return rig
    rng = np.random.default_rng(7000 + n_cameras)
    cams = []
    for k in range(n_cameras):
        x, z = _perimeter_point(4.0 * k / n_cameras, 2.8, 2.3)
        f = 0.8125 * width * (1.0 + 0.003 * rng.standard_normal())
        D = (-0.05 + 0.004 * rng.standard_normal(), 0.011 + 0.002 * rng.standard_normal(),
             0.0004 * rng.standard_normal(), 0.0004 * rng.standard_normal(), 0.0)
        cams.append(look_at(
            f"cam_{k + 1}", (x, 2.5, z), _TARGET, width=width, height=height,
            fx=round(f, 3), fy=round(f * (1.0 + 0.001 * rng.standard_normal()), 3),
            cx=round((width - 1) / 2 + 0.003 * width * rng.standard_normal(), 3),
            cy=round((height - 1) / 2 + 0.003 * height * rng.standard_normal(), 3),
            D=tuple(round(d, 5) for d in D)))
    return Rig(ROOM_FRAME, tuple(cams))


# ----------------------------------------------------------------------------- the subject


@dataclass(frozen=True, eq=False)
class _Performer:
    """A person's shape, look and motion, posed lazily."""

    shape: object
    look: object
    params: np.ndarray  # (F, D) tracking-model parameters
    joints: np.ndarray  # (F, J, 3)
    end_sites: np.ndarray  # (F, E, 3)
    full_params: np.ndarray  # (F, D_full) parameters of the rendered body


def _smooth_noise(rng, t: np.ndarray, amplitude: float, periods=(3.0, 9.0)) -> np.ndarray:
    """A sum of a few random sinusoids with periods in ``periods`` (seconds), peak ~amplitude."""
    out = np.zeros_like(t, dtype=float)
    for _ in range(3):
        period = rng.uniform(*periods)
        out += math.sqrt(2.0 / 3.0) * np.sin(2 * math.pi * t / period + rng.uniform(0, 2 * math.pi))
    return amplitude * out / 1.5


def _lighting_events(rng, t: np.ndarray, t_motion: float, t_end: float):
    """Lamp gain, exposure factor and window factor per frame for ``--lighting-changes``.

    The lamp dims to ~30 % over 0.1 s at 20-30 % of the motion and comes back at 60-70 %; the
    auto-exposure follows the lamp with a 0.4 s lag and compensates part of it; a cloud takes
    ~35 % of the window light for about a second around the middle of the motion.
    """
    dur = max(t_end - t_motion, 1e-6)
    t_off = t_motion + rng.uniform(0.2, 0.3) * dur
    t_on = t_motion + rng.uniform(0.6, 0.7) * dur
    low = rng.uniform(0.25, 0.35)
    ramp = 0.1
    down = np.clip((t - t_off) / ramp, 0.0, 1.0)
    up = np.clip((t - t_on) / ramp, 0.0, 1.0)
    lamp = 1.0 - (1.0 - low) * (down - up)
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.04
    alpha = 1.0 - math.exp(-dt / 0.4)
    seen = np.empty_like(lamp)
    acc = 1.0
    for i, g in enumerate(lamp):  # first-order lag of the auto-exposure
        acc += alpha * (g - acc)
        seen[i] = acc
    exposure = 1.0 + 0.3 * (1.0 - seen)
    t_cloud = t_motion + rng.uniform(0.4, 0.55) * dur
    window = 1.0 - 0.35 * np.exp(-0.5 * ((t - t_cloud) / 0.35) ** 2)
    return lamp, exposure, window


def _full_parameters(track_params, tracking, full) -> np.ndarray:
    """Parameters of the full-DoF model: the tracking DoFs copied, fingers relaxed."""
    out = np.zeros((len(track_params), full.skeleton.n_dofs))
    names = full.skeleton.dof_names
    for i, name in enumerate(tracking.skeleton.dof_names):
        out[:, names.index(name)] = track_params[:, i]
    for i, name in enumerate(names):
        key = name[2:]
        if key in THUMB_CURL:
            out[:, i] = THUMB_CURL[key]
        elif key.split("_", 1)[0][:-1] in ("index", "middle", "ring", "pinky"):
            suffix = key[-6:]
            out[:, i] = FINGER_CURL.get(suffix, 0.0)
    return out


def _retargeted(bvh_path, tracking, shape, fps):
    from hmocap_ros.body.anthropometry import apply_shape
    from hmocap_ros.sim.retarget import load_motion

    rest = apply_shape(tracking, shape)
    return load_motion(bvh_path, rest.joints, tracking.parents, tracking.joint_names,
                       rest.end_sites, tracking.end_site_parents, tracking.end_site_names,
                       fps=fps)


def _motion_window(motion, start: float, seconds: float, fps: float):
    n = motion.n_frames
    first = int(round(start * fps))
    count = int(round(seconds * fps))
    if count < 1:
        raise ValueError(f"--seconds {seconds} gives no frames at {fps} fps")
    if first >= n:
        raise ValueError(f"--start {start} s is past the end of the clip ({motion.duration:.2f} s)")
    if first + count > n:
        count = n - first
        print(f"hmocap sim mocap: the clip ends after {count / fps:.2f} s of motion from "
              f"--start {start}", file=sys.stderr)
    return replace(motion, local_rotations=motion.local_rotations[first:first + count],
                   root_translation=motion.root_translation[first:first + count],
                   source_frames=None)


def _performer(motion, tracking, full, shape, look) -> _Performer:
    """Tracking parameters of a placed motion, feet put back on the floor after the
    projection onto the model's DoFs, and the joints they give."""
    from hmocap_ros.body import local_rotations_to_pose

    params = local_rotations_to_pose(tracking.skeleton, motion.local_rotations,
                                     motion.root_translation)
    full_params = _full_parameters(params, tracking, full)
    # The DoF projection drops a little rotation (e.g. ankle inversion): re-level the feet
    # on the rendered mesh's lowest points (10th percentile over the clip, as the retarget).
    lowest = np.concatenate([full.forward(full_params[i:i + 64], shape).vertices[..., 1].min(-1)
                             for i in range(0, len(full_params), 64)])
    shift = -float(np.percentile(lowest, 10.0))
    ty = tracking.skeleton.dof_index("root_ty")
    params[:, ty] += shift
    full_params[:, full.skeleton.dof_index("root_ty")] += shift
    res = tracking.forward(params, shape)
    return _Performer(shape, look, params, res.joints, res.end_sites, full_params)


@dataclass(frozen=True, eq=False)
class _RestSkeleton:
    """The joints of a shaped body at rest (what placement needs for forward kinematics)."""

    joints_rest: np.ndarray
    parents: np.ndarray
    end_sites_rest: np.ndarray
    end_site_parents: np.ndarray


def _shaped_skeleton(model, shape) -> _RestSkeleton:
    from hmocap_ros.body.anthropometry import apply_shape

    rest = apply_shape(model, shape)
    return _RestSkeleton(np.asarray(rest.joints), model.parents, np.asarray(rest.end_sites),
                         model.end_site_parents)


def views_seeing(rig, points: np.ndarray, margin: float) -> np.ndarray:
    """(F, M) whether all points (F, P, 3) of a frame are inside camera m's image (with a
    margin, as a fraction of the image size)."""
    from hmocap_ros.camera_model import project_points

    proj = project_points(rig.cameras, points)
    w, h = rig[0].width, rig[0].height
    mx, my = margin * w, margin * h
    px = proj.pixels
    inside = (proj.visible & (px[..., 0] >= mx - 0.5) & (px[..., 0] <= w - 0.5 - mx)
              & (px[..., 1] >= my - 0.5) & (px[..., 1] <= h - 0.5 - my))
    return inside.all(axis=2).T


#: (m) a placement keeps the pelvis this far from every wall and furniture footprint in every
#: frame, if any candidate can: half a torso's width, so that no part of the trunk enters a wall
MIN_PELVIS_CLEARANCE = 0.25


def _place(motion, rig, room, rng, skeleton: _RestSkeleton, *, n_candidates: int = 64):
    """Choose position and heading so the subject stays in every view and off the furniture.

    Candidates are drawn from ``rng``: positions uniform over the central floor; headings
    uniform, or (for a motion that travels) turning its path along the room's axes or
    diagonals. A candidate scores first whether its pelvis keeps
    :data:`MIN_PELVIS_CLEARANCE` from walls and furniture in every frame (a motion too long
    for the views, like a 4 m run, must still not leave the room: otherwise the best
    candidate may take it through a wall, out of every view, where the ground truth goes on),
    then the fraction of frames in which every joint and end site is inside every image (3 %
    margin) with the pelvis 0.45 m from walls and furniture, then the fraction of (frame,
    camera) pairs that see the whole body; the first perfect candidate wins, else the best.
    A perfect candidate keeps 0.45 m everywhere, so the first rule changes no placement
    that has one.
    """
    from hmocap_ros.body import end_site_positions, forward_kinematics
    from hmocap_ros.sim.retarget import heading_of, place_in_room

    root = motion.root_translation[:, [0, 2]]
    path = root[-1] - root[0]
    travels = float(np.linalg.norm(path)) > 0.5
    path_angle = math.atan2(path[0], path[1])  # from +z towards +x, like headings
    diagonal = math.atan2(room.spec.size_x, room.spec.size_z)
    axes = [0.0, math.pi / 2, math.pi, -math.pi / 2, diagonal, -diagonal,
            math.pi - diagonal, diagonal - math.pi]
    best, best_score = None, (-1.0, -1.0, -1.0)
    for k in range(n_candidates):
        if k == 0:
            xz = (0.0, 0.0)
        else:
            xz = (rng.uniform(-1.3, 1.3), rng.uniform(-1.0, 1.0))
        if travels and k % 2 == 0:
            target = axes[int(rng.integers(len(axes)))] + rng.uniform(-0.15, 0.15)
            heading = heading_of(motion) + target - path_angle
        else:
            heading = rng.uniform(-math.pi, math.pi)
        placed = place_in_room(motion, xz, heading)
        transforms, pos = forward_kinematics(placed.local_rotations, placed.root_translation,
                                             skeleton.joints_rest, skeleton.parents)
        ends = end_site_positions(transforms, skeleton.end_sites_rest,
                                  skeleton.end_site_parents, skeleton.joints_rest)
        seeing = views_seeing(rig, np.concatenate([pos, ends], axis=1), 0.03)
        clearance = room.clearance(placed.root_translation[:, [0, 2]])
        clear = clearance >= 0.45
        score = (float(clearance.min() >= MIN_PELVIS_CLEARANCE),
                 float(np.mean(seeing.all(axis=1) & clear)),
                 float(np.mean(seeing & clear[:, None])))
        if score > best_score:
            best, best_score = placed, score
        if score[1] >= 1.0:
            break
    if best_score[0] < 1.0:
        print(f"hmocap sim mocap: no placement keeps the pelvis {MIN_PELVIS_CLEARANCE} m from "
              "the walls and furniture: the subject passes through one", file=sys.stderr)
    if best_score[1] < 1.0:
        print(f"hmocap sim mocap: the motion leaves some camera's view in "
              f"{100 * (1 - best_score[1]):.0f} % of its frames (whole body seen in "
              f"{100 * best_score[2]:.0f} % of the images)", file=sys.stderr)
    return best


def _streams(seed: int) -> tuple:
    """The recording's eight independent random streams (room, shape, look, place,
    distractors, light, cameras, events), so that e.g. ``--distractors`` does not change the
    subject."""
    return tuple(np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(8))


def _subject_in_room(config: "MocapSimConfig", rng_room, rng_shape, rng_place) -> tuple:
    """``(rig, room, tracking model, subject shape, placed motion)`` of a recording."""
    from hmocap_ros.body import load_body_model, sample_shape
    from hmocap_ros.rig import load_rig
    from hmocap_ros.sim.room import build_room

    fps = float(config.fps)
    rig = load_rig(config.rig) if config.rig is not None else make_rig(
        config.cameras, config.width, config.height)
    room = build_room(rng_room)
    tracking = load_body_model("tracking")
    shape = sample_shape(rng_shape)
    motion = _retargeted(Path(config.bvh), tracking, shape, fps)
    motion = _motion_window(motion, config.start, config.seconds, fps)
    motion = _place(motion, rig, room, rng_place, _shaped_skeleton(tracking, shape))
    return rig, room, tracking, shape, motion


def placement_report(config: "MocapSimConfig") -> dict:
    """Where :func:`generate` puts the subject of ``config`` (the same random streams,
    nothing rendered): ``frames`` (motion frames), ``all_views`` (fraction of frames whose
    joints and end sites are inside every image, 3 % margin), ``under_3_views`` (frames seen
    whole by fewer than 3 cameras), ``min_views``, ``min_clearance`` (m, the pelvis to walls
    and furniture, negative inside them), ``x`` and ``z`` (the pelvis' extent, m)."""
    from hmocap_ros.body import end_site_positions, forward_kinematics

    rng_room, rng_shape, _, rng_place = _streams(config.seed)[:4]
    rig, room, tracking, shape, motion = _subject_in_room(config, rng_room, rng_shape,
                                                          rng_place)
    sk = _shaped_skeleton(tracking, shape)
    transforms, pos = forward_kinematics(motion.local_rotations, motion.root_translation,
                                         sk.joints_rest, sk.parents)
    ends = end_site_positions(transforms, sk.end_sites_rest, sk.end_site_parents,
                              sk.joints_rest)
    seen = views_seeing(rig, np.concatenate([pos, ends], axis=1), 0.03).sum(axis=1)
    root = motion.root_translation
    return {"frames": int(len(seen)), "all_views": float(np.mean(seen == len(rig))),
            "under_3_views": int(np.sum(seen < 3)), "min_views": int(seen.min()),
            "min_clearance": float(room.clearance(root[:, [0, 2]]).min()),
            "x": (float(root[:, 0].min()), float(root[:, 0].max())),
            "z": (float(root[:, 2].min()), float(root[:, 2].max()))}


def _place_distractor(motion, room, rig, subject_xz: np.ndarray, rng):
    """A spot at the side of the room, clear of furniture, 1.3 m from the subject and 1.8 m
    from every camera (nearer, a person fills the view), facing roughly the room centre."""
    from hmocap_ros.sim.retarget import place_in_room

    spots = [(0.6, -1.7), (0.0, -1.7), (0.9, 1.6), (-0.6, 1.7), (-2.1, 0.6), (1.5, -0.6),
             (-2.1, 1.2), (-2.2, -1.3)]
    cameras = np.array([c.position[[0, 2]] for c in rig])
    for i in rng.permutation(len(spots)):
        xz = np.array(spots[i])
        heading = math.atan2(-xz[0], -xz[1]) + rng.uniform(-0.6, 0.6)
        placed = place_in_room(motion, xz, heading)
        root = placed.root_translation[:, [0, 2]]
        far = np.min(np.linalg.norm(root[:, None] - subject_xz[None], axis=-1)) >= 1.3
        seen = np.min(np.linalg.norm(root[:, None] - cameras[None], axis=-1)) >= 1.8
        if far and seen and room.clearance(root).min() >= 0.35:
            return placed
    return None


# ----------------------------------------------------------------------------- timelines


def _ease(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _door_angles(t: np.ndarray, rng, t0: float, t1: float) -> np.ndarray:
    """Open (1 s), hold, close (1.2 s), starting at a random time in ``[t0, t1)``."""
    start = rng.uniform(t0, max(t0, t1))
    hold = rng.uniform(1.2, 2.5)
    angle = math.radians(rng.uniform(65.0, 85.0))
    opening = _ease((t - start) / 1.0)
    closing = _ease((t - start - 1.0 - hold) / 1.2)
    return angle * (opening - closing)


def _ball_states(t: np.ndarray, rng, t0: float, t1: float, avoid: list, radius: float):
    """The ball lies by the west wall, then rolls east along a line of the floor (the one
    farthest from the people's tracks ``avoid``, each ``(F, 2)`` xz), slowing down
    (exponential rolling friction)."""
    x_start = -2.3 + rng.uniform(0, 0.3)
    path_x = np.linspace(x_start, x_start + 3.6, 40)
    lines = (-1.4, -1.1, 1.1, 1.4)

    def distance(z):
        path = np.stack([path_x, np.full_like(path_x, z)], 1)
        return min(float(np.min(np.linalg.norm(track[:, None] - path[None], axis=-1)))
                   for track in avoid) if avoid else 1e9

    z_line = max(lines, key=distance)
    start = rng.uniform(t0, max(t0, t1))
    v0, k = rng.uniform(1.2, 1.8), 0.45
    dt = np.maximum(t - start, 0.0)
    dist = np.minimum(v0 / k * (1.0 - np.exp(-k * dt)), 3.6)
    x = x_start + dist
    z = z_line + 0.1 * np.sin(dist * 0.6)
    return [((float(xi), radius, float(zi)), float(d / radius), math.pi / 2)
            for xi, zi, d in zip(x, z, dist)]


# ----------------------------------------------------------------------------- messages


def _skeleton_msg(factory, stamp, names, parents, points):
    from hmocap_ros.io.msg_factory import make_header

    return factory.make(
        "hmocap_interfaces/msg/Skeleton", header=make_header(factory, stamp, ROOM_FRAME),
        body_id=BODY_ID, joint_names=list(names),
        positions=[factory.make("geometry_msgs/msg/Point", x=float(p[0]), y=float(p[1]),
                                z=float(p[2])) for p in points],
        parents=np.asarray(parents, np.int32), confidence=np.ones(len(names), np.float32),
        fit_error=float("nan"))


def _body_shape_msg(factory, stamp, shape, height):
    from hmocap_ros.io.msg_factory import make_header

    return factory.make(
        "hmocap_interfaces/msg/BodyShape", header=make_header(factory, stamp, ROOM_FRAME),
        body_id=BODY_ID, entity_names=list(shape.entity_names),
        bone_scale=np.asarray(shape.bone_scale, np.float32),
        radial_scale=np.asarray(shape.radial_scale, np.float32),
        global_scale=float(shape.global_scale), height=float(height))


# ----------------------------------------------------------------------------- main loop


def _output_paths(out: Path) -> tuple[Path, Path]:
    stem = out.name[:-len(out.suffix)] if out.suffix else out.name
    return out.with_name(f"{stem}_rig.yaml"), out.with_name(f"{stem}.contact.png")


def generate(config: MocapSimConfig) -> SimResult:
    """Render and write one recording (module docstring); returns what was written."""
    import numba
    from tqdm import tqdm

    from hmocap_ros.body import load_body_model, sample_shape
    from hmocap_ros.camera_model import project_points
    from hmocap_ros.io import topics
    from hmocap_ros.io.bag_writer import LATCHED, whole_bag
    from hmocap_ros.io.conversions import make_joint_state, numpy_to_image
    from hmocap_ros.io.msg_factory import RosbagsFactory
    from hmocap_ros.io.typestore import hmocap_typestore
    from hmocap_ros.rig import rig_to_msg, save_rig
    from hmocap_ros.sim.appearance import dress, sample_appearance
    from hmocap_ros.sim.contact_sheet import Tile, contact_sheet, save_png
    from hmocap_ros.sim.mocap_render import (BALL_RADIUS, FrameState, MocapRenderer,
                                             RenderOptions)

    t_start = time.perf_counter()
    out = Path(config.out)
    rig_path, sheet_path = _output_paths(out)
    for p in (out, rig_path, sheet_path):
        if p.exists():
            if not config.force:
                raise FileExistsError(f"{p} exists; use --force to overwrite")
            if p.is_dir():
                import shutil
                shutil.rmtree(p)
            else:
                p.unlink()
    bvh = Path(config.bvh)
    if not bvh.is_file():
        raise FileNotFoundError(f"BVH file {bvh} not found")
    fps = float(config.fps)

    (rng_room, rng_shape, rng_look, rng_place, rng_dist, rng_light, rng_cam,
     rng_events) = _streams(config.seed)
    rig, room, tracking, shape, motion = _subject_in_room(config, rng_room, rng_shape,
                                                          rng_place)
    width, height = rig[0].width, rig[0].height
    full = load_body_model("hands", "full")
    look = dress(full, sample_appearance(rng_look))
    subject = _performer(motion, tracking, full, shape, look)
    n_motion = len(subject.params)
    n_bg = int(round(config.background_seconds * fps))
    n_frames = n_bg + n_motion
    t = np.arange(n_frames) / fps

    people = [(full.faces, look)]
    second = None
    door = np.zeros(n_frames)
    balls = [None] * n_frames
    t_motion = n_bg / fps
    t_end = n_frames / fps
    if config.distractors:
        shape2 = sample_shape(rng_dist)
        look2 = dress(full, sample_appearance(rng_dist))
        m2 = _retargeted(DISTRACTOR_BVH, tracking, shape2, fps)
        # Ping-pong through the clip if the recording is longer than it.
        idx = np.arange(n_motion) % (2 * m2.n_frames - 2)
        idx = np.where(idx < m2.n_frames, idx, 2 * m2.n_frames - 2 - idx)
        m2 = replace(m2, local_rotations=m2.local_rotations[idx],
                     root_translation=m2.root_translation[idx], source_frames=None)
        subject_xz = subject.joints[:, 0][:, [0, 2]]
        m2 = _place_distractor(m2, room, rig, subject_xz, rng_dist)
        if m2 is not None:
            second = _performer(m2, tracking, full, shape2, look2)
            people.append((full.faces, look2))
        door = _door_angles(t, rng_dist, t_motion + 0.2, t_motion + 0.5 * (t_end - t_motion))
        tracks = [subject_xz] + ([second.joints[:, 0][:, [0, 2]]] if second is not None else [])
        balls = _ball_states(t, rng_dist, t_motion, t_motion + 0.4 * (t_end - t_motion),
                             tracks, BALL_RADIUS)
    window_gain = 1.0 + _smooth_noise(rng_light, t, 0.12)
    exposure = 1.0 + _smooth_noise(rng_light, t, 0.03, periods=(5.0, 12.0))
    lamp_gain = np.ones(n_frames)
    if config.lighting_changes:
        lamp_gain, exposure_step, window_step = _lighting_events(rng_events, t, t_motion, t_end)
        exposure = exposure * exposure_step
        window_gain = window_gain * window_step
    camera_gains = ((1.0 + 0.04 * rng_cam.standard_normal((len(rig), 1)))
                    * (1.0 + 0.025 * rng_cam.standard_normal((len(rig), 3))))

    options = RenderOptions(shadows=config.shadows, noise=config.noise,
                            supersample=config.supersample)
    renderer = MocapRenderer(rig, room, people, options, camera_gains=camera_gains,
                             with_ball=config.distractors)

    factory = RosbagsFactory(hmocap_typestore())
    names = tuple(tracking.joint_names) + tuple(tracking.end_site_names)
    parents = np.concatenate([tracking.parents, tracking.end_site_parents]).astype(np.int32)
    dof_names = tracking.skeleton.dof_names
    stamps = BASE_STAMP_NS + np.round(np.arange(n_frames) * 1e9 / fps).astype(np.int64)
    n_sheet = max(0, int(config.contact_frames))
    sheet_frames = set((n_bg + np.linspace(0.1, 0.9, n_sheet) * (n_motion - 1)).round()
                       .astype(int).tolist()) if n_sheet else set()
    sheet_rows = []
    body_height = float(shape.height(tracking))

    render_time = 0.0
    totals: dict = {}
    pose_cache: dict = {}

    def posed(perf, j, key):
        chunk = j // 25
        if pose_cache.get(key, (None,))[0] != chunk:
            res = full.forward(perf.full_params[chunk * 25:(chunk + 1) * 25], perf.shape)
            pose_cache[key] = (chunk, res.vertices)
        v = pose_cache[key][1][j - chunk * 25]
        return perf.look.with_hair(v, full.faces)

    cams = list(rig.names)
    with whole_bag(out) as bag:
        bag.add_topic(topics.CAMERA_RIG, "hmocap_interfaces/msg/CameraRig", LATCHED)
        bag.add_topic(topics.GT_BODY_SHAPE, "hmocap_interfaces/msg/BodyShape", LATCHED)
        bag.write(topics.CAMERA_RIG, rig_to_msg(rig, int(stamps[0]), factory), int(stamps[0]))
        bag.write(topics.GT_BODY_SHAPE, _body_shape_msg(factory, int(stamps[0]), shape,
                                                        body_height), int(stamps[0]))
        bar = tqdm(total=n_frames, desc=f"rendering {out.name}", unit="frame", file=sys.stderr,
                   disable=not config.progress, dynamic_ncols=True)
        for i in range(n_frames):
            stamp = int(stamps[i])
            j = i - n_bg
            present = j >= 0
            verts = [posed(subject, j, "s") if present else None]
            if second is not None:
                verts.append(posed(second, j, "d") if present else None)
            state = FrameState(people=tuple(verts), door_angle=float(door[i]), ball=balls[i],
                               window_gain=float(window_gain[i]), exposure=float(exposure[i]),
                               lamp_gain=float(lamp_gain[i]))
            rngs = [np.random.default_rng(np.random.SeedSequence(int(config.seed),
                                                                 spawn_key=(1, i, k)))
                    for k in range(len(rig))]
            t0 = time.perf_counter()
            frame = renderer.render(state, rngs)
            render_time += time.perf_counter() - t0
            for key, val in frame.timings.items():
                totals[key] = totals.get(key, 0.0) + val
            for k, cam in enumerate(rig):
                bag.write(topics.camera_image(cam.name),
                          numpy_to_image(frame.images[k], "rgb8", stamp, cam.frame_id, factory),
                          stamp)
                bag.write(topics.gt_silhouette(cam.name),
                          numpy_to_image(frame.silhouettes[k], "mono8", stamp, cam.frame_id,
                                         factory), stamp)
            if present:
                points = np.concatenate([subject.joints[j], subject.end_sites[j]])
                bag.write(topics.GT_SKELETON, _skeleton_msg(factory, stamp, names, parents,
                                                            points), stamp)
                bag.write(topics.GT_JOINT_STATES,
                          make_joint_state(dof_names, subject.params[j], stamp, ROOM_FRAME,
                                           factory=factory), stamp)
            if i in sheet_frames:
                proj = project_points(rig.cameras, points)
                sheet_rows.append((i, [Tile(frame.images[k], mask=frame.silhouettes[k],
                                            points=proj.pixels[k], parents=parents,
                                            point_valid=proj.visible[k], label=cams[k])
                                       for k in range(len(rig))]))
            bar.update(1)
        bar.close()

    save_rig(rig, rig_path, header=(
        f"Camera rig of {out.name} (hmocap sim mocap, seed {config.seed}).\n"
        "Room frame: metres, +Y up, floor y = 0, room x in [-3, 3], z in [-2.5, 2.5]."))
    if sheet_rows:
        sheet = contact_sheet([r for _, r in sheet_rows],
                              row_labels=[f"{(i - n_bg) / fps:.2f} s" for i, _ in sheet_rows],
                              title=(f"{bvh.name} from {config.start:g} s, seed {config.seed}, "
                                     f"{len(rig)} cameras {width}x{height}"
                                     + (", distractors" if config.distractors else "")
                                     + (", lighting changes" if config.lighting_changes else "")))
    else:
        sheet = np.zeros((8, 8, 3), np.uint8)
    save_png(sheet_path, sheet)
    total = time.perf_counter() - t_start
    result = SimResult(
        bag=out, rig_yaml=rig_path, contact_sheet=sheet_path, n_frames=n_frames,
        n_motion_frames=n_motion, n_cameras=len(rig), width=width, height=height,
        bag_bytes=out.stat().st_size, render_seconds_per_frame=render_time / max(n_frames, 1),
        total_seconds=total, stamps_ns=tuple(int(s) for s in stamps),
        timings={k: v / max(n_frames, 1) for k, v in totals.items()})
    result.timings["threads"] = numba.get_num_threads()
    return result


# ----------------------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``hmocap sim mocap``."""
    parser.add_argument("--bvh", type=Path, default=DEFAULT_BVH,
                        help="BVH clip (CMU MotionBuilder, Daz or iClone skeleton; default: the "
                             "packaged 13_26 'direct traffic, wave')")
    parser.add_argument("--out", type=Path, required=True,
                        help="output bag (.mcap); the rig YAML and contact sheet go next to it")
    parser.add_argument("--cameras", type=int, default=4, help="number of cameras, 1-8 (default 4)")
    parser.add_argument("--width", type=int, default=640, help="image width (default 640)")
    parser.add_argument("--height", type=int, default=480, help="image height (default 480)")
    parser.add_argument("--rig", type=Path, default=None,
                        help="use this rig YAML instead of generating one (overrides "
                             "--cameras/--width/--height)")
    parser.add_argument("--fps", type=float, default=25.0, help="frame rate (default 25)")
    parser.add_argument("--start", type=float, default=0.0,
                        help="seconds into the clip where the recording's motion starts")
    parser.add_argument("--seconds", type=float, default=4.0,
                        help="seconds of motion to render (default 4)")
    parser.add_argument("--background-seconds", type=float, default=1.0,
                        help="seconds of empty room before the subject appears (default 1)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of subject shape, look, room, placement and noise (default 0)")
    parser.add_argument("--distractors", action="store_true",
                        help="add a door that opens, a rolling ball and a second person")
    parser.add_argument("--lighting-changes", action="store_true",
                        help="the lamp dims and comes back, auto-exposure follows, a cloud passes")
    parser.add_argument("--no-shadow", dest="shadows", action="store_false",
                        help="no shadow map (faster; the lamp lights everything)")
    parser.add_argument("--no-noise", dest="noise", action="store_false",
                        help="no sensor noise (clean renderings)")
    parser.add_argument("--supersample", type=int, default=0,
                        help="anti-aliasing factor (default 0 = 2 up to 320 px wide, else 1)")
    parser.add_argument("--contact-frames", type=int, default=4,
                        help="frames (rows) in the contact sheet (default 4)")
    parser.add_argument("--threads", type=int, default=None,
                        help="numba threads for rendering (default: all cores)")
    parser.add_argument("--force", action="store_true", help="overwrite existing outputs")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def main_from_args(ns: argparse.Namespace) -> int:
    """Run ``hmocap sim mocap`` with parsed options; print a summary."""
    if getattr(ns, "threads", None):
        import numba
        numba.set_num_threads(max(1, min(int(ns.threads), numba.config.NUMBA_NUM_THREADS)))
    config = MocapSimConfig(
        out=ns.out, bvh=ns.bvh, cameras=ns.cameras, width=ns.width, height=ns.height, fps=ns.fps,
        start=ns.start, seconds=ns.seconds, background_seconds=ns.background_seconds,
        seed=ns.seed, distractors=ns.distractors, lighting_changes=ns.lighting_changes,
        shadows=ns.shadows, noise=ns.noise,
        supersample=ns.supersample, rig=ns.rig, contact_frames=ns.contact_frames,
        force=ns.force, progress=not ns.quiet)
    try:
        r = generate(config)
    except (FileExistsError, FileNotFoundError, ValueError) as err:
        print(f"hmocap sim mocap: error: {err}", file=sys.stderr)
        return 2
    t = r.timings
    print(f"{r.bag}: {r.n_frames} frames ({r.n_motion_frames} with the subject) x "
          f"{r.n_cameras} cameras {r.width}x{r.height}, {r.bag_bytes / 1e6:.2f} MB")
    print(f"  render {r.render_seconds_per_frame:.3f} s per frame ({int(t.get('threads', 0))} "
          f"threads: shade {t.get('shade', 0):.3f}, raster {t.get('raster', 0):.3f}, sensor "
          f"{t.get('sensor', 0):.3f}, shadow {t.get('shadow', 0):.3f}); total "
          f"{r.total_seconds:.1f} s")
    print(f"  rig {r.rig_yaml}")
    print(f"  contact sheet {r.contact_sheet}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    p = argparse.ArgumentParser(prog="hmocap sim mocap", description=__doc__.splitlines()[0])
    add_arguments(p)
    raise SystemExit(main_from_args(p.parse_args()))
