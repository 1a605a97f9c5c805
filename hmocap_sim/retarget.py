"""Retarget BVH motion capture onto the body model by matching bone directions.

The BVH skeletons (three families, see ``bvh.detect_family``) have other bone lengths, rest poses
(T-pose against the body's MakeHuman A-pose) and bone rolls than the body, so Euler angles cannot
be copied. Instead, for every body joint ``j`` the *global* rotation ``G_j`` is solved so that the
body's bones point where the corresponding BVH bones point (shared/notes/body-model.md, "Motion"):

1. Landmarks. Each family maps the body's joints and end sites (``pelvis``, ``l_elbow``,
   ``head_top``, ...) to BVH points (a joint, an End Site, or a point fixed in a BVH joint's
   frame); twist bones, share bones and finger and toe rotations of the BVH are not used. World
   positions come from BVH forward kinematics, converted to the body's axes (+Y up).
2. Position frame ``P_j(t)``: weighted Kabsch/SVD (Kabsch 1976; Markley 1988 for the weighted
   form) taking unit vectors between body rest landmarks to the same vectors between BVH
   landmarks. Joints with several children use a lateral and an up vector (pelvis: hip to hip and
   hips to neck; chest: shoulder to shoulder and spine to neck), which fixes twist. Single-child
   joints use their bone plus a secondary direction that fixes twist where it is defined (upper
   arm: the forearm, i.e. the elbow plane; forearm: the upper arm; thigh and shin: the foot;
   foot: the shin; spine and neck: the shoulder line; head: the eye line where the BVH has eyes),
   plus a weak pull to the parent's frame so that twist falls back to the parent's when the
   secondary direction is parallel to the bone (a straight elbow).
3. Twist from the BVH segment. ``P_j`` is noisy or undefined in some frames (straight limbs, a
   head without face landmarks), whereas the BVH joint ``k`` of the same segment carries the full
   rotation in every frame. So a constant offset ``C_j = proj_SO(3)(sum_t c_t R_k(t)^T P_j(t))``
   is fitted over the clip (``c_t``: how well ``P_j`` is conditioned in frame ``t``) and
   ``Q_j(t) = R_k(t) C_j``. Neither the BVH's T-pose nor its zero pose is needed, so the same
   code serves clips with and without an added T-pose.
4. Exact bone direction. For a single-child joint the minimal rotation (swing) taking
   ``Q_j d0`` to the observed BVH bone direction is applied: ``G_j = swing(Q_j d0 -> d) Q_j``,
   so the bone points exactly along the BVH bone and the twist is that of step 3.
5. ``local_j = G_parent^T G_j``; the pelvis is placed at the BVH hip-joint midpoint (scaled by
   body leg length / BVH leg length) plus the body's own pelvis-above-hips offset, and one
   constant vertical shift puts the feet on the floor (y = 0).

Bone lengths are the body's own (forward kinematics with the rest offsets), so ground truth for
evaluation is the posed body, not the BVH positions.

The family tables are in :mod:`~hmocap_sim.retarget_landmarks`, the rotation helpers and the
body's forward kinematics in :mod:`~hmocap_sim.retarget_rotations`, :class:`Motion` with its
resampling and placement in :mod:`~hmocap_sim.retarget_motion`, and the bone-direction check
in :mod:`~hmocap_sim.retarget_diagnostics`; their public names are importable from here.
"""
from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from hmocap_sim.bvh import Bvh, detect_family, forward_kinematics, load_bvh
from hmocap_sim.retarget_diagnostics import bone_direction_errors
from hmocap_sim.retarget_landmarks import (
    FAMILY_LANDMARKS,
    FAMILY_TWIST_SOURCES,
    RestChain,
    Virtual,
    bvh_point,
    t_pose_frames,
)
from hmocap_sim.retarget_motion import Motion, heading_of, place_in_room, resample
from hmocap_sim.retarget_rotations import (
    end_site_forward_kinematics,
    joint_forward_kinematics,
    kabsch,
    nearest_rotation,
    swing,
    topological_order,
    unit_vectors,
    up_axis_rotation,
)

