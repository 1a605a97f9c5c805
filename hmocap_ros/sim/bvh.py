"""Biovision Hierarchy (BVH) motion files: parser and vectorised forward kinematics.

A BVH file has two parts (Biovision / Meredith & Maddock, "Motion capture file formats
explained", 2001):

* ``HIERARCHY``: a tree of ``ROOT`` / ``JOINT`` blocks, each with an ``OFFSET`` (translation
  from the parent joint in the parent's frame, in file units) and ``CHANNELS n ...`` naming, in
  order, the values the joint reads from every frame line (``Xposition``, ``Yposition``,
  ``Zposition``, ``Xrotation``, ``Yrotation``, ``Zrotation``, in any order); leaves carry an
  ``End Site`` block with an ``OFFSET`` only.
* ``MOTION``: ``Frames: N``, ``Frame Time: dt`` and N lines of whitespace-separated numbers, one
  value per channel, in the order the channels appear in the hierarchy (depth first).

Conventions used here (the common ones, as in Blender's importer and the CMU/cgspeed files):

* rotation channels are Euler angles in degrees; the local rotation is the product of the
  elementary rotations in the order the channels are listed, ``R = R_c1 @ R_c2 @ R_c3`` (for
  ``Zrotation Yrotation Xrotation``: ``Rz @ Ry @ Rx``), acting on column vectors;
* a joint with position channels uses them as its translation from the parent *instead of* its
  OFFSET (for roots the OFFSET is normally zero anyway); missing position axes keep the OFFSET's;
* world rotation ``G_j = G_parent @ R_j``, world position ``p_j = p_parent + G_parent @ t_j``.

Only numpy is used; the MOTION block is converted to floats in one numpy call, and forward
kinematics loops over joints (tens), never over frames or values.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

__all__ = [
    "Bvh",
    "BvhError",
    "BvhPose",
    "CMU_UNIT_M",
    "FAMILY_UNITS_M",
    "detect_family",
    "euler_to_matrix",
    "forward_kinematics",
    "load_bvh",
    "parse_bvh",
]

#: CMU ASF length unit used by the cgspeed MotionBuilder-friendly files: 1/0.45 inch, in metres.
CMU_UNIT_M = 0.0254 / 0.45

#: Metres per file unit for each known skeleton family (see ``detect_family``).
FAMILY_UNITS_M = {
    "cmu_mb": CMU_UNIT_M,  # cgspeed MotionBuilder-friendly, CMU ASF units
    "daz": 0.01,  # cgspeed Daz-friendly: centimetres (a generic Daz figure, hips ~0.84 m high)
    "cc_base": 0.01,  # iClone CC_Base retargets: centimetres
}

_AXES = {"X": 0, "Y": 1, "Z": 2}
_CHANNEL_NAMES = {
    f"{axis}{kind}": (kind, _AXES[axis]) for axis in "XYZ" for kind in ("position", "rotation")
}


class BvhError(ValueError):
    """A BVH file is malformed; the message names the source and the line."""


@dataclass(frozen=True)
class Bvh:
    """A parsed BVH file, in file units.

    Attributes:
        joint_names: names of the joints (ROOT and JOINT blocks), depth-first file order.
        parents: (J,) index of each joint's parent, -1 for a root; parents precede children.
        offsets: (J, 3) OFFSET of each joint.
        channels: per joint, the tuple of its channel names in file order.
        channel_start: (J,) column in ``motion`` of each joint's first channel.
        end_site_names: one name per End Site, ``"<parent joint>_end"`` (``_end2``... if a joint
            has several).
        end_site_parents: (E,) index of the joint each End Site hangs from.
        end_site_offsets: (E, 3) OFFSET of each End Site.
        frame_time: seconds per frame (``Frame Time:``).
        motion: (F, C) channel values, one row per frame.
        source: file name or ``"<string>"``, used in messages.
    """

    joint_names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    channel_start: np.ndarray
    end_site_names: tuple[str, ...]
    end_site_parents: np.ndarray
    end_site_offsets: np.ndarray
    frame_time: float
    motion: np.ndarray
    source: str = "<string>"

    @property
    def n_frames(self) -> int:
        return int(self.motion.shape[0])

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def fps(self) -> float:
        """Frame rate; snapped to the nearest integer when ``Frame Time`` is a rounded 1/n
        (".0083333" is 120 fps, not 120.0012)."""
        fps = 1.0 / self.frame_time
        nearest = round(fps)
        return float(nearest) if nearest > 0 and abs(fps - nearest) < 1e-3 * fps else fps

    def joint_index(self, name: str) -> int:
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise KeyError(f"{self.source}: no joint named {name!r}") from None

    def with_frames(self, frames: slice | np.ndarray) -> "Bvh":
        """The same skeleton with a subset of the frames (a slice or an index array)."""
        motion = np.ascontiguousarray(self.motion[frames])
        return Bvh(**{**self.__dict__, "motion": motion})


class BvhPose(NamedTuple):
    """World-space result of ``forward_kinematics`` (positions in metres if ``scale`` converts)."""

    positions: np.ndarray  # (F, J, 3) joint positions
    rotations: np.ndarray  # (F, J, 3, 3) joint world rotations (frame of each joint's children)
    end_sites: np.ndarray  # (F, E, 3) End Site positions

    def point(self, bvh: Bvh, name: str) -> np.ndarray:
        """(F, 3) position of a joint or an End Site (``"<joint>_end"``) by name."""
        if name in bvh.joint_names:
            return self.positions[:, bvh.joint_names.index(name)]
        if name in bvh.end_site_names:
            return self.end_sites[:, bvh.end_site_names.index(name)]
        raise KeyError(f"{bvh.source}: no joint or End Site named {name!r}")


# --------------------------------------------------------------------------- parsing


def load_bvh(path: str | os.PathLike) -> Bvh:
    """Read and parse a BVH file (see ``parse_bvh``)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise BvhError(f"{path}: cannot read BVH file: {exc}") from exc
    return parse_bvh(text, source=str(path))


