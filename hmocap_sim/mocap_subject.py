"""The subject of a simulated recording: body shape, retargeted motion, placement in the room.

A recording draws from eight independent random streams (``random_streams``) so that an option that
adds something (distractors, lighting changes) does not change what the others draw.
``subject_in_room`` sets up the rig, the room and the subject's placed motion;
``make_performer`` turns a placed motion into the parameters of the tracking body and of the finer
rendered body (relaxed fingers), with the feet on the floor.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hmocap_sim.mocap_rig import make_rig, views_seeing

if TYPE_CHECKING:
    from hmocap_sim.params import MocapSimConfig

__all__ = ["MIN_PELVIS_CLEARANCE", "PERSON_GAP", "full_parameters", "make_performer", "motion_window",
           "place_subject", "random_streams", "retargeted_motion", "shaped_skeleton",
           "subject_in_room"]

# Relaxed hand: flexion (rad) of the finger joints of the rendered body.
FINGER_CURL = {"1_flex": 0.25, "2_flex": 0.35, "3_flex": 0.25}
THUMB_CURL = {"thumb1_flex": 0.15, "thumb2_flex": 0.2, "thumb3_flex": 0.2}

#: (m) a placement keeps the pelvis this far from every wall and furniture footprint in every
#: frame, if any candidate can: half a torso's width, so that no part of the trunk enters a wall
MIN_PELVIS_CLEARANCE = 0.25

#: (m) a placement keeps the pelvis this far from every other person's at the same instant, if
#: any candidate can (two people shoulder to shoulder stand about 0.5 m apart)
PERSON_GAP = 0.9


@dataclass(frozen=True, eq=False)
class _Performer:
    """A person's shape, look and motion, posed lazily."""

    shape: object
    look: object
    params: np.ndarray  # (F, D) tracking-model parameters
    joints: np.ndarray  # (F, J, 3)
    end_sites: np.ndarray  # (F, E, 3)
    full_params: np.ndarray  # (F, D_full) parameters of the rendered body


def full_parameters(track_params, tracking, full) -> np.ndarray:
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


def retargeted_motion(bvh_path, tracking, shape, fps):
    """A BVH clip retargeted onto the tracking body of ``shape``, at ``fps``."""
    from hmocap_ros.body.anthropometry import apply_shape
    from hmocap_sim.retarget import load_motion

    rest = apply_shape(tracking, shape)
    return load_motion(bvh_path, rest.joints, tracking.parents, tracking.joint_names,
                       rest.end_sites, tracking.end_site_parents, tracking.end_site_names,
                       fps=fps)


def motion_window(motion, start: float, seconds: float, fps: float, still: float = 0.0):
    """``seconds`` of ``motion`` from ``start`` (shorter, with a warning, where the clip ends),
    after ``still`` seconds of its first frame held (the subject standing before it moves)."""
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
    held = [first] * int(round(still * fps)) + list(range(first, first + count))
    return replace(motion, local_rotations=motion.local_rotations[held],
                   root_translation=motion.root_translation[held], source_frames=None)


def make_performer(motion, tracking, full, shape, look) -> _Performer:
    """Tracking parameters of a placed motion, feet put back on the floor after the
    projection onto the model's DoFs, and the joints they give."""
    from hmocap_ros.body import local_rotations_to_pose

    params = local_rotations_to_pose(tracking.skeleton, motion.local_rotations,
                                     motion.root_translation)
    full_params = full_parameters(params, tracking, full)
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


def shaped_skeleton(model, shape) -> _RestSkeleton:
    """The rest skeleton of ``model`` with ``shape`` applied (joint positions and end sites),
    what :func:`place_subject` keeps clear of the furniture and the views' edges."""
    from hmocap_ros.body.anthropometry import apply_shape

    rest = apply_shape(model, shape)
    return _RestSkeleton(np.asarray(rest.joints), model.parents, np.asarray(rest.end_sites),
                         model.end_site_parents)