__all__ = [
    "FAMILY_LANDMARKS",
    "FAMILY_TWIST_SOURCES",
    "Motion",
    "RestChain",
    "Virtual",
    "bone_direction_errors",
    "heading_of",
    "kabsch",
    "load_motion",
    "place_in_room",
    "resample",
    "retarget",
    "swing",
    "t_pose_frames",
]


# Body-side frame vectors (step 2 of the module docstring). Each entry: (from landmarks, to
# landmarks, weight); a landmark tuple means its mean. Pairs whose landmarks only the BVH has
# take their body direction from _BODY_CONSTANT_VECTORS.
_FRAME_VECTORS: dict[str, list] = {
    "pelvis": [(("r_hip",), ("l_hip",), 1.0), (("l_hip", "r_hip"), ("neck",), 1.0)],
    "chest": [(("r_shoulder",), ("l_shoulder",), 1.0), (("spine",), ("neck",), 1.0)],
    "spine": [(("r_shoulder",), ("l_shoulder",), 0.5)],
    "neck": [(("r_shoulder",), ("l_shoulder",), 0.5)],
    "head": [(("r_eye",), ("l_eye",), 1.0)],
}
for _s in "lr":
    _FRAME_VECTORS |= {
        f"{_s}_clavicle": [(("spine",), ("neck",), 0.5)],
        f"{_s}_shoulder": [((f"{_s}_elbow",), (f"{_s}_wrist",), 1.0)],
        f"{_s}_elbow": [((f"{_s}_elbow",), (f"{_s}_shoulder",), 1.0)],
        f"{_s}_wrist": [],
        f"{_s}_hip": [((f"{_s}_ankle",), (f"{_s}_toe",), 1.0)],
        f"{_s}_knee": [((f"{_s}_ankle",), (f"{_s}_toe",), 1.0)],
        f"{_s}_ankle": [((f"{_s}_knee",), (f"{_s}_ankle",), 0.5)],
    }
# Landmarks that exist only on the BVH side; the body side is the rest direction between them.
_BODY_CONSTANT_VECTORS = {(("r_eye",), ("l_eye",)): np.array([1.0, 0.0, 0.0])}
_PARENT_PULL = 0.05  # weight of the parent's axes in P_j: decides twist only when nothing else does


def _body_landmarks(
    rest_joints: np.ndarray, joint_names: Sequence[str],
    end_sites_rest: np.ndarray | None, end_site_names: Sequence[str] | None,
) -> dict[str, np.ndarray]:
    out = {name: np.asarray(p, float) for name, p in zip(joint_names, rest_joints)}
    if end_sites_rest is not None and end_site_names is not None:
        out |= {name: np.asarray(p, float) for name, p in zip(end_site_names, end_sites_rest)}
    return out


def _mean_of(points: Mapping[str, np.ndarray], names: Sequence[str]) -> np.ndarray | None:
    if not all(n in points for n in names):
        return None
    return np.mean([points[n] for n in names], axis=0)