def parse_bvh(text: str, source: str = "<string>") -> Bvh:
    """Parse BVH text into a ``Bvh``.

    Raises:
        BvhError: with the source name and the 1-based line number of the problem, for a missing
            HIERARCHY or MOTION section, unbalanced braces, an unknown channel name, a channel
            count that does not match its names, a missing ``Frames:`` / ``Frame Time:``, a frame
            line with the wrong number of values, a value that is not a number, or fewer (or
            more) frame lines than ``Frames:`` says.
    """
    lines = text.splitlines()
    motion_line = next(
        (i for i, line in enumerate(lines) if line.strip().upper().startswith("MOTION")), None
    )
    header_end = len(lines) if motion_line is None else motion_line
    hierarchy = _parse_hierarchy(lines[:header_end], source)
    if motion_line is None:
        raise BvhError(
            f"{source}: no MOTION section (file ends at line {len(lines)} inside or after "
            "the HIERARCHY); the file is truncated or not a BVH file"
        )
    n_channels = sum(len(c) for c in hierarchy["channels"])
    frame_time, motion = _parse_motion(lines, motion_line, n_channels, source)
    return Bvh(
        joint_names=tuple(hierarchy["names"]),
        parents=np.asarray(hierarchy["parents"], dtype=np.int64),
        offsets=np.asarray(hierarchy["offsets"], dtype=np.float64).reshape(-1, 3),
        channels=tuple(hierarchy["channels"]),
        channel_start=np.cumsum([0] + [len(c) for c in hierarchy["channels"]])[:-1].astype(
            np.int64
        ),
        end_site_names=tuple(hierarchy["end_names"]),
        end_site_parents=np.asarray(hierarchy["end_parents"], dtype=np.int64),
        end_site_offsets=np.asarray(hierarchy["end_offsets"], dtype=np.float64).reshape(-1, 3),
        frame_time=frame_time,
        motion=motion,
        source=source,
    )


def _tokens(lines: list[str]):
    """(token, 1-based line number) for every whitespace-separated token; braces split off."""
    for lineno, line in enumerate(lines, start=1):
        for token in line.replace("{", " { ").replace("}", " } ").split():
            yield token, lineno


