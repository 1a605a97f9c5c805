"""The simulated room's camera rig, and which of its cameras see a set of points."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["ROOM_FRAME", "make_rig", "views_seeing"]

ROOM_FRAME = "room"
_TARGET = (0.0, 1.0, 0.0)  # where the rig's cameras look


def _perimeter_point(p: float, hx: float, hz: float) -> np.ndarray:
    """Point at perimeter parameter ``p`` in [0, 4) of the rectangle ``|x| <= hx, |z| <= hz``:
    integers are the corners (-hx,-hz), (hx,-hz), (hx,hz), (-hx,hz), linear in between."""
    corners = np.array([(-hx, -hz), (hx, -hz), (hx, hz), (-hx, hz)], float)
    i = int(math.floor(p)) % 4
    f = p - math.floor(p)
    return corners[i] + f * (corners[(i + 1) % 4] - corners[i])


def make_rig(n_cameras: int = 4, width: int = 640, height: int = 480):
    """The room's camera rig at ``width x height``.

    Four cameras at 4:3 are ``config/rig_example.yaml`` (upper corners, 2.5 m high, looking at
    the room centre at 1 m) scaled to the resolution; any other count or aspect ratio is a
    ring of cameras 2.5 m high spread evenly along the walls (corners first), looking at the
    same point, with intrinsics like the example's (focal length 0.81 x width, principal
    point within a few pixels of the centre, mild barrel distortion), drawn from a fixed
    seed per camera count: a calibrated installation does not change between recordings.
    """
    from hmocap_ros.config_files import find_config_file
    from hmocap_ros.geometry import look_at
    from hmocap_ros.geometry.rig import Rig, load_rig

    if not 1 <= n_cameras <= 8:
        raise ValueError(f"--cameras must be between 1 and 8, got {n_cameras}")
    if width < 16 or height < 16:
        raise ValueError(f"image size {width}x{height} is too small")
    example = find_config_file("rig_example.yaml")
    if n_cameras == 4 and width * 3 == height * 4 and example is not None:
        rig = load_rig(example)
        if rig[0].width != width:
            rig = rig.scaled(width / rig[0].width)
        return rig
    rng = np.random.default_rng(7000 + n_cameras)
    cams = []
    for k in range(n_cameras):
        x, z = _perimeter_point(4.0 * k / n_cameras, 2.8, 2.3)
        f = 0.8125 * width * (1.0 + 0.003 * rng.standard_normal())
        D = (-0.05 + 0.004 * rng.standard_normal(), 0.011 + 0.002 * rng.standard_normal(),
             0.0004 * rng.standard_normal(), 0.0004 * rng.standard_normal(), 0.0)
        cams.append(look_at(
            f"cam_{k + 1}", (x, 2.5, z), _TARGET, width=width, height=height,
            fx=round(f, 3), fy=round(f * (1.0 + 0.001 * rng.standard_normal()), 3),
            cx=round((width - 1) / 2 + 0.003 * width * rng.standard_normal(), 3),
            cy=round((height - 1) / 2 + 0.003 * height * rng.standard_normal(), 3),
            D=tuple(round(d, 5) for d in D)))
    return Rig(ROOM_FRAME, tuple(cams))


def views_seeing(rig, points: np.ndarray, margin: float) -> np.ndarray:
    """(F, M) whether all points (F, P, 3) of a frame are inside camera m's image (with a
    margin, as a fraction of the image size)."""
    from hmocap_ros.geometry import project_points

    proj = project_points(rig.cameras, points)
    w, h = rig[0].width, rig[0].height
    mx, my = margin * w, margin * h
    px = proj.pixels
    inside = (proj.visible & (px[..., 0] >= mx - 0.5) & (px[..., 0] <= w - 0.5 - mx)
              & (px[..., 1] >= my - 0.5) & (px[..., 1] <= h - 0.5 - my))
    return inside.all(axis=2).T