def retarget(
    bvh: Bvh,
    body_rest_joints: np.ndarray,
    body_parents: Sequence[int],
    joint_names: Sequence[str],
    end_sites_rest: np.ndarray | None = None,
    end_site_parents: Sequence[int] | None = None,
    end_site_names: Sequence[str] | None = None,
    *,
    family: str | None = None,
    landmarks: Mapping | None = None,
    twist_sources: Mapping[str, str] | None = None,
    frames: slice | np.ndarray | None = None,
    drop_t_pose: bool = True,
    floor_percentile: float = 10.0,
) -> Motion:
    """Retarget a parsed BVH onto the body (algorithm: module docstring).

    Args:
        bvh: parsed BVH (``bvh.load_bvh``).
        body_rest_joints: (J, 3) body rest joint positions, metres, +Y up, facing +Z.
        body_parents: (J,) parent index per joint, -1 for the root.
        joint_names: (J,) body joint names (the landmark tables use the reference body's names:
            pelvis, spine, chest, neck, head, l_clavicle, l_shoulder, l_elbow, l_wrist, ...).
        end_sites_rest: (E, 3) end-site rest positions (head_top, l_hand_tip, ..., l_toe, ...);
            without them the head, wrists and ankles follow their BVH segment's rotation only.
        end_site_parents: (E,) joint index of each end site.
        end_site_names: (E,) end-site names.
        family: BVH family; detected from joint names by default.
        landmarks: body landmark -> BVH point table (default ``FAMILY_LANDMARKS[family]``).
        twist_sources: body joint -> BVH joint table (default ``FAMILY_TWIST_SOURCES[family]``).
        frames: BVH frames to use (slice or indices), after dropping an added T-pose.
        drop_t_pose: drop a leading added T-pose frame (``t_pose_frames``).
        floor_percentile: the feet's lowest point is put on y = 0 in this percentile of frames.

    Returns:
        ``Motion`` at the BVH frame rate.

    Raises:
        ValueError: unknown family without tables, or a BVH lacking the landmarks needed.
    """
    rest = np.asarray(body_rest_joints, dtype=np.float64)
    parents = np.asarray(body_parents, dtype=np.int64)
    names = tuple(str(n) for n in joint_names)
    if rest.shape != (len(names), 3) or parents.shape != (len(names),):
        raise ValueError(
            f"body: {len(names)} joint names, rest joints {rest.shape}, parents {parents.shape}"
        )
    family = family or detect_family(bvh)
    landmarks, twist_sources = _family_tables(bvh, family, landmarks, twist_sources)
    site_names = tuple(str(n) for n in end_site_names) if end_site_names is not None else ()
    site_parents = (
        np.asarray(end_site_parents, dtype=np.int64) if end_site_parents is not None else None
    )
    body_pts = _body_landmarks(rest, names, end_sites_rest, site_names)
    keep, to_body, obs, bvh_rot = _observed(
        bvh, family, landmarks, twist_sources, body_pts, names, frames, drop_t_pose
    )
    glob = _global_rotations(names, parents, site_names, site_parents, body_pts, obs, bvh_rot)
    local = glob.copy()
    for j, p in enumerate(parents):
        if p >= 0:
            local[:, j] = np.swapaxes(glob[:, p], -1, -2) @ glob[:, j]

    # Root translation: hip midpoint, scaled by leg length, plus the body's pelvis offset.
    root = int(np.flatnonzero(parents < 0)[0])
    scale = _leg_length(body_pts) / _leg_length(obs)
    hips_body = _mean_of(body_pts, ("l_hip", "r_hip"))
    hips_obs = _mean_of(obs, ("l_hip", "r_hip"))
    root_t = scale * hips_obs + glob[:, root] @ (rest[root] - hips_body)
    motion = Motion(
        fps=bvh.fps, local_rotations=local, root_translation=root_t, joint_names=names,
        source=bvh.source, family=family, source_frames=keep, bvh_to_body=to_body,
        scale=float(scale),
    )
    return _feet_on_floor(motion, rest, parents, end_sites_rest, site_parents, floor_percentile)


def _family_tables(
    bvh: Bvh, family: str | None, landmarks: Mapping | None,
    twist_sources: Mapping[str, str] | None,
) -> tuple[Mapping, Mapping[str, str]]:
    """The landmark and twist-source tables: those given, else the family's."""
    if landmarks is None:
        if family not in FAMILY_LANDMARKS:
            raise ValueError(
                f"{bvh.source}: unknown BVH skeleton family (joints {bvh.joint_names[:6]}...): "
                "pass landmarks= and twist_sources="
            )
        landmarks = FAMILY_LANDMARKS[family]
    if twist_sources is None:
        twist_sources = FAMILY_TWIST_SOURCES.get(family, {})
    return landmarks, twist_sources