def _parse_hierarchy(lines: list[str], source: str) -> dict:
    tokens = list(_tokens(lines))
    out = {
        "names": [], "parents": [], "offsets": [], "channels": [],
        "end_names": [], "end_parents": [], "end_offsets": [],
    }
    if not tokens or tokens[0][0].upper() != "HIERARCHY":
        where = f"line {tokens[0][1]}" if tokens else "line 1"
        raise BvhError(f"{source}: {where}: expected 'HIERARCHY' at the start of a BVH file")
    pos = 1
    last_line = tokens[-1][1]

    def take(expected: str | None = None) -> tuple[str, int]:
        nonlocal pos
        if pos >= len(tokens):
            raise BvhError(
                f"{source}: line {last_line}: HIERARCHY ends early"
                + (f" (expected {expected!r})" if expected else "")
            )
        token, lineno = tokens[pos]
        if expected is not None and token != expected:
            raise BvhError(f"{source}: line {lineno}: expected {expected!r}, found {token!r}")
        pos += 1
        return token, lineno

    def number(what: str) -> float:
        token, lineno = take()
        try:
            return float(token)
        except ValueError:
            raise BvhError(f"{source}: line {lineno}: {what}: {token!r} is not a number") from None

    def joint_name(keyword_line: int) -> str:
        nonlocal pos
        parts = []
        while pos < len(tokens) and tokens[pos][1] == keyword_line and tokens[pos][0] != "{":
            parts.append(tokens[pos][0])
            pos += 1
        if not parts:
            raise BvhError(f"{source}: line {keyword_line}: joint without a name")
        return " ".join(parts)

    def block(parent: int, keyword_line: int) -> None:
        """Body of a ROOT/JOINT block, from its name to its closing brace."""
        name = joint_name(keyword_line)
        take("{")
        index = len(out["names"])
        out["names"].append(name)
        out["parents"].append(parent)
        out["channels"].append(())
        out["offsets"].append((0.0, 0.0, 0.0))
        seen_offset = False
        n_end = 0
        while True:
            token, lineno = take()
            key = token.upper()
            if key == "OFFSET":
                out["offsets"][index] = tuple(number(f"OFFSET of {name!r}") for _ in range(3))
                seen_offset = True
            elif key == "CHANNELS":
                count_token, count_line = take()
                if not count_token.isdigit():
                    raise BvhError(
                        f"{source}: line {count_line}: CHANNELS of {name!r} needs a count, "
                        f"found {count_token!r}"
                    )
                names = []
                for _ in range(int(count_token)):
                    channel, channel_line = take()
                    if channel not in _CHANNEL_NAMES:
                        raise BvhError(
                            f"{source}: line {channel_line}: CHANNELS of {name!r}: "
                            f"{channel!r} is not one of {sorted(_CHANNEL_NAMES)} "
                            f"(or the count {count_token} is larger than the names given)"
                        )
                    names.append(channel)
                if pos < len(tokens) and tokens[pos][1] == count_line and tokens[pos][0] in (
                    _CHANNEL_NAMES
                ):
                    raise BvhError(
                        f"{source}: line {count_line}: CHANNELS of {name!r} says "
                        f"{count_token} but lists more channel names"
                    )
                out["channels"][index] = tuple(names)
            elif key == "JOINT":
                block(index, lineno)
            elif key == "END":
                site, site_line = take()
                if site.upper() != "SITE":
                    raise BvhError(f"{source}: line {site_line}: expected 'End Site'")
                take("{")
                offset_token, offset_line = take()
                if offset_token.upper() != "OFFSET":
                    raise BvhError(
                        f"{source}: line {offset_line}: End Site of {name!r} needs an OFFSET"
                    )
                offset = tuple(number(f"End Site OFFSET of {name!r}") for _ in range(3))
                take("}")
                n_end += 1
                out["end_names"].append(f"{name}_end" + ("" if n_end == 1 else str(n_end)))
                out["end_parents"].append(index)
                out["end_offsets"].append(offset)
            elif token == "}":
                break
            else:
                raise BvhError(
                    f"{source}: line {lineno}: unexpected {token!r} inside joint {name!r}"
                )
        if not seen_offset:
            raise BvhError(f"{source}: line {keyword_line}: joint {name!r} has no OFFSET")

    while pos < len(tokens):
        token, lineno = take()
        if token.upper() != "ROOT":
            raise BvhError(f"{source}: line {lineno}: expected 'ROOT' or 'MOTION', found {token!r}")
        block(-1, lineno)
    if not out["names"]:
        raise BvhError(f"{source}: HIERARCHY has no ROOT joint")
    return out


