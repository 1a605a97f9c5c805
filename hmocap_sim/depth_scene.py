"""Cluttered room for the gesture depth camera, and its Kinect-like rendering (DESIGN sec. 5).

One depth camera (640x480, fx = fy = 575 px at that size, no distortion, like a Kinect v1)
stands 1.0-1.5 m high at the room origin and looks roughly horizontally at the zone where
the person stands, 1.5-3.5 m away.  A :class:`Layout` is one furnished room, drawn from a
seeded generator:

* walls (back wall 0.4-2.3 m behind the person, or 0.15-0.85 m for ``background="close"``,
  side walls, floor, ceiling), finely tessellated because the rasteriser does not clip at the
  near plane;
* furniture made of boxes: tables, chairs, shelves with boards, cabinets, a sofa, floor
  lamps, plants, a TV stand, kept out of the person's zone and of the corridor between the
  camera and that zone (the gesture itself is never hidden by furniture);
* 0-2 other people standing behind or beside the person (posed by the caller with the
  ``hands`` body model, see ``gesture_dataset``).

Coordinates are the room frame of :mod:`hmocap_ros.geometry`: metres, +Y up, floor at
y = 0; the camera looks along +Z.  :func:`render_depth` turns meshes into a z-buffer with
:func:`hmocap_sim.render.rasterize` and into uint16 millimetres with a sensor family of
:mod:`hmocap_sim.depth_sensor` (default structured light: disparity noise and steps growing as
z^2, speckle, edge fattening, projector shadows, holes at depth edges and on dark or grazing
surfaces, 0 = no data, 0.5-4.5 m working range).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hmocap_ros.geometry import PinholeCamera, look_at
from hmocap_ros.geometry.projection import project_batch
from hmocap_sim.depth_sensor import DEFAULT_ALBEDO, DEFAULT_SENSOR, DepthSensor, sensor_by_name, sensor_depth
from hmocap_sim.render import concatenate_meshes, grid_quad, rasterize

#: Kinect v1 depth intrinsics at 640x480 (focal length in pixels).
KINECT_FX = 575.0
KINECT_SIZE = (640, 480)
#: Name of the depth camera; its optical frame is ``depth_optical_frame``.
CAMERA_NAME = "depth"


def depth_camera(position, target, width: int = 640, height: int = 480) -> PinholeCamera:
    """The Kinect-like depth camera at ``position`` looking at ``target`` (room frame);
    the focal length scales with the image width (575 px at 640)."""
    f = KINECT_FX * width / KINECT_SIZE[0]
    return look_at(CAMERA_NAME, position, target, width=width, height=height, fx=f, fy=f,
                   D=np.zeros(5))


# ---------------------------------------------------------------------------------------
# Primitive meshes
# ---------------------------------------------------------------------------------------

_BOX_FACES = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                       [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]],
                      dtype=np.int32)


def box(centre, size, yaw: float = 0.0):
    """A closed box (vertices (8, 3), faces (12, 3)), ``size`` = (width x, height y, depth z),
    turned by ``yaw`` about +Y."""
    sx, sy, sz = np.asarray(size, dtype=np.float64) / 2
    corners = np.array([[-sx, -sy, -sz], [sx, -sy, -sz], [sx, -sy, sz], [-sx, -sy, sz],
                        [-sx, sy, -sz], [sx, sy, -sz], [sx, sy, sz], [-sx, sy, sz]])
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return (corners @ rot.T + np.asarray(centre, dtype=np.float64)).astype(np.float32), _BOX_FACES.copy()


def cylinder(base, radius: float, height: float, n: int = 12):
    """A closed vertical prism with ``n`` sides standing on ``base`` (x, y, z)."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.stack([radius * np.cos(a), np.zeros(n), radius * np.sin(a)], 1)
    base = np.asarray(base, dtype=np.float64)
    v = np.concatenate([ring + base, ring + base + [0, height, 0], [base, base + [0, height, 0]]])
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [(i, i + n, j), (j, i + n, j + n), (2 * n, i, j), (2 * n + 1, j + n, i + n)]
    return v.astype(np.float32), np.array(faces, dtype=np.int32)


def _merge(parts):
    v, f, _, _ = concatenate_meshes(parts)
    return v, f


def _place(parts, x: float, z: float, yaw: float):
    """Meshes built around the origin, turned by ``yaw`` and moved to floor point (x, z)."""
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    v, f = _merge(parts)
    return (v.astype(np.float64) @ rot.T + [x, 0.0, z]).astype(np.float32), f