def _observed(
    bvh: Bvh,
    family: str | None,
    landmarks: Mapping,
    twist_sources: Mapping[str, str],
    body_pts: Mapping[str, np.ndarray],
    names: tuple[str, ...],
    frames: slice | np.ndarray | None,
    drop_t_pose: bool,
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The BVH side in body axes (step 1 of the module docstring).

    Returns the BVH frames kept (an added T-pose dropped, then ``frames`` applied), the
    rotation from BVH to body axes, the landmark positions ``{name: (F, 3)}`` and the world
    rotations ``{body joint: (F, 3, 3)}`` of the twist-source joints, in those frames.
    """
    pose = forward_kinematics(bvh)
    bvh_pts = {name: p for name, spec in landmarks.items()
               if (p := bvh_point(bvh, pose, spec)) is not None}
    needed = ("l_hip", "r_hip", "l_knee", "r_knee", "l_ankle", "r_ankle", "neck")
    missing = [n for n in needed if n not in bvh_pts]
    if missing:
        raise ValueError(f"{bvh.source}: BVH lacks the landmarks {missing} ({family})")
    missing = [n for n in needed if n not in body_pts]
    if missing:
        raise ValueError(f"body lacks the joints {missing} (joint names {names})")
    n_drop = t_pose_frames(bvh_pts) if drop_t_pose else 0
    keep = np.arange(n_drop, bvh.n_frames)
    if frames is not None:
        keep = keep[frames]
    if keep.size == 0:
        raise ValueError(f"{bvh.source}: no frames left to retarget")
    mid_hips = 0.5 * (bvh_pts["l_hip"] + bvh_pts["r_hip"])
    to_body = up_axis_rotation(np.mean(bvh_pts["neck"] - mid_hips, axis=0))
    obs = {n: p[keep] @ to_body.T for n, p in bvh_pts.items()}
    bvh_rot = {
        j: to_body @ pose.rotations[keep, bvh.joint_names.index(k)]
        for j, k in twist_sources.items() if k in bvh.joint_names
    }
    return keep, to_body, obs, bvh_rot


def _global_rotations(
    names: tuple[str, ...],
    parents: np.ndarray,
    site_names: tuple[str, ...],
    site_parents: np.ndarray | None,
    body_pts: Mapping[str, np.ndarray],
    obs: Mapping[str, np.ndarray],
    bvh_rot: Mapping[str, np.ndarray],
) -> np.ndarray:
    """(F, J, 3, 3) global body rotations, steps 2-4 of the module docstring."""
    children: dict[int, list[str]] = {j: [] for j in range(len(names))}
    for c, p in enumerate(parents):
        if p >= 0:
            children[int(p)].append(names[c])
    if site_parents is not None:
        for s, p in zip(site_names, site_parents):
            children[int(p)].append(s)
    n_frames = next(iter(obs.values())).shape[0]
    glob = np.empty((n_frames, len(names), 3, 3))
    for j in topological_order(parents):
        name, parent = names[j], int(parents[j])
        kids = children[j]
        aim = kids[0] if len(kids) == 1 and {kids[0], name} <= (body_pts.keys() & obs.keys()) \
            else None
        g_parent = glob[:, parent] if parent >= 0 else np.broadcast_to(np.eye(3), (n_frames, 3, 3))
        frame, conditioning = _position_frame(name, aim, body_pts, obs, g_parent)
        if name in bvh_rot:
            # Constant offset between the BVH segment and the body segment, fitted over the clip
            # with the frames where the position frame is well defined counting most.
            seg = bvh_rot[name]
            weight = np.maximum(conditioning, 0.05)
            offset = nearest_rotation(np.einsum("f,fji,fjk->ik", weight, seg, frame))
            frame = seg @ offset
        if aim is not None:
            d0 = frame @ unit_vectors(body_pts[aim] - body_pts[name])
            frame = swing(d0, obs[aim] - obs[name]) @ frame
        glob[:, j] = frame
    return glob


def _position_frame(
    name: str,
    aim: str | None,
    body_pts: Mapping[str, np.ndarray],
    obs: Mapping[str, np.ndarray],
    g_parent: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Position-based global rotation ``P_j`` (F, 3, 3) of one joint and its conditioning (F,).

    Weighted Kabsch over the joint's bone (``aim``) and its ``_FRAME_VECTORS``, plus a pull of
    weight ``_PARENT_PULL`` towards the parent's frame. Conditioning is the ratio of the second
    to the first singular value of the vectors' cross-covariance: 0 when they are all parallel
    (twist undefined), 1 for two perpendicular vectors of equal weight.
    """
    rest_vecs, obs_vecs, weights = [], [], []
    if aim is not None:
        rest_vecs.append(body_pts[aim] - body_pts[name])
        obs_vecs.append(obs[aim] - obs[name])
        weights.append(1.0)
    for frm, to, w in _FRAME_VECTORS.get(name, []):
        o_from, o_to = _mean_of(obs, frm), _mean_of(obs, to)
        if o_from is None or o_to is None:
            continue
        b_from, b_to = _mean_of(body_pts, frm), _mean_of(body_pts, to)
        if b_from is not None and b_to is not None:
            rest_vecs.append(b_to - b_from)
        elif (frm, to) in _BODY_CONSTANT_VECTORS:
            rest_vecs.append(_BODY_CONSTANT_VECTORS[(frm, to)])
        else:
            continue
        obs_vecs.append(o_to - o_from)
        weights.append(w)
    if not rest_vecs:
        return np.array(g_parent), np.ones(g_parent.shape[0])
    a = unit_vectors(np.stack(rest_vecs))  # (N, 3)
    b = unit_vectors(np.stack(obs_vecs, axis=1))  # (F, N, 3)
    h = np.einsum("n,fni,nj->fij", np.asarray(weights), b, a)
    sv = np.linalg.svd(h, compute_uv=False)
    conditioning = sv[:, 1] / np.maximum(sv[:, 0], 1e-12)
    # The parent's axes e_i -> G_parent e_i, weakly: they decide twist only when nothing else does.
    return nearest_rotation(h + _PARENT_PULL * g_parent), conditioning


def _leg_length(points: Mapping[str, np.ndarray]) -> float:
    """Mean over both legs of thigh + shin length (median over frames for (F, 3) points)."""
    total = []
    for s in "lr":
        a, b, c = (points.get(f"{s}_{n}") for n in ("hip", "knee", "ankle"))
        if a is None or b is None or c is None:
            continue
        total.append(
            np.median(np.linalg.norm(np.atleast_2d(b - a), axis=-1))
            + np.median(np.linalg.norm(np.atleast_2d(c - b), axis=-1))
        )
    if not total:
        raise ValueError("need hip, knee and ankle landmarks to scale the motion")
    return float(np.mean(total))


def _feet_on_floor(
    motion: Motion, rest: np.ndarray, parents: np.ndarray,
    end_sites_rest: np.ndarray | None, end_site_parents: np.ndarray | None, percentile: float,
) -> Motion:
    """Shift the motion vertically so the feet touch y = 0.

    In every frame the lowest foot point's height above its rest height (rest: feet flat on the
    floor) is a contact height; the ``percentile`` of it over the clip is taken as the floor, so a
    jump does not lift the clip and a foot-skating outlier does not sink it.
    """
    positions, glob = joint_forward_kinematics(motion.local_rotations, motion.root_translation, rest, parents)
    points, rest_points = [positions], [rest]
    if end_sites_rest is not None and end_site_parents is not None and len(end_site_parents):
        sites = end_site_forward_kinematics(positions, glob, rest, end_sites_rest, end_site_parents)
        points.append(sites)
        rest_points.append(np.asarray(end_sites_rest, float))
    heights = np.concatenate(points, axis=1)[..., 1]
    rest_h = np.concatenate(rest_points, axis=0)[:, 1]
    low = rest_h < rest_h.min() + 0.12  # the feet (ankles, toes): within 12 cm of the floor
    contact = (heights[:, low] - rest_h[low]).min(axis=1)
    shift = -float(np.percentile(contact, percentile))
    return replace(motion, root_translation=motion.root_translation + [0.0, shift, 0.0])


def load_motion(
    path: str | os.PathLike,
    body_rest_joints: np.ndarray,
    body_parents: Sequence[int],
    joint_names: Sequence[str],
    end_sites_rest: np.ndarray | None = None,
    end_site_parents: Sequence[int] | None = None,
    end_site_names: Sequence[str] | None = None,
    *,
    fps: float | None = None,
    **options,
) -> Motion:
    """Load a BVH file and retarget it onto the body (``retarget``), optionally resampled.

    Args:
        path: BVH file.
        body_rest_joints, body_parents, joint_names, end_sites_rest, end_site_parents,
            end_site_names: the body (see ``retarget``).
        fps: resample to this frame rate (``resample``); the file's rate by default.
        **options: passed to ``retarget`` (family, landmarks, twist_sources, frames,
            drop_t_pose, floor_percentile).
    """
    motion = retarget(
        load_bvh(path), body_rest_joints, body_parents, joint_names,
        end_sites_rest, end_site_parents, end_site_names, **options,
    )
    return motion if fps is None else resample(motion, fps)