def _parse_motion(
    lines: list[str], motion_line: int, n_channels: int, source: str
) -> tuple[float, np.ndarray]:
    """Frames / Frame Time header and the frame lines below it (0-based ``motion_line``)."""
    rest = lines[motion_line].strip()[len("MOTION"):].strip()
    if rest:
        raise BvhError(f"{source}: line {motion_line + 1}: unexpected {rest!r} after MOTION")

    def header(index: int, key: str) -> float:
        if index >= len(lines):
            raise BvhError(f"{source}: line {index}: file ends before '{key}:' (truncated)")
        line = lines[index].strip()
        if not line.lower().replace(" ", "").startswith(key.lower().replace(" ", "") + ":"):
            raise BvhError(
                f"{source}: line {index + 1}: expected '{key}: <number>', found {line!r}"
            )
        value = line.split(":", 1)[1].strip()
        try:
            return float(value)
        except ValueError:
            raise BvhError(
                f"{source}: line {index + 1}: '{key}:' value {value!r} is not a number"
            ) from None

    n_frames_value = header(motion_line + 1, "Frames")
    frame_time = header(motion_line + 2, "Frame Time")
    if n_frames_value < 0 or n_frames_value != int(n_frames_value):
        raise BvhError(
            f"{source}: line {motion_line + 2}: Frames must be a count, got {n_frames_value}"
        )
    if not frame_time > 0:
        raise BvhError(
            f"{source}: line {motion_line + 3}: Frame Time must be > 0, got {frame_time}"
        )
    n_frames = int(n_frames_value)
    first = motion_line + 3  # 0-based index of the first frame line
    rows = lines[first:]
    while rows and not rows[-1].strip():
        rows.pop()
    split = [row.split() for row in rows]
    counts = np.fromiter((len(s) for s in split), dtype=np.int64, count=len(split))
    bad = np.flatnonzero(counts != n_channels)
    if bad.size:
        i = int(bad[0])
        if i == len(rows) - 1 and counts[i] < n_channels and i + 1 <= n_frames:
            raise BvhError(
                f"{source}: line {first + i + 1}: frame {i} has {counts[i]} values, expected "
                f"{n_channels}: the file is truncated (header says {n_frames} frames)"
            )
        what = "an empty line" if counts[i] == 0 else f"{counts[i]} values"
        raise BvhError(
            f"{source}: line {first + i + 1}: frame {i} has {what}, expected {n_channels} "
            "(one per channel in the HIERARCHY)"
        )
    if len(rows) < n_frames:
        raise BvhError(
            f"{source}: line {first + len(rows)}: file ends after {len(rows)} frame lines but "
            f"'Frames:' (line {motion_line + 2}) says {n_frames}: the file is truncated"
        )
    if len(rows) > n_frames:
        raise BvhError(
            f"{source}: line {first + n_frames + 1}: more frame lines ({len(rows)}) than "
            f"'Frames:' (line {motion_line + 2}) says ({n_frames})"
        )
    flat = [value for s in split for value in s]
    try:
        motion = np.array(flat, dtype=np.float64)
    except ValueError:
        # Rare path: find the offending value to name its line.
        for i, s in enumerate(split):
            for value in s:
                try:
                    float(value)
                except ValueError:
                    raise BvhError(
                        f"{source}: line {first + i + 1}: {value!r} is not a number"
                    ) from None
        raise
    motion = motion.reshape(n_frames, n_channels)
    if not np.all(np.isfinite(motion)):
        i = int(np.flatnonzero(~np.isfinite(motion).all(axis=1))[0])
        raise BvhError(f"{source}: line {first + i + 1}: non-finite value in frame {i}")
    return frame_time, motion


# ----------------------------------------------------------------------------- families


def detect_family(bvh: Bvh) -> str | None:
    """Which known skeleton family a BVH uses, from its joint names.

    Returns ``"cmu_mb"`` (cgspeed MotionBuilder-friendly CMU conversion: Hips, LHipJoint,
    LeftUpLeg, LowerBack, Spine1, ...), ``"daz"`` (cgspeed Daz-friendly: hip, abdomen, chest,
    lShldr, lThigh, ...), ``"cc_base"`` (Reallusion iClone CC_Base rig: CC_Base_Hip,
    CC_Base_L_Upperarm, ...) or ``None``.
    """
    names = set(bvh.joint_names)
    if {"Hips", "LeftUpLeg", "RightUpLeg", "LeftArm", "RightArm", "LeftForeArm", "Head"} <= names:
        return "cmu_mb"
    if {"hip", "abdomen", "chest", "lThigh", "rThigh", "lShldr", "rShldr", "head"} <= names:
        return "daz"
    if {"CC_Base_Hip", "CC_Base_L_Thigh", "CC_Base_R_Thigh", "CC_Base_L_Upperarm",
            "CC_Base_Head"} <= names:
        return "cc_base"
    return None