def _table(rng):
    """A table top on four legs."""
    u = rng.uniform
    w, d, h = u(0.8, 1.6), u(0.6, 0.9), u(0.7, 0.78)
    parts = [box((0, h - 0.02, 0), (w, 0.04, d))]
    parts += [box((sx * (w / 2 - 0.05), (h - 0.04) / 2, sz * (d / 2 - 0.05)), (0.05, h - 0.04, 0.05))
              for sx in (-1, 1) for sz in (-1, 1)]
    return parts, (w / 2, d / 2)


def _chair(rng):
    """A seat with a backrest on four legs."""
    u = rng.uniform
    w, seat = u(0.42, 0.5), u(0.43, 0.48)
    parts = [box((0, seat, 0), (w, 0.05, w)), box((0, seat + 0.25, -w / 2 + 0.02), (w, 0.45, 0.04))]
    parts += [box((sx * (w / 2 - 0.03), seat / 2, sz * (w / 2 - 0.03)), (0.035, seat, 0.035))
              for sx in (-1, 1) for sz in (-1, 1)]
    return parts, (w / 2, w / 2)


def _shelf(rng):
    """An open shelf with boards, books and boxes on them."""
    u = rng.uniform
    w, d, h = u(0.6, 1.2), u(0.28, 0.4), u(1.2, 2.1)
    boards = int(rng.integers(3, 6))
    parts = [box((-w / 2 + 0.01, h / 2, 0), (0.02, h, d)), box((w / 2 - 0.01, h / 2, 0), (0.02, h, d)),
             box((0, h / 2, -d / 2 + 0.005), (w, h, 0.01))]
    parts += [box((0, y, 0), (w, 0.02, d)) for y in np.linspace(0.05, h - 0.01, boards)]
    for y0, y1 in zip(np.linspace(0.05, h - 0.01, boards)[:-1], np.linspace(0.05, h - 0.01, boards)[1:]):
        x = -w / 2 + 0.05
        while x < w / 2 - 0.1 and rng.random() < 0.8:
            bw, bh = u(0.03, 0.15), u(0.4, 0.9) * (y1 - y0)
            parts.append(box((x + bw / 2, y0 + 0.01 + bh / 2, u(-0.05, 0.05)), (bw, bh, u(0.15, d - 0.04))))
            x += bw + u(0.0, 0.08)
    return parts, (w / 2, d / 2)


def _cabinet(rng):
    """A closed cabinet, sometimes with a box or a monitor on top."""
    u = rng.uniform
    w, d, h = u(0.5, 1.2), u(0.4, 0.6), u(0.6, 1.1)
    parts = [box((0, h / 2, 0), (w, h, d))]
    if rng.random() < 0.5:
        parts.append(box((u(-w / 4, w / 4), h + 0.15, 0), (u(0.2, 0.5), 0.3, u(0.05, 0.3))))
    return parts, (w / 2, d / 2)


def _sofa(rng):
    """A sofa: seat, backrest and two armrests."""
    u = rng.uniform
    w, d = u(1.5, 2.2), u(0.8, 0.95)
    parts = [box((0, 0.22, 0), (w, 0.44, d)), box((0, 0.62, -d / 2 + 0.1), (w, 0.4, 0.2)),
             box((-w / 2 + 0.08, 0.55, 0), (0.16, 0.22, d)), box((w / 2 - 0.08, 0.55, 0), (0.16, 0.22, d))]
    return parts, (w / 2, d / 2)


def _lamp(rng):
    """A floor lamp: base, pole and shade."""
    u = rng.uniform
    h = u(1.4, 1.8)
    parts = [cylinder((0, 0, 0), 0.15, 0.03), cylinder((0, 0.03, 0), 0.015, h - 0.03, 6),
             cylinder((0, h - 0.1, 0), u(0.15, 0.22), 0.25)]
    return parts, (0.2, 0.2)


def _plant(rng):
    """A pot with leaves as thin tilted slabs."""
    u = rng.uniform
    pot_h = u(0.3, 0.5)
    parts = [cylinder((0, 0, 0), u(0.15, 0.22), pot_h)]
    for _ in range(int(rng.integers(4, 8))):
        v, f = box((0, 0, 0), (u(0.05, 0.12), u(0.3, 0.7), 0.01))
        a, t = u(0, 2 * np.pi), u(0.2, 0.7)
        c, s = np.cos(a), np.sin(a)
        tilt = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
        yaw = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
        v = (v - [0, v[:, 1].min(), 0]) @ tilt.T @ yaw.T + [0, pot_h, 0]
        parts.append((v.astype(np.float32), f))
    return parts, (0.25, 0.25)


