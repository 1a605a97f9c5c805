"""The files beside a simulated recording's bag: the rig YAML and the contact sheet."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = ["clear_outputs", "output_paths", "save_contact_sheet", "save_rig_yaml"]


def output_paths(out: Path) -> tuple[Path, Path]:
    """``<stem>_rig.yaml`` and ``<stem>.contact.png`` next to the bag ``out``."""
    stem = out.name[:-len(out.suffix)] if out.suffix else out.name
    return out.with_name(f"{stem}_rig.yaml"), out.with_name(f"{stem}.contact.png")


def clear_outputs(paths: Sequence[Path], force: bool) -> None:
    """Remove existing outputs when ``force``; otherwise refuse to overwrite them."""
    for p in paths:
        if p.exists():
            if not force:
                raise FileExistsError(f"{p} exists; use --force to overwrite")
            if p.is_dir():
                import shutil
                shutil.rmtree(p)
            else:
                p.unlink()


def save_rig_yaml(rig, path: Path, bag_name: str, seed: int) -> None:
    """The rig in ``hmocap_ros.geometry.rig.load_rig`` format, with a header naming the recording."""
    from hmocap_ros.geometry.rig import save_rig

    save_rig(rig, path, header=(
        f"Camera rig of {bag_name} (hmocap sim mocap, seed {seed}).\n"
        "Room frame: metres, +Y up, floor y = 0, room x in [-3, 3], z in [-2.5, 2.5]."))


def save_contact_sheet(path: Path, sheet_rows: list, n_background: int, fps: float,
                       title: str) -> None:
    """One row per kept frame ``(frame, tiles)``, labelled with the time since the subject
    appeared; a blank 8 x 8 image when no frame was kept."""
    from hmocap_sim.contact_sheet import contact_sheet, save_png

    if sheet_rows:
        sheet = contact_sheet([r for _, r in sheet_rows],
                              row_labels=[f"{(i - n_background) / fps:.2f} s"
                                          for i, _ in sheet_rows],
                              title=title)
    else:
        sheet = np.zeros((8, 8, 3), np.uint8)
    save_png(path, sheet)
