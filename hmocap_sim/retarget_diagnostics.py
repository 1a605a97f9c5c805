"""How well a retargeted motion follows its BVH: the angle between each body bone and the
BVH bone it was aimed along (:mod:`hmocap_sim.retarget`, step 4)."""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from hmocap_sim.bvh import Bvh, forward_kinematics
from hmocap_sim.retarget_landmarks import FAMILY_LANDMARKS, bvh_point
from hmocap_sim.retarget_motion import Motion
from hmocap_sim.retarget_rotations import end_site_forward_kinematics, joint_forward_kinematics, unit_vectors

__all__ = ["bone_direction_errors"]


def bone_direction_errors(
    motion: Motion,
    bvh: Bvh,
    body_rest_joints: np.ndarray,
    body_parents: Sequence[int],
    end_sites_rest: np.ndarray | None = None,
    end_site_parents: Sequence[int] | None = None,
    end_site_names: Sequence[str] | None = None,
    landmarks: Mapping | None = None,
) -> dict[str, np.ndarray]:
    """Angle (degrees, per frame) between each posed body bone and the BVH's bone.

    For every body bone ``parent -> child`` (child a joint or an end site) whose two landmarks
    the family maps, the body's bone direction from ``joint_forward_kinematics`` is compared with the direction
    between the BVH landmarks in the same source frame. Needs ``motion.source_frames`` (a motion
    straight from ``retarget``, not resampled).

    Returns:
        ``{"parent->child": (F,) angles}``; NaN where the two BVH landmarks coincide.
    """
    if motion.source_frames is None:
        raise ValueError("motion has no source frames (resampled?)")
    rest = np.asarray(body_rest_joints, float)
    parents = np.asarray(body_parents, int)
    names = motion.joint_names
    landmarks = FAMILY_LANDMARKS[motion.family] if landmarks is None else landmarks
    positions, glob = joint_forward_kinematics(motion.local_rotations, motion.root_translation, rest, parents)
    body = {n: positions[:, i] for i, n in enumerate(names)}
    bones = [(names[p], names[c]) for c, p in enumerate(parents) if p >= 0]
    if end_sites_rest is not None and end_site_parents is not None and end_site_names is not None:
        sites = end_site_forward_kinematics(positions, glob, rest, end_sites_rest, end_site_parents)
        body |= {n: sites[:, i] for i, n in enumerate(end_site_names)}
        bones += [(names[p], str(n)) for n, p in zip(end_site_names, end_site_parents)]
    pose = forward_kinematics(bvh, frames=motion.source_frames)
    out = {}
    for a, b in bones:
        if a not in landmarks or b not in landmarks:
            continue
        pa, pb = bvh_point(bvh, pose, landmarks[a]), bvh_point(bvh, pose, landmarks[b])
        if pa is None or pb is None:
            continue
        v_bvh = (pb - pa) @ motion.bvh_to_body.T
        d_body = unit_vectors(body[b] - body[a])
        cos = np.clip(np.einsum("fi,fi->f", unit_vectors(v_bvh), d_body), -1.0, 1.0)
        angle = np.degrees(np.arccos(cos))
        # Two landmarks on the same BVH point (cmu_mb: LowerBack at Hips) define no direction.
        angle[np.linalg.norm(v_bvh, axis=-1) < 1e-9] = np.nan
        out[f"{a}->{b}"] = angle
    return out