def place_subject(motion, rig, room, rng, skeleton: _RestSkeleton, *, n_candidates: int = 64,
                  avoid: Sequence[np.ndarray] = (), who: str = "the subject"):
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

    ``avoid``: the pelvis tracks ``(F, 2)`` (floor x, z per frame) of people placed before; a
    candidate then scores, after the clearance, the fraction of frames in which its pelvis
    stands :data:`PERSON_GAP` from each of them at the same instant, and is perfect only when
    that holds in every frame. ``who`` names the person in the warnings.
    """
    from hmocap_ros.body import end_site_positions, forward_kinematics
    from hmocap_sim.retarget import heading_of, place_in_room

    root = motion.root_translation[:, [0, 2]]
    path = root[-1] - root[0]
    travels = float(np.linalg.norm(path)) > 0.5
    path_angle = math.atan2(path[0], path[1])  # from +z towards +x, like headings
    diagonal = math.atan2(room.spec.size_x, room.spec.size_z)
    axes = [0.0, math.pi / 2, math.pi, -math.pi / 2, diagonal, -diagonal,
            math.pi - diagonal, diagonal - math.pi]
    best, best_score = None, (-1.0, -1.0, -1.0, -1.0)
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
                 _apart_fraction(placed.root_translation[:, [0, 2]], avoid),
                 float(np.mean(seeing.all(axis=1) & clear)),
                 float(np.mean(seeing & clear[:, None])))
        if score > best_score:
            best, best_score = placed, score
        if score[1] >= 1.0 and score[2] >= 1.0:
            break
    if best_score[0] < 1.0:
        print(f"hmocap sim mocap: no placement keeps the pelvis {MIN_PELVIS_CLEARANCE} m from "
              f"the walls and furniture: {who} passes through one", file=sys.stderr)
    if best_score[1] < 1.0:
        print(f"hmocap sim mocap: {who} comes nearer than {PERSON_GAP} m to another person in "
              f"{100 * (1 - best_score[1]):.0f} % of the frames", file=sys.stderr)
    if best_score[2] < 1.0:
        print(f"hmocap sim mocap: the motion of {who} leaves some camera's view in "
              f"{100 * (1 - best_score[2]):.0f} % of its frames (whole body seen in "
              f"{100 * best_score[3]:.0f} % of the images)", file=sys.stderr)
    return best


def _apart_fraction(track: np.ndarray, avoid: Sequence[np.ndarray]) -> float:
    """Fraction of frames in which the pelvis track ``track`` (F, 2) stands at least
    :data:`PERSON_GAP` from every track of ``avoid`` at the same frame (1 without any)."""
    if not len(avoid):
        return 1.0
    gaps = np.stack([np.linalg.norm(track - other, axis=-1) for other in avoid])
    return float(np.mean(gaps.min(axis=0) >= PERSON_GAP))


def random_streams(seed: int) -> tuple:
    """The recording's eight independent random streams (room, shape, look, place,
    distractors, light, cameras, events), so that e.g. ``--distractors`` does not change the
    subject."""
    return tuple(np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(8))


def subject_in_room(config: MocapSimConfig, rng_room, rng_shape, rng_place) -> tuple:
    """``(rig, room, tracking model, subject shape, placed motion)`` of a recording."""
    from hmocap_ros.body import load_body_model, sample_shape
    from hmocap_ros.geometry.rig import load_rig
    from hmocap_sim.room import build_room

    fps = float(config.fps)
    rig = load_rig(config.rig) if config.rig is not None else make_rig(
        config.cameras, config.width, config.height)
    room = build_room(rng_room)
    tracking = load_body_model("tracking")
    shape = sample_shape(rng_shape)
    motion = retargeted_motion(Path(config.bvh), tracking, shape, fps)
    motion = motion_window(motion, config.start, config.seconds, fps, config.still_seconds)
    motion = place_subject(motion, rig, room, rng_place, shaped_skeleton(tracking, shape))
    return rig, room, tracking, shape, motion
