"""Turning a stream of poses and detections into an app's events; no rclpy.

- :class:`OncePerHold`: a gesture held over many frames (every depth frame detects it again)
  counts once; it counts again after a pause of ``cooldown_ns`` without it (stamps, so a bag
  replayed at any rate gives the same events);
- :func:`zones_containing`: the zones a position is in, with a margin that keeps a body in a
  zone until it is clearly out, so a pose that wobbles on a zone's edge does not enter and
  leave at every frame.
"""

from __future__ import annotations

from collections.abc import Mapping

__all__ = ["OncePerHold", "zones_containing"]


class OncePerHold:
    """Call with the stamp of each detection: True for the first of a hold (nothing for
    ``cooldown_ns`` before it, or the stamps went back), False for the rest."""

    def __init__(self, cooldown_ns: int):
        self.cooldown_ns = int(cooldown_ns)
        self.last_ns: int | None = None

    def __call__(self, stamp_ns: int) -> bool:
        first = self.last_ns is None or stamp_ns < self.last_ns or stamp_ns - self.last_ns >= self.cooldown_ns
        self.last_ns = stamp_ns
        return first


def zones_containing(position, zones: Mapping, inside=frozenset(), margin: float = 0.0) -> set[str]:
    """Names of the ``zones`` (name -> place with ``contains``) that hold ``position`` (3,):
    a zone of ``inside`` (those the body was in) while the position is within ``margin`` m of
    it, any other once the position is in it; empty for a position of None."""
    if position is None:
        return set()
    return {name for name, zone in zones.items()
            if bool(zone.contains(position, margin if name in inside else 0.0))}
