"""Named places and zones of a room from a YAML file, read again when the file changes; no rclpy.

Format (``config/places_example.yaml`` is one)::

    frame_id: world            # the frame of every coordinate: the app's fixed frame (+Z up)
    places:                    # what an app points at or makes a gesture near
      tv: {point: [0.0, 2.45, 1.1]}
      lamp: {box: {min: [-2.9, 2.0, 0.0], max: [-2.4, 2.5, 1.8]}}
    zones:                     # areas of the floor (presence)
      door: {box: {min: [2.0, -2.5], max: [3.0, -1.2]}}   # [x, y]: a floor rectangle, any height

An app names the section it reads (``places`` or ``zones``). A file that cannot be read, a
section that is missing, or a ``frame_id`` other than the app's fixed frame leaves the app
without places; an entry with an error is left out and the others are kept. Each problem is
one line of text (:attr:`PlacesFile.errors`); the app logs it and keeps running, and
:meth:`PlacesFile.reload_if_changed` reads the file again once it is written.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml

from hmocap_ros.client.geometry import BoxPlace, PointPlace

__all__ = ["PlacesFile", "parse_place", "read_places"]


def parse_place(name: str, spec) -> PointPlace | BoxPlace:
    """The place of one YAML entry: ``{point: [x, y, z]}`` or ``{box: {min: [...], max: [...]}}``.
    ValueError naming the entry otherwise."""
    try:
        if isinstance(spec, dict) and set(spec) == {"point"}:
            return PointPlace(_numbers(spec["point"]))
        if isinstance(spec, dict) and set(spec) == {"box"} and isinstance(spec["box"], dict) \
                and set(spec["box"]) == {"min", "max"}:
            return BoxPlace(_numbers(spec["box"]["min"]), _numbers(spec["box"]["max"]))
    except ValueError as err:
        raise ValueError(f"{name}: {err}") from None
    raise ValueError(f"{name}: expected {{point: [x, y, z]}} or {{box: {{min: [...], max: [...]}}}}, got {spec!r}")


def _numbers(value) -> np.ndarray:
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                      for v in value):
        raise ValueError(f"expected a list of numbers, got {value!r}")
    return np.array([float(v) for v in value], dtype=np.float64)


def read_places(path, section: str, frame_id: str) -> tuple[dict, list[str]]:
    """``({name: place}, errors)`` of ``section`` of the YAML file ``path``, whose coordinates
    must be in ``frame_id`` (module docstring); every error a line naming the file."""
    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        reason = str(err).splitlines()[0] if str(err) else type(err).__name__
        return {}, [f"{path}: cannot read ({reason}): no {section}"]
    if not isinstance(data, dict):
        return {}, [f"{path}: expected a mapping with '{section}:', got {type(data).__name__}: no {section}"]
    frame = str(data.get("frame_id", frame_id))
    if frame != frame_id:
        return {}, [f"{path}: coordinates in frame '{frame}', the app works in '{frame_id}': no {section}"]
    entries = data.get(section)
    if not isinstance(entries, dict) or not entries:
        return {}, [f"{path}: no '{section}:' mapping of names to places: no {section}"]
    places, errors = {}, []
    for name, spec in entries.items():
        try:
            places[str(name)] = parse_place(str(name), spec)
        except ValueError as err:
            errors.append(f"{path}: {section} {err}: left out")
    return places, errors


def _signature(path) -> tuple | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_ino, st.st_size, st.st_mtime_ns


class PlacesFile:
    """The places of one section of a YAML file, kept as last read (module docstring).

    ``places`` maps names to places; ``errors`` holds the problems of the last reading.
    """

    def __init__(self, path, section: str, frame_id: str):
        self.path = Path(path)
        self.section = section
        self.frame_id = frame_id
        self._signature = _signature(self.path)
        self.places, self.errors = read_places(self.path, section, frame_id)

    def reload_if_changed(self) -> bool:
        """Read the file again when it changed since the last reading (a file that disappears
        keeps the places as they were); True when it was read."""
        signature = _signature(self.path)
        if signature is None or signature == self._signature:
            return False
        self._signature = signature
        self.places, self.errors = read_places(self.path, self.section, self.frame_id)
        return True

    def __getitem__(self, name: str):
        return self.places[name]

    def get(self, name: str, default=None):
        return self.places.get(name, default)

    def items(self):
        return self.places.items()

    def __len__(self) -> int:
        return len(self.places)
