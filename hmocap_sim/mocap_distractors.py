"""Distractors of a simulated recording (``--distractors``): foreground that is not the subject.

A second person performs another clip at the side of the room, the door opens and closes, and a
ball rolls across the floor; all may occlude the subject (its silhouettes stay exact). Each
distractor is a builder in :data:`DISTRACTORS`, run in that order with one random stream, that
adds its part to a :class:`Distractors`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from hmocap_sim.mocap_people import pingpong_frames
from hmocap_sim.mocap_subject import make_performer, retargeted_motion
from hmocap_sim.params import DATA_DIR

__all__ = ["DISTRACTORS", "DISTRACTOR_BVH", "DistractorContext", "Distractors",
           "build_distractors"]

DISTRACTOR_BVH = DATA_DIR / "bvh" / "14_19_first1201.bvh"


@dataclass(frozen=True, eq=False)
class DistractorContext:
    """What the builders see of the recording.

    t: (N,) time of each frame (s); t_motion: when the subject appears; t_end: the end of the
    recording; fps: frame rate; rig, room: the cameras and the room; tracking, full: the
    tracking body model and the rendered one; subject: the subject's performer; people: the
    performers of the other people with ground truth (``--people``).
    """

    t: np.ndarray
    t_motion: float
    t_end: float
    fps: float
    rig: object
    room: object
    tracking: object
    full: object
    subject: object
    people: tuple = ()


@dataclass(eq=False)
class Distractors:
    """What the distractors add to a recording, per frame.

    performers: people beside the subject; door: (N,) the door's opening angle (rad); balls:
    the ball's ``(centre, spin, axis_yaw)`` per frame, or None; with_ball: the scene has a ball.
    """

    performers: list = field(default_factory=list)
    door: np.ndarray | None = None
    balls: list | None = None
    with_ball: bool = False


def _place_distractor(motion, room, rig, people_xz: np.ndarray, rng):
    """A spot at the side of the room, clear of furniture, 1.3 m from the people with ground
    truth (``people_xz``: their pelvis positions on the floor, any frame) and 1.8 m
    from every camera (nearer, a person fills the view), facing roughly the room centre."""
    from hmocap_sim.retarget import place_in_room

    spots = [(0.6, -1.7), (0.0, -1.7), (0.9, 1.6), (-0.6, 1.7), (-2.1, 0.6), (1.5, -0.6),
             (-2.1, 1.2), (-2.2, -1.3)]
    cameras = np.array([c.position[[0, 2]] for c in rig])
    for i in rng.permutation(len(spots)):
        xz = np.array(spots[i])
        heading = math.atan2(-xz[0], -xz[1]) + rng.uniform(-0.6, 0.6)
        placed = place_in_room(motion, xz, heading)
        root = placed.root_translation[:, [0, 2]]
        far = np.min(np.linalg.norm(root[:, None] - people_xz[None], axis=-1)) >= 1.3
        seen = np.min(np.linalg.norm(root[:, None] - cameras[None], axis=-1)) >= 1.8
        if far and seen and room.clearance(root).min() >= 0.35:
            return placed
    return None


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


# ----------------------------------------------------------------------------- builders


def _second_person(ctx: DistractorContext, out: Distractors, rng) -> None:
    """Another person (shape and look drawn from ``rng``) playing ``DISTRACTOR_BVH`` at the
    side of the room, ping-ponging through the clip if the recording is longer than it, away
    from the people with ground truth; nobody where no spot is free (``_place_distractor``)."""
    from hmocap_ros.body import sample_shape
    from hmocap_sim.appearance import dress, sample_appearance

    shape = sample_shape(rng)
    look = dress(ctx.full, sample_appearance(rng))
    motion = retargeted_motion(DISTRACTOR_BVH, ctx.tracking, shape, ctx.fps)
    n_motion = len(ctx.subject.params)
    idx = pingpong_frames(motion.n_frames, n_motion)
    motion = replace(motion, local_rotations=motion.local_rotations[idx],
                     root_translation=motion.root_translation[idx], source_frames=None)
    people_xz = np.concatenate([p.joints[:, 0][:, [0, 2]] for p in (ctx.subject, *ctx.people)])
    motion = _place_distractor(motion, ctx.room, ctx.rig, people_xz, rng)
    if motion is not None:
        out.performers.append(make_performer(motion, ctx.tracking, ctx.full, shape, look))


def _door(ctx: DistractorContext, out: Distractors, rng) -> None:
    """The door opens in the first half of the motion and closes again."""
    t_motion = ctx.t_motion
    out.door = _door_angles(ctx.t, rng, t_motion + 0.2, t_motion + 0.5 * (ctx.t_end - t_motion))


def _ball(ctx: DistractorContext, out: Distractors, rng) -> None:
    """The ball starts rolling in the first 40 % of the motion, away from the people."""
    from hmocap_sim.mocap_render import BALL_RADIUS

    tracks = [p.joints[:, 0][:, [0, 2]] for p in [ctx.subject, *ctx.people, *out.performers]]
    t_motion = ctx.t_motion
    out.balls = _ball_states(ctx.t, rng, t_motion, t_motion + 0.4 * (ctx.t_end - t_motion),
                             tracks, BALL_RADIUS)
    out.with_ball = True


#: The distractors of ``--distractors``, built in this order (they share one random stream).
DISTRACTORS: tuple[tuple[str, Callable[[DistractorContext, Distractors, object], None]], ...] = (
    ("second_person", _second_person),
    ("door", _door),
    ("ball", _ball),
)


def build_distractors(ctx: DistractorContext, rng, enabled: bool) -> Distractors:
    """The distractors of a recording (none, a closed door and no ball unless ``enabled``)."""
    out = Distractors(door=np.zeros(len(ctx.t)), balls=[None] * len(ctx.t))
    if enabled:
        for _, build in DISTRACTORS:
            build(ctx, out, rng)
    return out