# --------------------------------------------------------------------------- kinematics


def euler_to_matrix(angles_deg: np.ndarray, order: str) -> np.ndarray:
    """Rotation matrices from Euler angles applied in BVH channel order.

    Args:
        angles_deg: (..., k) angles in degrees, column i about axis ``order[i]``.
        order: axis letters, e.g. ``"ZYX"``; the result is ``R_order[0] @ R_order[1] @ ...``
            (intrinsic rotations, as BVH channel lists are read).

    Returns:
        (..., 3, 3) rotation matrices.
    """
    angles = np.radians(np.asarray(angles_deg, dtype=np.float64))
    if angles.shape[-1] != len(order):
        raise ValueError(f"{angles.shape[-1]} angles for rotation order {order!r}")
    result = np.broadcast_to(np.eye(3), angles.shape[:-1] + (3, 3)).copy()
    for i, axis in enumerate(order.upper()):
        c, s = np.cos(angles[..., i]), np.sin(angles[..., i])
        elementary = np.zeros(angles.shape[:-1] + (3, 3))
        a = _AXES[axis]
        b, d = (a + 1) % 3, (a + 2) % 3
        elementary[..., a, a] = 1.0
        elementary[..., b, b] = c
        elementary[..., d, d] = c
        elementary[..., b, d] = -s
        elementary[..., d, b] = s
        result = result @ elementary
    return result


def local_transforms(bvh: Bvh, motion: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-joint local rotations (F, J, 3, 3) and translations (F, J, 3), file units."""
    motion = bvh.motion if motion is None else np.asarray(motion, dtype=np.float64)
    n_frames = motion.shape[0]
    rotations = np.broadcast_to(np.eye(3), (n_frames, bvh.n_joints, 3, 3)).copy()
    translations = np.broadcast_to(bvh.offsets, (n_frames, bvh.n_joints, 3)).copy()
    for j, channels in enumerate(bvh.channels):
        start = int(bvh.channel_start[j])
        rot_cols, rot_axes = [], ""
        for k, channel in enumerate(channels):
            kind, axis = _CHANNEL_NAMES[channel]
            if kind == "position":
                translations[:, j, axis] = motion[:, start + k]
            else:
                rot_cols.append(start + k)
                rot_axes += "XYZ"[axis]
        if rot_cols:
            rotations[:, j] = euler_to_matrix(motion[:, rot_cols], rot_axes)
    return rotations, translations


def forward_kinematics(
    bvh: Bvh, frames: slice | np.ndarray | None = None, scale: float = 1.0
) -> BvhPose:
    """World positions and rotations of every joint in every (selected) frame.

    Args:
        bvh: parsed file.
        frames: optional slice or index array of frames; all frames by default.
        scale: metres per file unit (e.g. ``FAMILY_UNITS_M[detect_family(bvh)]``); positions are
            multiplied by it, rotations are unaffected.

    Returns:
        ``BvhPose`` with positions (F, J, 3), rotations (F, J, 3, 3), end_sites (F, E, 3), in
        the file's axes.
    """
    motion = bvh.motion if frames is None else bvh.motion[frames]
    local_r, local_t = local_transforms(bvh, motion)
    world_r = np.empty_like(local_r)
    world_p = np.empty_like(local_t)
    for j, parent in enumerate(bvh.parents):
        if parent < 0:
            world_r[:, j] = local_r[:, j]
            world_p[:, j] = local_t[:, j]
        else:
            world_r[:, j] = world_r[:, parent] @ local_r[:, j]
            world_p[:, j] = world_p[:, parent] + np.einsum(
                "fab,fb->fa", world_r[:, parent], local_t[:, j]
            )
    if len(bvh.end_site_names):
        ends = world_p[:, bvh.end_site_parents] + np.einsum(
            "feab,eb->fea", world_r[:, bvh.end_site_parents], bvh.end_site_offsets
        )
    else:
        ends = np.zeros((motion.shape[0], 0, 3))
    return BvhPose(world_p * scale, world_r, ends * scale)