def _tv_stand(rng):
    """A low stand with a flat screen on it."""
    u = rng.uniform
    w = u(1.0, 1.8)
    parts = [box((0, 0.25, 0), (w, 0.5, 0.45)), box((0, 0.5 + 0.35, -0.1), (w * 0.8, 0.6, 0.06))]
    return parts, (w / 2, 0.23)


#: Furniture builders by kind: rng -> (meshes around the origin, front towards +Z; footprint
#: half-extents (x, z)).  The order of the kinds is the order :func:`make_layout` draws from.
FURNITURE = {
    "table": _table,
    "chair": _chair,
    "shelf": _shelf,
    "cabinet": _cabinet,
    "sofa": _sofa,
    "lamp": _lamp,
    "plant": _plant,
    "tv_stand": _tv_stand,
}
FURNITURE_KINDS = tuple(FURNITURE)


def furniture(kind: str, rng: np.random.Generator):
    """One piece of furniture around the origin (front towards +Z): (vertices, faces, footprint
    half-extents (x, z))."""
    build = FURNITURE.get(kind)
    if build is None:
        raise ValueError(f"unknown furniture kind {kind!r}")
    parts, half = build(rng)
    return (*_merge(parts), half)


# ---------------------------------------------------------------------------------------
# Layouts
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Layout:
    """One furnished room: the camera, the zone where the person stands and the static clutter.

    zone: (x, z, radius) of the disc where the person's pelvis may be; bystanders: floor
    positions (x, z, yaw) of the other people.  vertices/faces: all static geometry merged.
    """

    layout_id: int
    camera: PinholeCamera
    zone: tuple
    vertices: np.ndarray
    faces: np.ndarray
    items: tuple = field(default_factory=tuple)  # (kind, x, z, yaw) of each piece of furniture
    bystanders: tuple = field(default_factory=tuple)


def _walls(rng, back: float, left: float, right: float, ceiling: float, cell: float = 0.5):
    """Floor, ceiling, back and side walls of a room spanning x in [-right, left] (camera at
    the origin looking along +Z), tessellated in ``cell``-metre squares."""
    near = 0.3  # nothing of the room behind the camera: the rasteriser does not clip
    depth = back - near
    width = left + right

    def quad(origin, eu, ev):
        nu = max(1, int(np.ceil(np.linalg.norm(eu) / cell)))
        nv = max(1, int(np.ceil(np.linalg.norm(ev) / cell)))
        return grid_quad(origin, eu, ev, nu, nv)

    parts = [quad((-right, 0, near), (width, 0, 0), (0, 0, depth)),  # floor
             quad((-right, ceiling, near), (0, 0, depth), (width, 0, 0)),  # ceiling
             quad((-right, 0, back), (0, ceiling, 0), (width, 0, 0)),  # back wall
             quad((left, 0, near), (0, ceiling, 0), (0, 0, depth)),  # left wall (+x)
             quad((-right, 0, near), (0, 0, depth), (0, ceiling, 0))]  # right wall (-x)
    # A door frame or a window recess on the back wall: depth edges on a flat wall.
    if rng.random() < 0.7:
        x = rng.uniform(-right + 0.6, left - 0.6)
        parts.append(box((x, 1.05, back - 0.04), (1.0, 2.1, 0.08)) if rng.random() < 0.5
                     else box((x, 1.5, back - 0.1), (1.2, 1.0, 0.2)))
    return parts


def _blocked(x, z, half, zone, camera_xz, keep_out):
    """True if a footprint (centre x, z; half-size half) touches the person's zone or the
    corridor from the camera to the zone."""
    zx, zz, zr = zone
    r = np.hypot(*half)
    if np.hypot(x - zx, z - zz) < zr + r + keep_out:
        return True
    # distance from the segment camera -> far edge of the zone
    a = np.asarray(camera_xz, dtype=np.float64)
    b = np.array([zx, zz])
    ab = b - a
    t = np.clip(np.dot(np.array([x, z]) - a, ab) / np.dot(ab, ab), 0.0, 1.0)
    return np.hypot(*(np.array([x, z]) - (a + t * ab))) < zr + r + keep_out


