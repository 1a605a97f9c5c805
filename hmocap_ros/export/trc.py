"""Skeleton points -> an OpenSim marker file (``.trc``, "PathFileType 4 (X/Y/Z)").

Layout (tab-separated, as OpenSim's TRCFileAdapter reads it):

    PathFileType  4  (X/Y/Z)  <file name>
    DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  OrigDataStartFrame  OrigNumFrames
    <rate>    <rate>      <F>        <P>         mm     <rate>        1                   <F>
    Frame#  Time  <marker 1>  (two empty cells)  <marker 2> ...
                  X1  Y1  Z1  X2  Y2  Z2 ...
    (empty line)
    1  0.000000  x  y  z ...

One marker per skeleton point (joints, and end sites where the skeleton has them), in
millimetres with three decimals, in the room frame: +Y up like OpenSim's ground, so no axis is
swapped. ``Time`` is seconds from the first frame (from the stamps, gaps kept); the rate is the
median frame interval's.
"""

from __future__ import annotations

import io

import numpy as np

__all__ = ["TRC_UNITS_PER_M", "frame_rate", "trc_text"]

TRC_UNITS_PER_M = 1000.0
#: Frame rate written for a single frame, whose rate the stamps cannot tell.
SINGLE_FRAME_RATE_HZ = 25.0


def frame_rate(stamps_ns: np.ndarray) -> float:
    """Frames per second of the median interval between ``stamps_ns``."""
    steps = np.diff(np.asarray(stamps_ns, dtype=np.int64))
    return 1e9 / float(np.median(steps)) if len(steps) else SINGLE_FRAME_RATE_HZ


def trc_text(names, stamps_ns: np.ndarray, points_m: np.ndarray, file_name: str) -> str:
    """The TRC file of points (F, P, 3) in metres named ``names``, at ``stamps_ns`` (F,)."""
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    n, p = len(stamps_ns), len(names)
    rate = f"{frame_rate(stamps_ns):.6g}"
    header = [
        f"PathFileType\t4\t(X/Y/Z)\t{file_name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate}\t{rate}\t{n}\t{p}\tmm\t{rate}\t1\t{n}",
        "Frame#\tTime\t" + "\t".join(f"{name}\t\t" for name in names).rstrip("\t"),
        "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, p + 1)),
        "",
    ]
    time_s = (stamps_ns - stamps_ns[0]) * 1e-9 if n else np.zeros(0)
    table = np.column_stack([np.arange(1, n + 1), time_s,
                             np.asarray(points_m, dtype=np.float64).reshape(n, 3 * p) * TRC_UNITS_PER_M])
    buf = io.StringIO()
    np.savetxt(buf, table, fmt=["%d", "%.6f"] + ["%.3f"] * (3 * p), delimiter="\t")
    return "\n".join(header) + "\n" + buf.getvalue()
