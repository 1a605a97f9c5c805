"""The export formats, one registry (:data:`EXPORT_FORMATS`): a body's motion in, file text out."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .motion import BodyMotion, ExportError

__all__ = ["EXPORT_FORMATS", "Export", "ExportFormat", "shape_in_effect"]


@dataclass(frozen=True)
class Export:
    """A rendered file: its text, the frames it holds and notes for the user."""

    text: str
    n_frames: int
    notes: tuple = field(default=())


@dataclass(frozen=True)
class ExportFormat:
    """One output format: file suffix, a line of help, and its renderer
    ``render(motion, out_path) -> Export``."""

    suffix: str
    help: str
    render: Callable[[BodyMotion, Path], Export]


def _topics_line(motion: BodyMotion) -> str:
    return f"the bag has {', '.join(motion.bag_topics) or 'no topics'}"


def shape_in_effect(shapes, stamps_ns: np.ndarray) -> tuple:
    """The body shape of most frames at ``stamps_ns`` and how many shapes the frames use:
    a frame uses the latest shape stamped at or before it (the first shape before that)."""
    if not shapes:
        return None, 0
    at = np.maximum(np.searchsorted([s for s, _ in shapes], stamps_ns, side="right") - 1, 0)
    counts = np.bincount(at, minlength=len(shapes))
    return shapes[int(np.argmax(counts))][1], int(np.count_nonzero(counts))


def _render_bvh(motion: BodyMotion, _out: Path) -> Export:
    from hmocap_ros.body import load_body_model

    from .bvh_writer import bvh_text
    from .trc import frame_rate

    if not len(motion.dof_stamps_ns):
        raise ExportError(f"{motion.bag}: no joint states of {motion.body_id} ({motion.source}) for the BVH "
                          f"rotations; {_topics_line(motion)}")
    shape, n_shapes = shape_in_effect(motion.shapes, motion.dof_stamps_ns)
    if shape is None:
        raise ExportError(f"{motion.bag}: no body shape of {motion.body_id} ({motion.source}) for the BVH "
                          f"offsets; {_topics_line(motion)}")
    notes: tuple[str, ...] = ()
    if n_shapes > 1:
        notes = ((f"the body shape of {motion.body_id} changes during the recording ({n_shapes} shapes); "
                  "the BVH offsets are those of the shape of most frames"),)
    text = bvh_text(load_body_model("tracking"), shape, motion.dof_names, motion.dofs,
                    1.0 / frame_rate(motion.dof_stamps_ns))
    return Export(text, len(motion.dof_stamps_ns), notes)


def _render_trc(motion: BodyMotion, out: Path) -> Export:
    from .trc import trc_text

    return Export(trc_text(motion.point_names, motion.stamps_ns, motion.points, out.name), motion.n_frames)


def _render_csv(motion: BodyMotion, _out: Path) -> Export:
    from .csv_writer import csv_text

    text = csv_text(motion.body_id, motion.point_names, motion.stamps_ns, motion.points,
                    motion.dof_names, motion.dofs_at_skeleton_frames())
    return Export(text, motion.n_frames)


#: Output formats by ``--format`` name.
EXPORT_FORMATS = {
    "bvh": ExportFormat(".bvh", "Biovision hierarchy of the tracking body: offsets from the body shape, "
                                "root position and joint rotations per frame (cm, degrees)", _render_bvh),
    "trc": ExportFormat(".trc", "OpenSim marker file of the skeleton points (mm)", _render_trc),
    "csv": ExportFormat(".csv", "one row per frame: stamp, time, body id, skeleton points (m), "
                                "joint-state DoFs (m, rad)", _render_csv),
}