def _in_view(x: float, z: float, radius: float, half_fov_tan: float = 0.55) -> bool:
    """Whether a footprint at (x, z) reaches into the camera's horizontal field of view
    (the camera at the origin looking along +Z; 0.55 = 320 / 575)."""
    return z > 0.8 and abs(x) - radius < half_fov_tan * z


def _furniture_spot(rng, half, back: float, left: float, right: float):
    """One random try at a place for a footprint of half-size ``half``: against the back wall
    or a side wall (where the camera sees it), or free-standing.  Returns (x, z, yaw,
    (half x, half z) as placed), or None when the chosen side wall has no room for it."""
    u = rng.uniform
    against_wall = rng.random() < 0.6
    if against_wall:
        wall = rng.integers(0, 3)
        if wall == 0:  # back wall, facing the camera
            x, z, yaw = u(-right + half[0], left - half[0]), back - half[1] - 0.02, np.pi
        else:
            wall_x = left if wall == 1 else right
            z_lo, z_hi = wall_x / 0.55 - 0.5, back - half[0]
            if z_lo >= z_hi:
                return None
            sign = 1.0 if wall == 1 else -1.0
            x, z, yaw = sign * (wall_x - half[1] - 0.02), u(z_lo, z_hi), -sign * np.pi / 2
        hx, hz = (half[1], half[0]) if wall else half
    else:
        x, z, yaw = u(-right + 0.4, left - 0.4), u(0.9, back - 0.4), u(-np.pi, np.pi)
        hx = hz = max(half)
    return x, z, yaw, (hx, hz)


def _furnish(rng, parts: list, zone, back: float, left: float, right: float) -> list:
    """Draw 4-9 pieces of furniture and place each (up to 30 tries) in view, clear of the
    person's zone and of the corridor to it; appends their meshes to ``parts`` and returns
    their (kind, x, z, yaw)."""
    items = []
    n_items = int(rng.integers(4, 10))
    kinds = rng.choice(FURNITURE_KINDS, size=n_items)
    for kind in kinds:
        v, f, half = furniture(str(kind), rng)
        for _ in range(30):
            spot = _furniture_spot(rng, half, back, left, right)
            if spot is None:
                continue
            x, z, yaw, (hx, hz) = spot
            if _in_view(x, z, max(hx, hz)) and not _blocked(x, z, (hx, hz), zone, (0.0, 0.0), 0.25):
                parts.append(_place([(v, f)], x, z, yaw))
                items.append((str(kind), float(x), float(z), float(yaw)))
                break
    return items


def _place_bystanders(rng, n_people: int, background: str, zone, back: float, left: float,
                      right: float, items) -> list:
    """Floor spots (x, z, yaw) of up to ``n_people`` bystanders (30 tries each), behind or
    beside the person, in view, apart from the furniture and from each other, roughly
    facing the camera."""
    u = rng.uniform
    zone_z = zone[1]
    bystanders = []
    for _ in range(n_people):
        for _ in range(30):
            if background == "close":  # no room behind the person: beside them, before the wall
                x, z = u(-right + 0.4, left - 0.4), u(zone_z - 0.5, back - 0.3)
            else:
                x, z = u(-right + 0.4, left - 0.4), u(zone_z + 0.6, back - 0.3)
                if rng.random() < 0.3:  # beside the person instead of behind
                    z = u(zone_z - 0.5, zone_z + 1.0)
            blocked = not _in_view(x, z, 0.0) or _blocked(x, z, (0.3, 0.3), zone, (0.0, 0.0), 0.15)
            blocked |= any(np.hypot(x - ix, z - iz) < 0.9 for _, ix, iz, _ in items)
            blocked |= any(np.hypot(x - bx, z - bz) < 0.7 for bx, bz, _ in bystanders)
            if not blocked:
                bystanders.append((float(x), float(z), float(np.arctan2(-x, -z) + u(-1.2, 1.2))))
                break
    return bystanders


#: Room kinds of :func:`make_layout`: the back wall 0.4-2.3 m behind the person ("room"), or
#: close behind them, 0.15-0.85 m ("close": the background of a gesture lies within a few
#: tens of centimetres, where depth clipping, eq. 3.6, matters most).
BACKGROUNDS = ("room", "close")


