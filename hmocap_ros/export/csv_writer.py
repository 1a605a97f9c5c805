"""Skeleton points and joint states -> one CSV row per frame.

Columns: ``stamp_ns`` (the messages' ``header.stamp``, integer nanoseconds), ``time_s``
(seconds from the first row), ``body_id``, then ``<point>_x``, ``<point>_y``, ``<point>_z`` per
skeleton point (metres, room frame, +Y up, six decimals), then one column per joint-state DoF
by its name (root translation in metres, angles in radians, six decimals), ``nan`` in a row
whose stamp has no joint state. The DoF columns are left out when the bag has no joint states
for the body. Rows follow the skeleton messages of the body.
"""

from __future__ import annotations

import io

import numpy as np

__all__ = ["csv_text"]


def _cell(text: str) -> str:
    """A CSV cell (RFC 4180 quoting where the text needs it)."""
    return '"' + text.replace('"', '""') + '"' if any(c in text for c in ',"\n') else text


def csv_text(body_id: str, names, stamps_ns: np.ndarray, points_m: np.ndarray,
             dof_names=(), dofs: np.ndarray | None = None) -> str:
    """The CSV of points (F, P, 3) named ``names`` and joint-state values ``dofs`` (F, D)
    named ``dof_names`` at ``stamps_ns`` (F,)."""
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    n = len(stamps_ns)
    columns = ["stamp_ns", "time_s", "body_id"]
    columns += [f"{name}_{axis}" for name in names for axis in "xyz"]
    columns += list(dof_names)
    values = [np.asarray(points_m, dtype=np.float64).reshape(n, -1)]
    if len(dof_names):
        values.append(np.asarray(dofs, dtype=np.float64).reshape(n, len(dof_names)))
    buf = io.StringIO()
    np.savetxt(buf, np.concatenate(values, axis=1), fmt="%.6f", delimiter=",")
    time_s = np.char.mod("%.9f", (stamps_ns - stamps_ns[0]) * 1e-9 if n else np.zeros(0))
    prefix = np.char.add(np.char.add(stamps_ns.astype(str), ","), time_s)
    prefix = np.char.add(prefix, f",{_cell(body_id)},")
    rows = np.char.add(prefix, np.asarray(buf.getvalue().splitlines(), dtype=str)).tolist() if n else []
    return "\n".join([",".join(_cell(c) for c in columns), *rows]) + "\n"
