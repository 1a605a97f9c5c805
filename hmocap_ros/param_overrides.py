"""``KEY=VALUE`` overrides of a parameter dataclass, as command-line tools take them.

One parser for every tool that lets a user change a few fields of a parameter dataclass
(``hmocap eval mocap --param`` for :class:`~hmocap_ros.tracking.body_tracker.TrackerParams`,
``benchmarks/bench_segmentation.py -p`` and ``tools/silhouette_misses.py -p`` for
:class:`~hmocap_ros.segmentation.ForegroundParams`): each value is typed as the field's
default (``true``/``yes``/``on``/``1`` for a bool); a field without a default (a list, e.g.
``track_region``) takes comma-separated numbers.
"""
from __future__ import annotations

from dataclasses import MISSING, fields

__all__ = ["field_overrides"]


def field_overrides(cls, items, what: str = "parameter") -> dict:
    """``{field: typed value}`` of ``cls`` from ``KEY=VALUE`` strings; ValueError names a
    malformed item or an unknown key (``what``: how the message calls the fields)."""
    known = {f.name: f for f in fields(cls)}
    out = {}
    for item in items or []:
        if "=" not in item:
            raise ValueError(f"expected KEY=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        if key not in known:
            raise ValueError(f"unknown {what} {key!r}; known: {sorted(known)}")
        default = known[key].default
        if default is MISSING:  # a list (track_region): comma-separated numbers
            out[key] = [float(v) for v in value.split(",") if v.strip()]
        elif isinstance(default, bool):
            out[key] = value.lower() in ("1", "true", "yes", "on")
        else:
            out[key] = type(default)(value)
    return out
