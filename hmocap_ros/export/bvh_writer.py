"""Joint states -> a Biovision Hierarchy (BVH) file of the tracking body.

The hierarchy is the tracking body's kinematic tree (``load_body_model("tracking")``: 19
joints, End Sites at the head top, hand tips and toes). OFFSETs are the rest skeleton of the
subject: the body model deformed by the bag's anthropometry (:func:`~hmocap_ros.body.apply_shape`,
thesis sec. 2.3.2); the root's OFFSET is its rest position standing on the floor. Every frame
gives the pelvis position and each joint's local rotation (:func:`~hmocap_ros.body.pose_to_local_rotations`,
eq. 2.11) as Euler angles.

This is exactly the body's forward kinematics: joint frames are parallel to the room frame at
rest, so ``G_j = G_parent R_j`` and ``p_j = p_parent + G_parent (r_j - r_parent)``
(:func:`~hmocap_ros.body.forward_kinematics`) is BVH's ``p_j = p_parent + G_parent OFFSET_j``.

File conventions: centimetres (import in Blender with scale 0.01 for metres), the room's axes
(+Y up; BVH's usual up axis); angles in degrees, each channel list read as intrinsic rotations
(``Yrotation Xrotation Zrotation`` is ``R = Ry Rx Rz``, as Blender and
:mod:`hmocap_sim.bvh` read it). The root turns in ``Yrotation Xrotation Zrotation`` (heading,
then lean forward, then lean sideways), the other joints in ``Xrotation Zrotation Yrotation``
(flexion, sideways bend, twist along the bone for spine, neck and legs), so the Euler lock
(middle angle at +-90 degrees) lies where bodies rarely go: lying flat, or a leg or the spine
bent 90 degrees sideways. Angle channels are unwrapped over time (no 360-degree jumps).
"""

from __future__ import annotations

import io

import numpy as np

from .motion import ExportError

__all__ = ["BVH_UNITS_PER_M", "JOINT_ORDER", "ROOT_ORDER", "bvh_text", "matrix_to_euler"]

#: File units per metre: centimetres.
BVH_UNITS_PER_M = 100.0
ROOT_ORDER = "YXZ"
JOINT_ORDER = "XZY"
_AXIS = {"X": 0, "Y": 1, "Z": 2}
_OFFSET_FMT = "%.6f"
_POSITION_FMT = "%.5f"  # 0.1 micrometre in centimetres
_ANGLE_FMT = "%.6f"


def matrix_to_euler(r: np.ndarray, order: str) -> np.ndarray:
    """Angles (..., 3) in degrees with ``R = R_a(t0) R_b(t1) R_c(t2)`` for ``order = "abc"``
    (three different axes), the inverse of :func:`hmocap_sim.bvh.euler_to_matrix`.

    With (i, j, k) the axes and s = +1 for a cyclic order (XYZ, YZX, ZXY), -1 otherwise:
    R[i, k] = s sin t1, tan t0 = -s R[j, k] / R[k, k], tan t2 = -s R[i, j] / R[i, i].
    At the lock (cos t1 = 0) only t0 + s t2 is defined: t2 = 0 and t0 from column j,
    R e_j = R_a e_j = cos t0 e_j + s sin t0 e_k.
    """
    i, j, k = (_AXIS[a] for a in order.upper())
    s = 1.0 if (j - i) % 3 == 1 else -1.0
    r = np.asarray(r, dtype=np.float64)
    cos1 = np.hypot(r[..., i, i], r[..., i, j])
    t1 = np.arctan2(s * r[..., i, k], cos1)
    locked = cos1 < 1e-9
    t0 = np.where(locked, np.arctan2(s * r[..., k, j], r[..., j, j]),
                  np.arctan2(-s * r[..., j, k], r[..., k, k]))
    t2 = np.where(locked, 0.0, np.arctan2(-s * r[..., i, j], r[..., i, i]))
    return np.degrees(np.stack([t0, t1, t2], axis=-1))


