"""Takes of the gesture bag: the schedule of pose kinds, the world poses of one take of the
subject (a transition, then a held gesture, a negative pose or a walk) and the poses of the
bystanders, all drawn from explicit random generators in a fixed order."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hmocap_sim import gesture_set as gs
from hmocap_sim.depth_scene import Layout

NEGATIVES_PER_BLOCK = 3
HOLD_FRAMES = (5, 10)
TRANSITION_FRAMES = (1, 3)
MAX_YAW_DEG = 30.0
WALK_STEP_M = 0.11  # per frame at 10 fps: 1.1 m/s


@dataclass
class Actor:
    """A person in the scene: subject, current world pose and cached mesh."""

    subject: gs.Subject
    params: np.ndarray | None = None
    _cache: tuple = field(default=(None, None))

    def vertices(self, model) -> np.ndarray:
        if self._cache[0] is None or not np.array_equal(self._cache[0], self.params):
            verts = gs.posed_vertices(model, self.subject, self.params)
            self._cache = (self.params.copy(), verts)
        return self._cache[1]


@dataclass
class FrameState:
    """One frame of a take: the subject's world pose, the phase ("transition", "hold" or
    "negative"), the pose kind, the main hand ("" when none) and the take's index."""

    params: np.ndarray
    phase: str
    kind: str
    side: str
    take: int


def lerp_pose(model, a: np.ndarray, b: np.ndarray, t: float) -> np.ndarray:
    """Linear blend of two poses, the root yaw along the shorter way round."""
    out = (1.0 - t) * a + t * b
    k = model.skeleton.dof_index("root_yaw")
    out[k] = a[k] + t * ((b[k] - a[k] + np.pi) % (2 * np.pi) - np.pi)
    return out


def take_schedule(rng: np.random.Generator, gestures=gs.GESTURE_CLASSES, negatives: int = NEGATIVES_PER_BLOCK,
                  near_misses: int = 0, near_of=None):
    """Endless take kinds: shuffled blocks of ``gestures`` (default the six classes) plus
    ``negatives`` everyday negatives (drawn by :data:`NEGATIVE_WEIGHTS`) and ``near_misses``
    near misses of ``near_of`` (default ``gestures``; uniform among their kinds)."""
    kinds = list(gs.NEGATIVE_WEIGHTS)
    w = np.array([gs.NEGATIVE_WEIGHTS[k] for k in kinds])
    near = gs.near_misses_of(gestures if near_of is None else near_of)
    if near_misses and not near:
        raise ValueError("near misses need gestures to miss")
    if not gestures and not negatives and not near_misses:
        raise ValueError("a take schedule needs gestures, negatives or near misses")
    while True:
        block = list(gestures) + [str(k) for k in rng.choice(kinds, negatives, p=w / w.sum())]
        if near_misses:
            block += [str(k) for k in rng.choice(near, near_misses)]
        yield from (block[i] for i in rng.permutation(len(block)))


def _in_zone(rng, zone, radius_scale=1.0):
    """A uniform random point of the zone's disc (shrunk by ``radius_scale``)."""
    x0, z0, r = zone
    a, rad = rng.uniform(0, 2 * np.pi), r * radius_scale * np.sqrt(rng.random())
    return x0 + rad * np.cos(a), z0 + rad * np.sin(a)


def facing_yaw(camera_pos, x, z):
    """Root yaw that turns a person at (x, z) to face the camera."""
    return float(np.arctan2(camera_pos[0] - x, camera_pos[2] - z))


def _walk_poses(model, subj: gs.Subject, layout: Layout, rng, n: int) -> list:
    """``n`` frames of walking across the zone, left or right, near its centre."""
    heading = float(rng.choice([-1, 1]) * np.pi / 2 + rng.uniform(-0.6, 0.6))
    x, z = _in_zone(rng, layout.zone, 0.2)
    step = WALK_STEP_M * np.array([np.sin(heading), np.cos(heading)])
    x, z = np.array([x, z]) - step * n / 2
    spec = gs.negative_spec(model, subj, "walk", rng)
    standing = gs.solve_spec(model, subj, spec)
    phase0 = rng.uniform(0, 2 * np.pi)
    poses = []
    for i in range(n):
        p = gs.ground(model, subj, gs.walk_params(model, standing, phase0 + i * 2 * np.pi * WALK_STEP_M / 1.2))
        poses.append(gs.place(model, p, x + i * step[0], z + i * step[1], heading))
    return poses


def _held_poses(model, subj: gs.Subject, kind: str, layout: Layout, rng, n: int) -> tuple:
    """``n`` frames holding a pose of ``kind`` in the zone, roughly facing the camera, with
    small motion (two jittered solutions blended, a slow sway); returns (poses, side)."""
    cam = layout.camera.position
    x, z = _in_zone(rng, layout.zone)
    yaw = facing_yaw(cam, x, z) + np.deg2rad(rng.uniform(-MAX_YAW_DEG, MAX_YAW_DEG))
    camera_body = gs.world_to_body(x, z, yaw, cam)
    spec = gs.pose_spec(model, subj, kind, rng, camera_body=camera_body)
    # only the gestures need their targets met exactly (restarts cost time)
    a = gs.solve_spec(model, subj, gs.jitter_spec(spec, rng, model=model),
                      restarts=None if kind in gs.ALL_GESTURES else 0)
    b = gs.solve_spec(model, subj, gs.jitter_spec(spec, rng, model=model), start=a, iterations=15,
                      restarts=0)
    sway = rng.normal(0.0, 0.01, (2, 3))
    poses = []
    for i in range(n):
        t = i / max(n - 1, 1)
        dx, dz, dyaw = (1 - t) * sway[0] + t * sway[1]
        poses.append(gs.place(model, lerp_pose(model, a, b, t), x + dx, z + dz, yaw + dyaw))
    side = spec.side if (kind in gs.ALL_GESTURES or spec.stages) else ""
    return poses, side


def take_frames(model, actor: Actor, kind: str, layout: Layout, rng, take: int,
                hold=HOLD_FRAMES) -> list:
    """World poses of one take of ``actor``: a transition from its current pose (if any),
    then ``hold`` (min, max) frames of the gesture or negative."""
    n = int(rng.integers(hold[0], hold[1] + 1))
    if kind == "walk":
        poses, side = _walk_poses(model, actor.subject, layout, rng, n), ""
    else:
        poses, side = _held_poses(model, actor.subject, kind, layout, rng, n)
    frames = []
    if actor.params is not None:
        m = int(rng.integers(TRANSITION_FRAMES[0], TRANSITION_FRAMES[1] + 1))
        for i in range(m):
            frames.append(FrameState(lerp_pose(model, actor.params, poses[0], (i + 1) / (m + 1)),
                                     "transition", kind, side, take))
    phase = "hold" if kind in gs.ALL_GESTURES else "negative"
    frames += [FrameState(p, phase, kind, side, take) for p in poses]
    return frames


def bystander_pose(model, actor: Actor, spot, layout: Layout, rng) -> np.ndarray:
    """A random standing negative pose (not walking) of a bystander at ``spot`` (x, z, yaw)."""
    x, z, yaw = spot
    kind = str(rng.choice([k for k in gs.NEGATIVE_KINDS if k != "walk"]))
    cam = gs.world_to_body(x, z, yaw, layout.camera.position)
    p = gs.solve_spec(model, actor.subject, gs.negative_spec(model, actor.subject, kind, rng, camera_body=cam),
                      iterations=20, restarts=0)
    return gs.place(model, p, x, z, yaw + rng.uniform(-0.3, 0.3))
