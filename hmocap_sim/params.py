"""The settings of a simulated multi-view recording (``hmocap sim mocap``'s options).

:class:`MocapSimConfig` is read by the recording (:mod:`.mocap_dataset`) and by its parts
(:mod:`.mocap_subject`, :mod:`.mocap_distractors`), so it lives apart from all of them.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import hmocap_ros

__all__ = ["DATA_DIR", "DEFAULT_BVH", "MocapSimConfig"]

#: The product's data folder (body assets, BVH clips).
DATA_DIR = Path(hmocap_ros.__file__).resolve().parent / "data"
DEFAULT_BVH = DATA_DIR / "bvh" / "13_26.bvh"


@dataclass(frozen=True)
class MocapSimConfig:
    """Everything that defines a recording (the CLI options)."""

    out: Path
    bvh: Path = DEFAULT_BVH
    cameras: int = 4
    width: int = 640
    height: int = 480
    fps: float = 25.0
    start: float = 0.0
    seconds: float = 4.0
    background_seconds: float = 1.0
    still_seconds: float = 0.0
    seed: int = 0
    people: int = 1
    distractors: bool = False
    lighting_changes: bool = False
    shadows: bool = True
    noise: bool = True
    supersample: int = 0
    rig: Path | None = None
    contact_frames: int = 4
    force: bool = False
    progress: bool = True