def _pose_params(skeleton, dof_names, dofs: np.ndarray) -> np.ndarray:
    """(G, D) parameters of the body's DoFs from joint states with ``dof_names``; other names
    are ignored."""
    where = {n: i for i, n in enumerate(dof_names)}
    missing = [n for n in skeleton.dof_names if n not in where]
    if missing:
        raise ExportError(f"the joint states lack the body's DoFs {', '.join(missing)}")
    return np.asarray(dofs, dtype=np.float64)[:, [where[n] for n in skeleton.dof_names]]


def _depth_first(parents: np.ndarray) -> list:
    """Joint indices in depth-first order, children in index order (the order of BVH blocks
    and of the channel columns)."""
    children = {j: [c for c in range(len(parents)) if parents[c] == j] for j in range(len(parents))}
    order, stack = [], [int(np.flatnonzero(parents < 0)[0])]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(children[j]))
    return order


def _hierarchy(model, joints: np.ndarray, ends: np.ndarray) -> list:
    """HIERARCHY lines for rest joints (J, 3) and end sites (E, 3) in file units."""
    parents = np.asarray(model.parents)
    end_of: dict[int, list[int]] = {}
    for e, p in enumerate(model.end_site_parents):
        end_of.setdefault(int(p), []).append(e)
    lines = ["HIERARCHY"]

    def offset(v) -> str:
        return "OFFSET " + " ".join(_OFFSET_FMT % x for x in v)

    def block(j: int, depth: int) -> None:
        pad = "  " * depth
        root = parents[j] < 0
        lines.append(f"{pad}{'ROOT' if root else 'JOINT'} {model.joint_names[j]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  {offset(joints[j] if root else joints[j] - joints[parents[j]])}")
        order = ROOT_ORDER if root else JOINT_ORDER
        channels = (["Xposition", "Yposition", "Zposition"] if root else []) + [f"{a}rotation" for a in order]
        lines.append(f"{pad}  CHANNELS {len(channels)} {' '.join(channels)}")
        kids = [c for c in range(len(parents)) if parents[c] == j]
        for c in kids:
            block(c, depth + 1)
        sites = end_of.get(j, [] if kids else [None])
        for e in sites:
            lines.extend([f"{pad}  End Site", f"{pad}  {{",
                      f"{pad}    {offset(np.zeros(3) if e is None else ends[e] - joints[j])}", f"{pad}  }}"])
        lines.append(f"{pad}}}")

    block(_depth_first(parents)[0], 0)
    return lines


def bvh_text(model, shape, dof_names, dofs: np.ndarray, frame_time: float) -> str:
    """The BVH file (module docstring) of joint states ``dofs`` (G, D) named ``dof_names``
    on ``model`` (the tracking body) with ``shape`` (a BodyShape, or None for the model's
    own proportions), ``frame_time`` seconds apart."""
    from hmocap_ros.body import apply_shape, pose_to_local_rotations

    params = _pose_params(model.skeleton, dof_names, dofs)
    if not np.all(np.isfinite(params)):
        bad = int(np.flatnonzero(~np.isfinite(params).all(axis=1))[0])
        raise ExportError(f"joint state {bad} holds a non-finite value")
    rest = apply_shape(model, shape)
    joints = np.asarray(rest.joints, dtype=np.float64) * BVH_UNITS_PER_M
    ends = np.asarray(rest.end_sites, dtype=np.float64) * BVH_UNITS_PER_M
    rot, root_t = pose_to_local_rotations(model.skeleton, params)
    parents = np.asarray(model.parents)
    columns = []
    for j in _depth_first(parents):
        if parents[j] < 0:
            columns.append(root_t * BVH_UNITS_PER_M)
        order = ROOT_ORDER if parents[j] < 0 else JOINT_ORDER
        columns.append(np.unwrap(matrix_to_euler(rot[:, j], order), period=360.0, axis=0))
    motion = np.concatenate(columns, axis=1)
    fmt = [_POSITION_FMT] * 3 + [_ANGLE_FMT] * (motion.shape[1] - 3)
    buf = io.StringIO()
    np.savetxt(buf, motion, fmt=fmt, delimiter=" ")
    lines = _hierarchy(model, joints, ends)
    lines += ["MOTION", f"Frames: {len(motion)}", f"Frame Time: {frame_time:.8f}"]
    return "\n".join(lines) + "\n" + buf.getvalue()