def make_layout(rng: np.random.Generator, layout_id: int = 0, width: int = 640, height: int = 480,
                n_bystanders: int | None = None, background: str = "room") -> Layout:
    """A random furnished room with the camera at the origin (see the module docstring);
    ``background`` (:data:`BACKGROUNDS`) sets how far behind the person the back wall stands."""
    if background not in BACKGROUNDS:
        raise ValueError(f"background must be one of {BACKGROUNDS}, got {background!r}")
    u = rng.uniform
    cam_h = u(1.0, 1.5)
    zone_z = u(2.0, 3.0)
    zone_x = u(-0.4, 0.4)
    zone = (zone_x, zone_z, 0.5 if background == "room" else 0.2)
    camera = depth_camera((u(-0.1, 0.1), cam_h, 0.0), (zone_x + u(-0.15, 0.15), u(1.1, 1.35), zone_z),
                          width, height)
    back = zone_z + zone[2] + (u(0.4, 1.8) if background == "room" else u(0.15, 0.45))
    left, right = u(1.3, 2.8), u(1.3, 2.8)
    ceiling = u(2.5, 3.0)
    parts = _walls(rng, back, left, right, ceiling)
    items = _furnish(rng, parts, zone, back, left, right)
    n_people = int(rng.choice([0, 1, 1, 2])) if n_bystanders is None else n_bystanders
    bystanders = _place_bystanders(rng, n_people, background, zone, back, left, right, items)
    v, f = _merge(parts)
    return Layout(layout_id, camera, zone, v, f, tuple(items), tuple(bystanders))


# ---------------------------------------------------------------------------------------
# Rendering
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class DepthRender:
    """A rendered frame: noisy ``depth_mm`` (uint16, 0 = invalid), the clean z-buffer
    ``zbuf`` (float32 metres along the optical axis, inf = nothing), ``face_id`` (int32, -1 =
    nothing) and the face range of each input mesh (``face_offsets``, n + 1)."""

    depth_mm: np.ndarray
    zbuf: np.ndarray
    face_id: np.ndarray
    face_offsets: np.ndarray


def face_albedo(meshes, albedo) -> np.ndarray:
    """Per-face near-infrared albedo (F,) of the concatenated ``meshes`` from ``albedo``: per
    mesh one value or one value per face."""
    parts = [np.broadcast_to(np.asarray(a, dtype=np.float32), (len(f),)) for (_, f), a in zip(meshes, albedo)]
    return np.concatenate(parts) if parts else np.zeros(0, np.float32)


def render_depth(camera: PinholeCamera, meshes, rng: np.random.Generator,
                 noise: DepthSensor | str | None = DEFAULT_SENSOR, albedo=None) -> DepthRender:
    """Rasterise meshes ``[(vertices (V, 3), faces (F, 3)), ...]`` (room frame) into the
    camera and measure the z-buffer with a depth sensor: a :class:`DepthSensor`, its name in
    :data:`hmocap_sim.depth_sensor.SENSORS`, or None (the ideal sensor: exact millimetres, no
    holes). ``albedo``: per mesh its near-infrared albedo, one value or one per face (None:
    :data:`~hmocap_sim.depth_sensor.DEFAULT_ALBEDO` everywhere)."""
    sensor = sensor_by_name("ideal" if noise is None else noise) if not isinstance(noise, DepthSensor) else noise
    meshes = list(meshes)
    verts, faces, face_offsets, _ = concatenate_meshes(meshes)
    uv, z = project_batch(np.asarray(verts, dtype=np.float64)[None], camera.K[None], camera.R[None],
                          camera.t[None], np.asarray(camera.D)[None])
    uv, z = uv[0, 0], z[0, 0]
    zbuf, face_id, _ = rasterize(uv, z, faces, camera.height, camera.width, with_barycentrics=False)
    pixel_albedo = None
    if albedo is not None and not sensor.ideal:
        per_face = np.append(face_albedo(meshes, albedo), np.float32(DEFAULT_ALBEDO))
        pixel_albedo = per_face[face_id]  # face_id -1 (nothing) reads the last entry
    depth = sensor_depth(zbuf, rng, camera.fx, sensor, pixel_albedo, (camera.cx, camera.cy))
    return DepthRender(depth, zbuf, face_id, face_offsets)


def pixel_to_optical(camera: PinholeCamera, u: float, v: float, z: float) -> np.ndarray:
    """Point (3,) in the optical frame seen at pixel (u, v) at depth z (no distortion)."""
    return np.array([(u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z])
