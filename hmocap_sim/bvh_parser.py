"""Biovision Hierarchy (BVH) text: the parsed file (:class:`Bvh`) and its parser.

The file format and the conventions used to read it are described in :mod:`hmocap_sim.bvh`,
which re-exports everything public here. The HIERARCHY is parsed by recursive descent over
whitespace-separated tokens; the MOTION block is converted to floats in one numpy call. Every
error names the source and the 1-based line of the problem.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["AXES", "CHANNEL_NAMES", "Bvh", "BvhError", "load_bvh", "parse_bvh"]

#: BVH axis letter -> coordinate index.
AXES = {"X": 0, "Y": 1, "Z": 2}
#: Channel name -> (``"position"`` or ``"rotation"``, axis index).
CHANNEL_NAMES = {
    f"{axis}{kind}": (kind, AXES[axis]) for axis in "XYZ" for kind in ("position", "rotation")
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

    def with_frames(self, frames: slice | np.ndarray) -> Bvh:
        """The same skeleton with a subset of the frames (a slice or an index array)."""
        motion = np.ascontiguousarray(self.motion[frames])
        return Bvh(**{**self.__dict__, "motion": motion})


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
    hierarchy = _HierarchyParser(lines[:header_end], source).parse()
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


# ---------------------------------------------------------------------------- HIERARCHY


def _tokens(lines: list[str]):
    """(token, 1-based line number) for every whitespace-separated token; braces split off."""
    for lineno, line in enumerate(lines, start=1):
        for token in line.replace("{", " { ").replace("}", " } ").split():
            yield token, lineno


class _HierarchyParser:
    """Recursive-descent parser of the HIERARCHY section (lines before ``MOTION``).

    ``parse`` returns lists keyed ``names``, ``parents``, ``offsets``, ``channels`` (per joint,
    depth-first file order) and ``end_names``, ``end_parents``, ``end_offsets`` (per End Site).
    """

    def __init__(self, lines: list[str], source: str):
        self.tokens = list(_tokens(lines))
        self.source = source
        self.pos = 1
        self.out = {
            "names": [], "parents": [], "offsets": [], "channels": [],
            "end_names": [], "end_parents": [], "end_offsets": [],
        }

    def parse(self) -> dict:
        tokens, source = self.tokens, self.source
        if not tokens or tokens[0][0].upper() != "HIERARCHY":
            where = f"line {tokens[0][1]}" if tokens else "line 1"
            raise BvhError(f"{source}: {where}: expected 'HIERARCHY' at the start of a BVH file")
        while self.pos < len(tokens):
            token, lineno = self.take()
            if token.upper() != "ROOT":
                raise BvhError(
                    f"{source}: line {lineno}: expected 'ROOT' or 'MOTION', found {token!r}"
                )
            self.block(-1, lineno)
        if not self.out["names"]:
            raise BvhError(f"{source}: HIERARCHY has no ROOT joint")
        return self.out

    def take(self, expected: str | None = None) -> tuple[str, int]:
        """The next token and its line; ``expected``: the token that must come."""
        if self.pos >= len(self.tokens):
            raise BvhError(
                f"{self.source}: line {self.tokens[-1][1]}: HIERARCHY ends early"
                + (f" (expected {expected!r})" if expected else "")
            )
        token, lineno = self.tokens[self.pos]
        if expected is not None and token != expected:
            raise BvhError(f"{self.source}: line {lineno}: expected {expected!r}, found {token!r}")
        self.pos += 1
        return token, lineno

    def number(self, what: str) -> float:
        token, lineno = self.take()
        try:
            return float(token)
        except ValueError:
            raise BvhError(
                f"{self.source}: line {lineno}: {what}: {token!r} is not a number"
            ) from None

    def joint_name(self, keyword_line: int) -> str:
        """The rest of the ROOT/JOINT line up to ``{`` (a name may contain spaces)."""
        tokens, parts = self.tokens, []
        while (self.pos < len(tokens) and tokens[self.pos][1] == keyword_line
               and tokens[self.pos][0] != "{"):
            parts.append(tokens[self.pos][0])
            self.pos += 1
        if not parts:
            raise BvhError(f"{self.source}: line {keyword_line}: joint without a name")
        return " ".join(parts)

    def block(self, parent: int, keyword_line: int) -> None:
        """Body of a ROOT/JOINT block, from its name to its closing brace."""
        out, source = self.out, self.source
        name = self.joint_name(keyword_line)
        self.take("{")
        index = len(out["names"])
        out["names"].append(name)
        out["parents"].append(parent)
        out["channels"].append(())
        out["offsets"].append((0.0, 0.0, 0.0))
        seen_offset = False
        n_end = 0
        while True:
            token, lineno = self.take()
            key = token.upper()
            if key == "OFFSET":
                out["offsets"][index] = tuple(self.number(f"OFFSET of {name!r}") for _ in range(3))
                seen_offset = True
            elif key == "CHANNELS":
                out["channels"][index] = self.channels(name)
            elif key == "JOINT":
                self.block(index, lineno)
            elif key == "END":
                n_end += 1
                self.end_site(name, index, n_end)
            elif token == "}":
                break
            else:
                raise BvhError(
                    f"{source}: line {lineno}: unexpected {token!r} inside joint {name!r}"
                )
        if not seen_offset:
            raise BvhError(f"{source}: line {keyword_line}: joint {name!r} has no OFFSET")

    def channels(self, name: str) -> tuple[str, ...]:
        """``CHANNELS n name...`` of joint ``name``, after the keyword."""
        source, tokens = self.source, self.tokens
        count_token, count_line = self.take()
        if not count_token.isdigit():
            raise BvhError(
                f"{source}: line {count_line}: CHANNELS of {name!r} needs a count, "
                f"found {count_token!r}"
            )
        names = []
        for _ in range(int(count_token)):
            channel, channel_line = self.take()
            if channel not in CHANNEL_NAMES:
                raise BvhError(
                    f"{source}: line {channel_line}: CHANNELS of {name!r}: "
                    f"{channel!r} is not one of {sorted(CHANNEL_NAMES)} "
                    f"(or the count {count_token} is larger than the names given)"
                )
            names.append(channel)
        if (self.pos < len(tokens) and tokens[self.pos][1] == count_line
                and tokens[self.pos][0] in CHANNEL_NAMES):
            raise BvhError(
                f"{source}: line {count_line}: CHANNELS of {name!r} says "
                f"{count_token} but lists more channel names"
            )
        return tuple(names)

    def end_site(self, name: str, index: int, n_end: int) -> None:
        """``End Site { OFFSET x y z }`` of joint ``name``, after the keyword ``End``; the
        ``n_end``-th of that joint."""
        source, out = self.source, self.out
        site, site_line = self.take()
        if site.upper() != "SITE":
            raise BvhError(f"{source}: line {site_line}: expected 'End Site'")
        self.take("{")
        offset_token, offset_line = self.take()
        if offset_token.upper() != "OFFSET":
            raise BvhError(f"{source}: line {offset_line}: End Site of {name!r} needs an OFFSET")
        offset = tuple(self.number(f"End Site OFFSET of {name!r}") for _ in range(3))
        self.take("}")
        out["end_names"].append(f"{name}_end" + ("" if n_end == 1 else str(n_end)))
        out["end_parents"].append(index)
        out["end_offsets"].append(offset)


# ------------------------------------------------------------------------------- MOTION


def _parse_motion(
    lines: list[str], motion_line: int, n_channels: int, source: str
) -> tuple[float, np.ndarray]:
    """Frames / Frame Time header and the frame lines below it (0-based ``motion_line``)."""
    rest = lines[motion_line].strip()[len("MOTION"):].strip()
    if rest:
        raise BvhError(f"{source}: line {motion_line + 1}: unexpected {rest!r} after MOTION")
    n_frames_value = _header_value(lines, motion_line + 1, "Frames", source)
    frame_time = _header_value(lines, motion_line + 2, "Frame Time", source)
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
    _check_frame_counts(split, n_frames, n_channels, first, motion_line, source)
    motion = _frame_values(split, first, source).reshape(n_frames, n_channels)
    if not np.all(np.isfinite(motion)):
        i = int(np.flatnonzero(~np.isfinite(motion).all(axis=1))[0])
        raise BvhError(f"{source}: line {first + i + 1}: non-finite value in frame {i}")
    return frame_time, motion


def _header_value(lines: list[str], index: int, key: str, source: str) -> float:
    """The number after ``key:`` on line ``index`` (0-based) of the MOTION header."""
    if index >= len(lines):
        raise BvhError(f"{source}: line {index}: file ends before '{key}:' (truncated)")
    line = lines[index].strip()
    if not line.lower().replace(" ", "").startswith(key.lower().replace(" ", "") + ":"):
        raise BvhError(f"{source}: line {index + 1}: expected '{key}: <number>', found {line!r}")
    value = line.split(":", 1)[1].strip()
    try:
        return float(value)
    except ValueError:
        raise BvhError(
            f"{source}: line {index + 1}: '{key}:' value {value!r} is not a number"
        ) from None


def _check_frame_counts(
    split: list[list[str]], n_frames: int, n_channels: int, first: int, motion_line: int,
    source: str,
) -> None:
    """One value per channel on every frame line, and as many lines as ``Frames:`` says."""
    counts = np.fromiter((len(s) for s in split), dtype=np.int64, count=len(split))
    bad = np.flatnonzero(counts != n_channels)
    if bad.size:
        i = int(bad[0])
        if i == len(split) - 1 and counts[i] < n_channels and i + 1 <= n_frames:
            raise BvhError(
                f"{source}: line {first + i + 1}: frame {i} has {counts[i]} values, expected "
                f"{n_channels}: the file is truncated (header says {n_frames} frames)"
            )
        what = "an empty line" if counts[i] == 0 else f"{counts[i]} values"
        raise BvhError(
            f"{source}: line {first + i + 1}: frame {i} has {what}, expected {n_channels} "
            "(one per channel in the HIERARCHY)"
        )
    if len(split) < n_frames:
        raise BvhError(
            f"{source}: line {first + len(split)}: file ends after {len(split)} frame lines but "
            f"'Frames:' (line {motion_line + 2}) says {n_frames}: the file is truncated"
        )
    if len(split) > n_frames:
        raise BvhError(
            f"{source}: line {first + n_frames + 1}: more frame lines ({len(split)}) than "
            f"'Frames:' (line {motion_line + 2}) says ({n_frames})"
        )


def _frame_values(split: list[list[str]], first: int, source: str) -> np.ndarray:
    """All frame values as one flat float64 array (one numpy conversion)."""
    flat = [value for s in split for value in s]
    try:
        return np.array(flat, dtype=np.float64)
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
