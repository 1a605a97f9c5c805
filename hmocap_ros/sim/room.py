"""The furnished smart room of the multi-view simulator: static geometry, materials, lights.

Room frame (as ``config/rig_example.yaml``): metres, +Y up, floor ``y = 0``, the room spans
``x in [-size_x/2, size_x/2]`` and ``z in [-size_z/2, size_z/2]`` (6 x 5 m by default) and is
``height`` high. :func:`build_room` makes a seeded variation of one layout:

- north wall (``z = -2.5``): a door in its frame (with a dark corridor behind its opening, so
  that the door can swing open as a distractor), a framed poster, a bookshelf with books;
- east wall (``x = +3``): a window (bright glass, white frame and sill) above a radiator, a
  table with a laptop and a mug, and two chairs;
- south wall (``z = +2.5``): a whiteboard, a low sideboard, a potted plant in the corner;
- west wall (``x = -3``): a second bookshelf, a poster, a wall clock;
- skirting boards everywhere, a wooden (or laminate, or tiled) floor, mottled plaster walls.

Everything is meshed with :func:`hmocap_ros.render.meshes.grid_quad`-style tessellation
(the rasteriser does not clip at the near plane and lens distortion bends long edges) and
carries a material index into :attr:`Room.materials` and per-vertex coordinates into one
procedural texture atlas (posters, whiteboard, clock face, rug). Window panes are emissive:
the renderer paints them with :attr:`Room.emissive` instead of shading them.

The moving parts used as distractors are described here too: :class:`Door` (hinged panel)
and :func:`ball_mesh` (a beach ball rolling on the floor). Free floor space for the person is
given by :meth:`Room.clearance`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from hmocap_ros.render.shading import Material

__all__ = ["RoomSpec", "SceneMesh", "MeshBuilder", "Door", "Room", "build_room", "ball_mesh",
           "box_mesh", "textured_quad", "uv_sphere"]

ATLAS_CELLS = 4  # the atlas is ATLAS_CELLS x ATLAS_CELLS square cells
ATLAS_CELL_PX = 256


@dataclass(frozen=True)
class RoomSpec:
    """Room size in metres (floor centred on the origin) and mesh density."""

    size_x: float = 6.0
    size_z: float = 5.0
    height: float = 2.8
    cell: float = 0.25  # tessellation of large surfaces (m)

    @property
    def half_x(self) -> float:
        return 0.5 * self.size_x

    @property
    def half_z(self) -> float:
        return 0.5 * self.size_z


@dataclass(frozen=True, eq=False)
class SceneMesh:
    """Triangles with a material per face and texture coordinates per vertex."""

    vertices: np.ndarray  # (V, 3) float32
    faces: np.ndarray  # (F, 3) int32
    face_material: np.ndarray  # (F,) int32
    uv: np.ndarray  # (V, 2) float32, atlas coordinates (0 where unused)
    colours: np.ndarray  # (V, 3) float32 sRGB multipliers (1 where unused)

    @property
    def n_faces(self) -> int:
        return len(self.faces)


class MeshBuilder:
    """Accumulates mesh parts (vertices, faces, material, uv, colours) into a :class:`SceneMesh`."""

    def __init__(self) -> None:
        self._parts: list[tuple] = []
        self._n_vertices = 0

    def add(self, vertices, faces, material: int, uv=None, colours=None) -> None:
        v = np.asarray(vertices, dtype=np.float32).reshape(-1, 3)
        f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        uv = np.zeros((len(v), 2), np.float32) if uv is None else np.asarray(uv, np.float32)
        if colours is None:
            colours = np.ones((len(v), 3), np.float32)
        colours = np.broadcast_to(np.asarray(colours, np.float32), (len(v), 3))
        self._parts.append((v, f + self._n_vertices, np.full(len(f), material, np.int32), uv,
                            colours))
        self._n_vertices += len(v)

    def add_mesh(self, mesh: tuple, material: int, colours=None) -> None:
        """Add a ``(vertices, faces, uv)`` triple from the helpers below."""
        self.add(mesh[0], mesh[1], material, mesh[2], colours)

    def build(self) -> SceneMesh:
        if not self._parts:
            return SceneMesh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32),
                             np.zeros(0, np.int32), np.zeros((0, 2), np.float32),
                             np.zeros((0, 3), np.float32))
        v, f, m, uv, c = (np.concatenate(x) for x in zip(*self._parts))
        return SceneMesh(v.astype(np.float32), f.astype(np.int32), m.astype(np.int32),
                         uv.astype(np.float32), np.ascontiguousarray(c, np.float32))


# ----------------------------------------------------------------------------- mesh helpers


def textured_quad(origin, edge_u, edge_v, n_u: int = 1, n_v: int = 1, uv_rect=None):
    """A planar quad ``origin + s edge_u + t edge_v`` in ``n_u x n_v`` cells (two triangles
    each), facing ``edge_u x edge_v``. ``uv_rect = (u0, v0, u1, v1)`` maps ``s`` to
    ``u0..u1`` and ``t`` to ``v1..v0`` (atlas images have their top row at ``v0``, and
    ``edge_v`` points up on walls). Returns ``(vertices, faces, uv)``."""
    n_u = max(int(n_u), 1)
    n_v = max(int(n_v), 1)
    s = np.linspace(0.0, 1.0, n_u + 1)
    t = np.linspace(0.0, 1.0, n_v + 1)
    ss, tt = np.meshgrid(s, t, indexing="xy")
    verts = (np.asarray(origin, float) + ss[..., None] * np.asarray(edge_u, float)
             + tt[..., None] * np.asarray(edge_v, float)).reshape(-1, 3)
    ii, jj = np.meshgrid(np.arange(n_u), np.arange(n_v), indexing="xy")
    a = (jj * (n_u + 1) + ii).ravel()
    b = a + 1
    c = a + n_u + 1
    d = c + 1
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    if uv_rect is None:
        uv = np.zeros((len(verts), 2))
    else:
        u0, v0, u1, v1 = uv_rect
        uv = np.stack([u0 + ss.ravel() * (u1 - u0), v1 - tt.ravel() * (v1 - v0)], 1)
    return verts.astype(np.float32), faces.astype(np.int32), uv.astype(np.float32)


def _cells(length: float, cell: float) -> int:
    return max(1, int(math.ceil(abs(length) / cell - 1e-9)))


def _merge(parts):
    verts, faces, uvs, n = [], [], [], 0
    for v, f, uv in parts:
        verts.append(v)
        faces.append(f + n)
        uvs.append(uv)
        n += len(v)
    return (np.concatenate(verts).astype(np.float32), np.concatenate(faces).astype(np.int32),
            np.concatenate(uvs).astype(np.float32))


def box_mesh(lo, hi, *, cell: float = 1.0, yaw: float = 0.0, pivot=(0.0, 0.0, 0.0),
             skip=(), uv_faces: dict | None = None):
    """Axis-aligned box ``lo..hi`` (outward faces), optionally turned by ``yaw`` about the
    vertical through ``pivot``. ``skip``: faces to leave out ('-x', '+x', '-y', '+y', '-z',
    '+z'); ``uv_faces``: atlas rectangles per face name. Returns ``(vertices, faces, uv)``."""
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    dx, dy, dz = hi - lo
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    uv_faces = uv_faces or {}
    spec = {
        "+x": ((x1, y0, z1), (0, 0, -dz), (0, dy, 0)),
        "-x": ((x0, y0, z0), (0, 0, dz), (0, dy, 0)),
        "+y": ((x0, y1, z1), (dx, 0, 0), (0, 0, -dz)),
        "-y": ((x0, y0, z0), (dx, 0, 0), (0, 0, dz)),
        "+z": ((x0, y0, z1), (dx, 0, 0), (0, dy, 0)),
        "-z": ((x1, y0, z0), (-dx, 0, 0), (0, dy, 0)),
    }
    parts = []
    for name, (o, eu, ev) in spec.items():
        if name in skip:
            continue
        nu = _cells(np.linalg.norm(eu), cell)
        nv = _cells(np.linalg.norm(ev), cell)
        parts.append(textured_quad(o, eu, ev, nu, nv, uv_faces.get(name)))
    v, f, uv = _merge(parts)
    if yaw:
        v = _turn(v, yaw, pivot)
    return v, f, uv


def _turn(vertices, yaw: float, pivot) -> np.ndarray:
    """Rotate points about the vertical axis through ``pivot`` (positive: +z towards +x)."""
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    p = np.asarray(pivot, float)
    return ((np.asarray(vertices, float) - p) @ rot.T + p).astype(np.float32)


def uv_sphere(centre, radii, n_lat: int = 10, n_lon: int = 16, *, split_lon: bool = False):
    """An ellipsoid (outward faces) with ``n_lat`` bands and ``n_lon`` segments. With
    ``split_lon`` every segment gets its own vertices (for sharp per-segment colours); uv
    holds (segment index, band index). Returns ``(vertices, faces, uv)``."""
    centre = np.asarray(centre, float)
    radii = np.broadcast_to(np.asarray(radii, float), (3,))
    lat = np.linspace(0.0, math.pi, n_lat + 1)
    parts = []
    if split_lon:
        for k in range(n_lon):
            lon = np.array([k, k + 1]) * 2 * math.pi / n_lon
            la, lo_ = np.meshgrid(lat, lon, indexing="ij")
            v = np.stack([np.sin(la) * np.sin(lo_), np.cos(la), np.sin(la) * np.cos(lo_)], -1)
            v = (v.reshape(-1, 3) * radii + centre)
            i = np.arange(n_lat)
            a, b, c, d = 2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3
            f = np.concatenate([np.stack([a, c, d], 1), np.stack([a, d, b], 1)])
            uv = np.tile([k, 0.0], (len(v), 1))
            parts.append((v, f, uv))
        return _merge(parts)
    lon = np.linspace(0.0, 2 * math.pi, n_lon + 1)
    la, lo_ = np.meshgrid(lat, lon, indexing="ij")
    v = np.stack([np.sin(la) * np.sin(lo_), np.cos(la), np.sin(la) * np.cos(lo_)], -1)
    v = v.reshape(-1, 3) * radii + centre
    ii, jj = np.meshgrid(np.arange(n_lat), np.arange(n_lon), indexing="ij")
    a = (ii * (n_lon + 1) + jj).ravel()
    b = a + 1
    c = a + n_lon + 1
    d = c + 1
    f = np.concatenate([np.stack([a, c, d], 1), np.stack([a, d, b], 1)])
    return v.astype(np.float32), f.astype(np.int32), np.zeros((len(v), 2), np.float32)


def _cylinder(base, radius_bottom: float, radius_top: float, height: float, n: int = 16,
              cap: bool = True):
    """A (truncated) cone standing on ``base`` with a top cap. Returns (vertices, faces, uv)."""
    base = np.asarray(base, float)
    ang = np.linspace(0.0, 2 * math.pi, n + 1)[:-1]
    ring = np.stack([np.sin(ang), np.zeros(n), np.cos(ang)], 1)
    bottom = base + ring * radius_bottom
    top = base + ring * radius_top + [0.0, height, 0.0]
    v = np.concatenate([bottom, top, [base + [0.0, height, 0.0]]])
    k = np.arange(n)
    k1 = (k + 1) % n
    f = [np.stack([k, k1, n + k1], 1), np.stack([k, n + k1, n + k], 1)]
    if cap:
        f.append(np.stack([n + k, n + k1, np.full(n, 2 * n)], 1))
    return v.astype(np.float32), np.concatenate(f).astype(np.int32), np.zeros((len(v), 2),
                                                                               np.float32)


def ball_mesh(centre, radius: float, spin: float = 0.0, axis_yaw: float = 0.0):
    """A beach ball: an 8-segment sphere rolled by ``spin`` radians about a horizontal axis
    at ``axis_yaw``. Returns ``(vertices, faces, segment index per vertex)``."""
    v, f, uv = uv_sphere((0.0, 0.0, 0.0), radius, 10, 8, split_lon=True)
    c, s = math.cos(spin), math.sin(spin)
    roll = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])  # about +x
    v = v @ roll.T
    v = _turn(v, axis_yaw, (0.0, 0.0, 0.0)) + np.asarray(centre, np.float32)
    return v.astype(np.float32), f, uv[:, 0].astype(np.int32)


# ----------------------------------------------------------------------------- the atlas


class _Atlas:
    """A square float32 sRGB atlas of ``ATLAS_CELLS^2`` cells; :meth:`add` returns the uv
    rectangle of a cell (with a half-texel inset so bilinear lookups stay inside)."""

    def __init__(self) -> None:
        n = ATLAS_CELLS * ATLAS_CELL_PX
        self.image = np.ones((n, n, 3), np.float32)
        self._next = 0

    def add(self, image: np.ndarray, aspect: float = 1.0) -> tuple:
        """Store ``image`` (uint8 RGB, any size) in the next cell; return its uv rectangle."""
        if self._next >= ATLAS_CELLS * ATLAS_CELLS:
            raise ValueError("texture atlas is full")
        row, col = divmod(self._next, ATLAS_CELLS)
        self._next += 1
        px = ATLAS_CELL_PX
        cell = cv2.resize(image, (px, px), interpolation=cv2.INTER_AREA)
        self.image[row * px:(row + 1) * px, col * px:(col + 1) * px] = cell / 255.0
        n = float(ATLAS_CELLS * px)
        inset = 1.0 / n
        return (col * px / n + inset, row * px / n + inset,
                (col + 1) * px / n - inset, (row + 1) * px / n - inset)


def _poster_circles(rng, size=(360, 256)) -> np.ndarray:
    """Abstract print: overlapping coloured discs on a light ground."""
    h, w = size
    ground = rng.choice([(236, 232, 220), (245, 240, 232), (40, 44, 52), (226, 222, 210)])
    img = np.zeros((h, w, 3), np.uint8)
    img[:] = ground
    palette = [(72, 52, 120), (38, 120, 60), (200, 120, 140), (110, 90, 200), (60, 180, 170),
               (220, 170, 60), (190, 70, 50), (40, 90, 150)]
    for _ in range(int(rng.integers(6, 11))):
        c = palette[int(rng.integers(len(palette)))]
        centre = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        cv2.circle(img, centre, int(rng.integers(w // 10, w // 4)), c, -1, cv2.LINE_AA)
    return img


def _poster_landscape(rng, size=(256, 360)) -> np.ndarray:
    """A simple landscape print: sky gradient, sun, layered hills."""
    h, w = size
    y = np.linspace(0, 1, h)[:, None, None]
    top = np.array(rng.choice([(120, 170, 220), (235, 160, 120), (150, 190, 230)]), float)
    bottom = np.array([235, 230, 215], float)
    img = (top + (bottom - top) * y).repeat(w, axis=1).astype(np.uint8)
    cv2.circle(img, (int(w * rng.uniform(0.2, 0.8)), int(h * 0.3)), h // 10, (250, 240, 200), -1,
               cv2.LINE_AA)
    greens = [(90, 130, 80), (60, 100, 60), (40, 70, 45)]
    for k, g in enumerate(greens):
        base = h * (0.55 + 0.15 * k)
        xs = np.arange(0, w + 8, 8)
        ys = base - h * 0.08 * np.sin(xs / w * math.pi * (1.5 + k) + rng.uniform(0, 6))
        pts = np.concatenate([np.stack([xs, ys], 1), [[w, h], [0, h]]]).astype(np.int32)
        cv2.fillPoly(img, [pts], g, cv2.LINE_AA)
    return img


def _whiteboard(rng, size=(256, 360)) -> np.ndarray:
    h, w = size
    img = np.full((h, w, 3), 246, np.uint8)
    colours = [(30, 60, 170), (20, 20, 20), (170, 40, 40), (30, 120, 60)]
    y = int(h * 0.12)
    while y < h * 0.85:
        x0 = int(w * rng.uniform(0.06, 0.3))
        x1 = int(w * rng.uniform(0.55, 0.94))
        c = colours[int(rng.integers(len(colours)))]
        xs = np.linspace(x0, x1, 24)
        ys = y + 2.0 * np.sin(xs * 0.3 + rng.uniform(0, 6))
        cv2.polylines(img, [np.stack([xs, ys], 1).astype(np.int32)], False, c, 2, cv2.LINE_AA)
        y += int(h * rng.uniform(0.08, 0.14))
    cv2.rectangle(img, (int(w * 0.62), int(h * 0.55)), (int(w * 0.9), int(h * 0.85)),
                  colours[0], 2, cv2.LINE_AA)
    return img


def _clock_face(size=256) -> np.ndarray:
    img = np.full((size, size, 3), 250, np.uint8)
    c = size // 2
    cv2.circle(img, (c, c), c - 2, (30, 30, 30), 10, cv2.LINE_AA)
    for k in range(12):
        a = k * math.pi / 6
        p0 = (int(c + 0.78 * c * math.sin(a)), int(c - 0.78 * c * math.cos(a)))
        p1 = (int(c + 0.9 * c * math.sin(a)), int(c - 0.9 * c * math.cos(a)))
        cv2.line(img, p0, p1, (30, 30, 30), 6, cv2.LINE_AA)
    cv2.line(img, (c, c), (int(c + 0.45 * c), int(c - 0.2 * c)), (20, 20, 20), 8, cv2.LINE_AA)
    cv2.line(img, (c, c), (int(c - 0.15 * c), int(c - 0.7 * c)), (20, 20, 20), 5, cv2.LINE_AA)
    return img


def _rug(rng, size=256) -> np.ndarray:
    """A patterned rug: border bands and a diamond lattice."""
    base = np.array(rng.choice([(150, 50, 45), (60, 70, 120), (90, 100, 80)]), float)
    img = np.zeros((size, size, 3), np.uint8)
    img[:] = base
    light = tuple(int(x) for x in np.clip(base * 1.8 + 30, 0, 255))
    dark = tuple(int(x) for x in base * 0.5)
    for k, col in enumerate((light, dark, light)):
        m = 10 + 12 * k
        cv2.rectangle(img, (m, m), (size - m, size - m), col, 4)
    for i in range(-size, 2 * size, 40):
        cv2.line(img, (i, 46), (i + size, 46 + size), dark, 3, cv2.LINE_AA)
        cv2.line(img, (i, 46 + size), (i + size, 46), dark, 3, cv2.LINE_AA)
    img[:46] = cv2.resize(img[46:92], (size, 46))
    return img


# ----------------------------------------------------------------------------- the room


@dataclass(frozen=True, eq=False)
class Door:
    """A door panel hinged on a vertical axis, swinging into the room.

    ``mesh`` is the closed panel in room coordinates; :meth:`vertices` turns it by an
    opening angle (radians, positive into the room) about the hinge.
    """

    mesh: SceneMesh
    hinge: tuple  # (x, z) of the hinge axis
    swing_sign: float  # yaw sign that swings the panel into the room
    max_angle: float = math.radians(80.0)

    def vertices(self, angle: float) -> np.ndarray:
        if angle == 0.0:
            return self.mesh.vertices
        return _turn(self.mesh.vertices, self.swing_sign * angle,
                     (self.hinge[0], 0.0, self.hinge[1]))


@dataclass(frozen=True, eq=False)
class Room:
    """A furnished room: static mesh, door, materials, atlas, lights and free floor space.

    Attributes:
        spec: dimensions.
        static: every static triangle (walls, floor, ceiling, furniture, window, corridor).
        shadow_casters: static faces in the lamp's shadow map (furniture; not the room's
            shell, whose planes only receive shadows).
        door: the hinged door panel (closed unless a distractor opens it).
        materials: materials indexed by the meshes' ``face_material``.
        material_index: name -> index into ``materials``.
        atlas: float32 sRGB texture atlas (H, W, 3) for 'image' materials.
        emissive: material index -> linear RGB radiance painted unshaded (window glass: above
            1, so the sky through the window is overexposed, as indoor cameras show it).
        lamp: position of the ceiling lamp (the shadow-casting light).
        lamp_colour: its linear RGB intensity (irradiance at 1 m).
        window_direction: travel direction of the daylight through the window.
        window_colour: linear RGB irradiance of the daylight.
        ambient_sky, ambient_ground: hemispheric ambient light (linear RGB).
        obstacles: floor footprints ``(x0, z0, x1, z1)`` of the furniture.
    """

    spec: RoomSpec
    static: SceneMesh
    shadow_casters: np.ndarray  # indices of static faces that cast the lamp's shadows
    door: Door
    materials: tuple
    material_index: dict
    atlas: np.ndarray
    emissive: dict
    lamp: tuple
    lamp_colour: tuple
    window_direction: tuple
    window_colour: tuple
    ambient_sky: tuple
    ambient_ground: tuple
    obstacles: tuple = field(default=())

    def clearance(self, xz: np.ndarray) -> np.ndarray:
        """Distance (m) from floor points ``(..., 2)`` to the nearest wall or furniture
        footprint (negative inside furniture or outside the room)."""
        xz = np.asarray(xz, float)
        x, z = xz[..., 0], xz[..., 1]
        d = np.minimum(np.minimum(self.spec.half_x - x, self.spec.half_x + x),
                       np.minimum(self.spec.half_z - z, self.spec.half_z + z))
        for x0, z0, x1, z1 in self.obstacles:
            dx = np.maximum(np.maximum(x0 - x, x - x1), 0.0)
            dz = np.maximum(np.maximum(z0 - z, z - z1), 0.0)
            outside = np.hypot(dx, dz)
            inside = -np.minimum(np.minimum(x - x0, x1 - x), np.minimum(z - z0, z1 - z))
            d = np.minimum(d, np.where((dx > 0) | (dz > 0), outside, inside))
        return d


_WALL_PAINTS = [  # (main tone, mottling tone), sRGB
    ((0.87, 0.85, 0.80), (0.79, 0.77, 0.72)),
    ((0.81, 0.86, 0.83), (0.73, 0.78, 0.75)),
    ((0.80, 0.83, 0.87), (0.72, 0.75, 0.80)),
    ((0.90, 0.87, 0.78), (0.82, 0.79, 0.70)),
    ((0.84, 0.82, 0.77), (0.76, 0.74, 0.69)),
    ((0.88, 0.84, 0.84), (0.80, 0.76, 0.76)),
]
_FLOORS = [
    Material("wood", (0.70, 0.46, 0.28), (0.42, 0.24, 0.12), scale=0.15),
    Material("wood", (0.78, 0.62, 0.42), (0.56, 0.40, 0.24), scale=0.18),
    Material("wood", (0.60, 0.58, 0.55), (0.42, 0.40, 0.38), scale=0.19),
    Material("tiles", (0.74, 0.73, 0.70), (0.45, 0.44, 0.42), scale=0.5, noise=0.05),
]
_BOOK_COLOURS = [(0.55, 0.12, 0.10), (0.12, 0.22, 0.45), (0.15, 0.35, 0.20), (0.80, 0.70, 0.45),
                 (0.20, 0.20, 0.22), (0.85, 0.85, 0.80), (0.50, 0.30, 0.55), (0.75, 0.45, 0.15),
                 (0.25, 0.45, 0.55), (0.60, 0.55, 0.50)]


def build_room(rng: np.random.Generator, spec: RoomSpec = RoomSpec()) -> Room:
    """A seeded variation of the furnished room (layout in the module docstring).

    Colours, floor type, poster prints, book sizes and small placement offsets come from
    ``rng``; the layout itself is fixed, so that the person's floor area is always free.
    """
    hx, hz, H, cell = spec.half_x, spec.half_z, spec.height, spec.cell
    atlas = _Atlas()
    materials: list[Material] = []
    index: dict[str, int] = {}

    def mat(name: str, m: Material) -> int:
        index[name] = len(materials)
        materials.append(m)
        return index[name]

    paint_a, paint_b = (_WALL_PAINTS[i] for i in rng.choice(len(_WALL_PAINTS), 2, replace=False))
    floor = _FLOORS[int(rng.integers(len(_FLOORS)))]
    m_floor = mat("floor", Material(floor.kind, floor.colour, floor.colour2, scale=floor.scale,
                                    noise=floor.noise, seed=int(rng.integers(1000))))
    m_wall_a = mat("wall_a", Material("plaster", *paint_a, scale=0.45, noise=0.04, seed=2))
    m_wall_b = mat("wall_b", Material("plaster", *paint_b, scale=0.45, noise=0.04, seed=3))
    m_ceiling = mat("ceiling", Material("plaster", (0.93, 0.93, 0.91), (0.89, 0.89, 0.87),
                                        scale=0.6, noise=0.02, seed=4))
    m_trim = mat("trim", Material("plain", (0.93, 0.92, 0.89), noise=0.02, scale=0.05,
                                  specular=0.08))
    m_door = mat("door", Material("wood", (0.50, 0.31, 0.17), (0.33, 0.19, 0.09), scale=0.3,
                                  angle=math.pi / 2, seed=5, specular=0.05))
    m_metal = mat("metal", Material("plain", (0.62, 0.62, 0.64), specular=0.6))
    m_corridor = mat("corridor", Material("plaster", (0.55, 0.53, 0.50), (0.48, 0.46, 0.44),
                                          scale=0.4, noise=0.04, seed=6))
    m_glass = mat("glass", Material("plain", (0.9, 0.95, 1.0)))
    m_image = mat("image", Material("image", (1.0, 1.0, 1.0), specular=0.04))
    m_frame = mat("frame", Material("plain", (0.10, 0.10, 0.10), specular=0.1))
    m_shelf = mat("shelf", Material("wood", (0.62, 0.44, 0.28), (0.45, 0.30, 0.18), scale=0.25,
                                    angle=0.0, seed=7))
    m_white_furn = mat("white_furniture", Material("plain", (0.88, 0.88, 0.86), noise=0.02,
                                                   scale=0.1, specular=0.1))
    m_table = mat("table", Material("wood", (0.72, 0.55, 0.36), (0.55, 0.38, 0.22), scale=0.35,
                                    seed=8, specular=0.08))
    m_chair = mat("chair", Material("plain", (1.0, 1.0, 1.0), vertex_colour=True, specular=0.1))
    m_fabric = mat("upholstery", Material("fabric", (1.0, 1.0, 1.0), scale=0.06, noise=0.12,
                                          vertex_colour=True, seed=9))
    m_books = mat("books", Material("plain", (1.0, 1.0, 1.0), vertex_colour=True, noise=0.03,
                                    scale=0.02))
    m_plant = mat("plant", Material("fabric", (0.22, 0.42, 0.18), scale=0.05, noise=0.35,
                                    smooth=False, seed=10))
    m_pot = mat("pot", Material("plain", (0.62, 0.32, 0.22), noise=0.05, scale=0.05,
                                specular=0.1))
    m_radiator = mat("radiator", Material("plain", (0.92, 0.92, 0.90), specular=0.15))
    m_dark = mat("dark", Material("plain", (0.12, 0.12, 0.13), specular=0.3))

    # Atlas images (posters, whiteboard, clock, rug).
    uv_poster1 = atlas.add(_poster_circles(rng))
    uv_poster2 = atlas.add(_poster_landscape(rng))
    uv_poster3 = atlas.add(_poster_circles(rng))
    uv_board = atlas.add(_whiteboard(rng))
    uv_clock = atlas.add(_clock_face())
    uv_rug = atlas.add(_rug(rng))

    b = MeshBuilder()
    obstacles: list[tuple] = []

    # ---- floor and ceiling
    b.add_mesh(textured_quad((-hx, 0, -hz), (0, 0, 2 * hz), (2 * hx, 0, 0),
                             _cells(2 * hz, cell), _cells(2 * hx, cell)), m_floor)
    b.add_mesh(textured_quad((-hx, H, -hz), (2 * hx, 0, 0), (0, 0, 2 * hz),
                             _cells(2 * hx, cell), _cells(2 * hz, cell)), m_ceiling)

    # ---- walls: (origin, unit direction along the wall, length, material, holes (u0,u1,v0,v1))
    door_u0 = 1.15 + rng.uniform(-0.1, 0.1)  # along the north wall from x = -hx
    door_w, door_h = 0.92, 2.05
    win_u0 = 1.35 + rng.uniform(-0.15, 0.15)  # along the east wall from z = -hz
    win_w, win_sill, win_top = 1.5, 0.9, 2.2
    walls = {
        "north": ((-hx, 0, -hz), (1, 0, 0), 2 * hx, m_wall_a,
                  [(door_u0, door_u0 + door_w, 0, door_h)]),
        "east": ((hx, 0, -hz), (0, 0, 1), 2 * hz, m_wall_b,
                 [(win_u0, win_u0 + win_w, win_sill, win_top)]),
        "south": ((hx, 0, hz), (-1, 0, 0), 2 * hx, m_wall_a, []),
        "west": ((-hx, 0, hz), (0, 0, -1), 2 * hz, m_wall_b, []),
    }
    for origin, direction, length, m, holes in walls.values():
        origin = np.asarray(origin, float)
        direction = np.asarray(direction, float)
        _wall_with_holes(b, origin, direction, length, H, holes, m, cell)
        # Skirting board: 8 cm high, 1.5 cm proud, interrupted by the door.
        spans = [(0.0, length)]
        for u0, u1, v0, _ in holes:
            if v0 == 0:
                spans = [(a, min(c, u0)) for a, c in spans if a < u0] + \
                        [(max(a, u1), c) for a, c in spans if c > u1]
        inward = np.array([-direction[2], 0.0, direction[0]])  # into the room
        for a, c in spans:
            if c - a < 0.02:
                continue
            p0 = np.asarray(origin) + direction * a
            b.add_mesh(textured_quad(p0 + inward * 0.015, direction * (c - a), (0, 0.08, 0),
                                     _cells(c - a, cell), 1), m_trim)
            b.add_mesh(textured_quad(p0 + inward * 0.015 + [0, 0.08, 0], direction * (c - a),
                                     -inward * 0.015, _cells(c - a, cell), 1), m_trim)

    # ---- door opening on the north wall: reveal, frame (architrave), corridor behind
    n_origin = np.array([-hx, 0.0, -hz])
    dx0 = n_origin[0] + door_u0
    dx1 = dx0 + door_w
    wall_t = 0.12
    zw = -hz
    # reveal (the wall's thickness around the opening)
    b.add_mesh(textured_quad((dx0, 0, zw), (0, 0, -wall_t), (0, door_h, 0), 1, 8), m_wall_a)
    b.add_mesh(textured_quad((dx1, 0, zw - wall_t), (0, 0, wall_t), (0, door_h, 0), 1, 8), m_wall_a)
    b.add_mesh(textured_quad((dx0, door_h, zw), (door_w, 0, 0), (0, 0, -wall_t), 4, 1), m_wall_a)
    # architrave: three trim strips 7 cm wide, 2 cm proud
    for lo, hi in (((dx0 - 0.07, 0, zw), (dx0, door_h + 0.07, zw + 0.02)),
                   ((dx1, 0, zw), (dx1 + 0.07, door_h + 0.07, zw + 0.02)),
                   ((dx0, door_h, zw), (dx1, door_h + 0.07, zw + 0.02))):
        b.add_mesh(box_mesh(lo, hi, cell=0.5, skip=("-z",)), m_trim)
    # corridor: a dim box behind the opening
    cz = zw - wall_t
    depth = 1.6
    b.add_mesh(textured_quad((dx0 - 0.6, 0, cz - depth), (0, 0, depth), (door_w + 1.2, 0, 0),
                             6, 8), m_floor)
    b.add_mesh(textured_quad((dx0 - 0.6, 0, cz - depth), (door_w + 1.2, 0, 0), (0, H, 0), 8, 10),
               m_corridor)
    b.add_mesh(textured_quad((dx0 - 0.6, 0, cz), (0, 0, -depth), (0, H, 0), 6, 10), m_corridor)
    b.add_mesh(textured_quad((dx1 + 0.6, 0, cz - depth), (0, 0, depth), (0, H, 0), 6, 10),
               m_corridor)
    b.add_mesh(textured_quad((dx0 - 0.6, H, cz), (door_w + 1.2, 0, 0), (0, 0, -depth), 8, 6),
               m_corridor)
    # the door panel (separate, movable), hinged at dx0, 4 cm thick, flush with the room side
    door_builder = MeshBuilder()
    panel_lo = (dx0 + 0.005, 0.01, zw - 0.045)
    panel_hi = (dx1 - 0.005, door_h - 0.005, zw - 0.005)
    door_builder.add_mesh(box_mesh(panel_lo, panel_hi, cell=0.35), m_door)
    handle_x = dx1 - 0.09
    door_builder.add_mesh(box_mesh((handle_x - 0.02, 1.02, zw - 0.005),
                                   (handle_x + 0.02, 1.06, zw + 0.045), cell=1), m_metal)
    door_builder.add_mesh(box_mesh((handle_x - 0.13, 1.025, zw + 0.045),
                                   (handle_x + 0.02, 1.055, zw + 0.065), cell=1), m_metal)
    door = Door(door_builder.build(), hinge=(dx0 + 0.005, zw - 0.005), swing_sign=-1.0)
    obstacles.append((dx0, -hz, dx1, -hz + door_w))  # where the door swings

    # ---- window on the east wall: reveal, glass, frame and mullions, sill, radiator
    e_z0 = -hz + win_u0
    e_z1 = e_z0 + win_w
    xw = hx
    b.add_mesh(textured_quad((xw, win_sill, e_z0), (wall_t, 0, 0), (0, win_top - win_sill, 0),
                             1, 5), m_wall_b)
    b.add_mesh(textured_quad((xw + wall_t, win_sill, e_z1), (-wall_t, 0, 0),
                             (0, win_top - win_sill, 0), 1, 5), m_wall_b)
    b.add_mesh(textured_quad((xw, win_top, e_z0), (0, 0, win_w), (wall_t, 0, 0), 6, 1), m_wall_b)
    b.add_mesh(textured_quad((xw + wall_t, win_sill, e_z0), (-wall_t, 0, 0), (0, 0, win_w), 1, 6),
               m_trim)
    gx = xw + 0.08
    b.add_mesh(textured_quad((gx, win_sill, e_z0), (0, 0, win_w), (0, win_top - win_sill, 0),
                             6, 5), m_glass)
    fw = 0.06
    zm = 0.5 * (e_z0 + e_z1)
    ym = win_sill + 0.62 * (win_top - win_sill)
    for lo, hi in (((gx - 0.05, win_sill, e_z0), (gx, win_top, e_z0 + fw)),
                   ((gx - 0.05, win_sill, e_z1 - fw), (gx, win_top, e_z1)),
                   ((gx - 0.05, win_sill, e_z0), (gx, win_sill + fw, e_z1)),
                   ((gx - 0.05, win_top - fw, e_z0), (gx, win_top, e_z1)),
                   ((gx - 0.05, win_sill, zm - 0.03), (gx, win_top, zm + 0.03)),
                   ((gx - 0.05, ym - 0.03, e_z0), (gx, ym + 0.03, e_z1))):
        b.add_mesh(box_mesh(lo, hi, cell=0.5, skip=("+x",)), m_trim)
    b.add_mesh(box_mesh((xw - 0.06, win_sill - 0.04, e_z0 - 0.06), (xw + 0.02, win_sill,
                                                                    e_z1 + 0.06), cell=0.5),
               m_trim)
    # radiator: a box with vertical fins
    r_z0, r_z1 = zm - 0.55, zm + 0.55
    b.add_mesh(box_mesh((xw - 0.09, 0.15, r_z0), (xw - 0.03, 0.72, r_z1), cell=0.5, skip=("+x",)),
               m_radiator)
    for z in np.arange(r_z0 + 0.03, r_z1 - 0.02, 0.05):
        b.add_mesh(box_mesh((xw - 0.11, 0.17, z - 0.008), (xw - 0.09, 0.70, z + 0.008), cell=1,
                            skip=("+x", "-y")), m_radiator)

    # ---- table with laptop and mug, two chairs, by the east wall (south of the window)
    tx0, tx1 = hx - 0.95, hx - 0.15
    tz0 = hz - 1.85 + rng.uniform(-0.1, 0.1)
    tz1 = tz0 + 1.4
    top_y = 0.74
    b.add_mesh(box_mesh((tx0, top_y, tz0), (tx1, top_y + 0.035, tz1), cell=0.5), m_table)
    for lx, lz in ((tx0 + 0.04, tz0 + 0.04), (tx1 - 0.08, tz0 + 0.04), (tx0 + 0.04, tz1 - 0.08),
                   (tx1 - 0.08, tz1 - 0.08)):
        b.add_mesh(box_mesh((lx, 0, lz), (lx + 0.045, top_y, lz + 0.045), cell=0.5,
                            skip=("-y", "+y")), m_table)
    obstacles.append((tx0, tz0, tx1, tz1))
    # laptop: base and opened lid
    lap_x, lap_z = tx0 + 0.35, tz0 + 0.45
    b.add_mesh(box_mesh((lap_x - 0.16, top_y + 0.035, lap_z - 0.12),
                        (lap_x + 0.16, top_y + 0.05, lap_z + 0.12), cell=1), m_dark)
    lid = box_mesh((lap_x - 0.16, top_y + 0.05, lap_z - 0.12),
                   (lap_x + 0.16, top_y + 0.065, lap_z + 0.12), cell=1)
    # tilt the lid up about its hinge edge (towards +x, facing the room)
    lv = lid[0] - [lap_x + 0.16, top_y + 0.05, 0]
    a = math.radians(-105.0)
    rot = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    b.add(lv @ rot.T + [lap_x + 0.16, top_y + 0.05, 0], lid[1], m_dark)
    b.add_mesh(_cylinder((tx0 + 0.3, top_y + 0.035, tz1 - 0.3), 0.04, 0.045, 0.1, 12), m_pot)
    # chairs: seat, legs, back; upholstered seat in a random colour
    seat_colour = [(0.15, 0.25, 0.45), (0.45, 0.12, 0.12), (0.25, 0.25, 0.27),
                   (0.20, 0.38, 0.30)][int(rng.integers(4))]
    for cz_, yaw in ((tz0 + 0.35, math.pi / 2 + rng.uniform(-0.25, 0.25)),
                     (tz1 - 0.35, math.pi / 2 + rng.uniform(-0.25, 0.25))):
        cx_ = tx0 - 0.25 + rng.uniform(-0.05, 0.1)
        _chair(b, (cx_, cz_), yaw, m_chair, m_fabric, seat_colour)
        obstacles.append((cx_ - 0.3, cz_ - 0.3, cx_ + 0.3, cz_ + 0.3))

    # ---- bookshelves (north wall east part, west wall)
    _bookshelf(b, rng, (hx - 1.45 + rng.uniform(-0.2, 0.1), -hz), 0.0, 0.9, 1.95, 0.34,
               m_shelf, m_books)
    obstacles.append((hx - 1.7, -hz, hx - 0.4, -hz + 0.4))
    wz = -0.2 + rng.uniform(-0.15, 0.15)
    _bookshelf(b, rng, (-hx, wz), math.pi / 2, 1.0, 1.8, 0.32, m_white_furn, m_books)
    obstacles.append((-hx, wz - 0.6, -hx + 0.4, wz + 0.6))

    # ---- sideboard and plant by the south wall, whiteboard above
    sb_x0 = -1.6 + rng.uniform(-0.2, 0.2)
    b.add_mesh(box_mesh((sb_x0, 0.08, hz - 0.45), (sb_x0 + 1.6, 0.8, hz - 0.01), cell=0.5),
               m_white_furn)
    b.add_mesh(box_mesh((sb_x0 + 0.05, 0, hz - 0.4), (sb_x0 + 1.55, 0.08, hz - 0.06), cell=0.5,
                        skip=("-y",)), m_dark)
    for k in range(1, 4):
        x = sb_x0 + 0.4 * k
        b.add_mesh(box_mesh((x - 0.004, 0.1, hz - 0.455), (x + 0.004, 0.78, hz - 0.45), cell=1),
                   m_dark)
    obstacles.append((sb_x0, hz - 0.45, sb_x0 + 1.6, hz))
    px_, pz_ = -hx + 0.35, hz - 0.35
    b.add_mesh(_cylinder((px_, 0.0, pz_), 0.15, 0.2, 0.42, 16), m_pot)
    for k in range(7):
        ang = rng.uniform(0, 2 * math.pi)
        r = rng.uniform(0.0, 0.16)
        centre = (px_ + r * math.sin(ang), 0.55 + rng.uniform(0.0, 0.7), pz_ + r * math.cos(ang))
        b.add_mesh(uv_sphere(centre, (rng.uniform(0.14, 0.22), rng.uniform(0.16, 0.28),
                                      rng.uniform(0.14, 0.22)), 6, 9), m_plant)
    obstacles.append((px_ - 0.3, pz_ - 0.3, hx, hz))
    bw, bh = 1.5, 1.0
    bx0 = sb_x0 + 0.05
    _framed_picture(b, (bx0 + bw, 1.0, hz), (-1, 0, 0), bw, bh, uv_board, m_image, m_metal, 0.025)

    # ---- pictures, clock, rug
    _framed_picture(b, (-hx + 3.3 + rng.uniform(-0.2, 0.2), 1.25, -hz), (1, 0, 0), 0.55, 0.75,
                    uv_poster1, m_image, m_frame, 0.02)
    _framed_picture(b, (-hx, 1.2, hz - 0.6 + rng.uniform(-0.1, 0.1)), (0, 0, -1), 0.9, 0.64,
                    uv_poster2, m_image, m_frame, 0.025)
    _framed_picture(b, (hx, 1.15, hz - 0.25), (0, 0, -1), 0.5, 0.7, uv_poster3, m_image,
                    m_frame, 0.02)
    _framed_picture(b, (-hx, 1.85, -hz + 1.3), (0, 0, 1), 0.32, 0.32, uv_clock, m_image, m_frame,
                    0.02)
    rug_x0, rug_z0 = tx0 - 1.0, tz0 - 0.3
    b.add_mesh(textured_quad((rug_x0, 0.004, rug_z0), (0, 0, tz1 - tz0 + 0.6), (1.9, 0, 0), 4, 4,
                             uv_rug), m_image)

    static = b.build()
    casters = {m_door, m_metal, m_shelf, m_white_furn, m_table, m_chair, m_fabric, m_books,
               m_plant, m_pot, m_radiator, m_dark}
    room = Room(
        spec=spec, static=static,
        shadow_casters=np.flatnonzero(np.isin(static.face_material, list(casters))),
        door=door, materials=tuple(materials),
        material_index=index, atlas=atlas.image, emissive={m_glass: (1.25, 1.32, 1.45)},
        lamp=(rng.uniform(-0.9, -0.4), H - 0.45, rng.uniform(-0.8, -0.3)),
        lamp_colour=(4.0, 3.9, 3.7),
        window_direction=tuple(_unit([-1.0, -0.55, rng.uniform(-0.4, 0.4)])),
        window_colour=(0.30, 0.32, 0.36),
        ambient_sky=(0.46, 0.46, 0.47), ambient_ground=(0.30, 0.29, 0.27),
        obstacles=tuple(obstacles))
    return room


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _wall_with_holes(b: MeshBuilder, origin, direction, length, height, holes, material, cell):
    """A wall rectangle (facing into the room) minus rectangular holes ``(u0, u1, v0, v1)``."""
    us = sorted({0.0, length, *[h[0] for h in holes], *[h[1] for h in holes]})
    vs = sorted({0.0, height, *[h[2] for h in holes], *[h[3] for h in holes]})
    up = np.array([0.0, 1.0, 0.0])
    for u0, u1 in zip(us[:-1], us[1:]):
        for v0, v1 in zip(vs[:-1], vs[1:]):
            um, vm = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
            if any(h[0] < um < h[1] and h[2] < vm < h[3] for h in holes):
                continue
            o = origin + direction * u0 + up * v0
            b.add_mesh(textured_quad(o, direction * (u1 - u0), up * (v1 - v0),
                                     _cells(u1 - u0, cell), _cells(v1 - v0, cell)), material)


def _framed_picture(b: MeshBuilder, corner, direction, width, height, uv_rect, m_image, m_frame,
                    frame_w):
    """A picture on a wall: ``corner`` is the wall point at the picture's lower-left edge (seen
    from the room) at its bottom height; ``direction`` runs along the wall to the right."""
    d = np.asarray(direction, float)
    inward = np.array([-d[2], 0.0, d[0]])
    base = np.asarray(corner, float)
    o = base + inward * 0.015
    b.add_mesh(textured_quad(o, d * width, (0, height, 0), 2, 2, uv_rect), m_image)
    f = frame_w
    for a0, a1, v0, v1 in ((-f, 0, -f, height + f), (width, width + f, -f, height + f),
                           (0, width, -f, 0), (0, width, height, height + f)):
        p = base + d * a0 + np.array([0, v0, 0])
        span = d * (a1 - a0)
        up = np.array([0, v1 - v0, 0])
        b.add_mesh(textured_quad(p + inward * 0.022, span, up, 1, 1), m_frame)
        # sides of the frame's thickness
        b.add_mesh(textured_quad(p, span, inward * 0.022, 1, 1), m_frame)
        b.add_mesh(textured_quad(p + up, inward * 0.022, span, 1, 1), m_frame)


def _chair(b: MeshBuilder, xz, yaw, m_chair, m_fabric, seat_colour):
    """A chair facing ``yaw`` (0 = facing +z) at floor position ``xz``."""
    x, z = xz
    leg_colour = (0.16, 0.16, 0.17)
    pivot = (x, 0.0, z)
    s = 0.22
    b.add_mesh(box_mesh((x - s, 0.44, z - s), (x + s, 0.49, z + s), cell=1, yaw=yaw, pivot=pivot),
               m_fabric, seat_colour)
    for lx, lz in ((-s + 0.02, -s + 0.02), (s - 0.05, -s + 0.02), (-s + 0.02, s - 0.05),
                   (s - 0.05, s - 0.05)):
        b.add_mesh(box_mesh((x + lx, 0, z + lz), (x + lx + 0.03, 0.44, z + lz + 0.03), cell=1,
                            yaw=yaw, pivot=pivot, skip=("-y", "+y")), m_chair, leg_colour)
    for lx in (-s + 0.02, s - 0.05):
        b.add_mesh(box_mesh((x + lx, 0.49, z - s + 0.005), (x + lx + 0.03, 0.9, z - s + 0.03),
                            cell=1, yaw=yaw, pivot=pivot), m_chair, leg_colour)
    b.add_mesh(box_mesh((x - s, 0.62, z - s - 0.005), (x + s, 0.88, z - s + 0.025), cell=1,
                        yaw=yaw, pivot=pivot), m_fabric, seat_colour)


def _bookshelf(b: MeshBuilder, rng, wall_xz, yaw, width, height, depth, m_shelf, m_books):
    """An open bookshelf standing against a wall. ``wall_xz``: the wall point behind the
    shelf's centre; ``yaw``: 0 for the north wall (shelf opening towards +z), pi/2 for the
    west wall (opening towards +x)."""
    x, z = wall_xz
    pivot = (x, 0.0, z)
    w2 = 0.5 * width
    t = 0.02
    z0 = z + 0.01
    z1 = z0 + depth

    def add(lo, hi, m, colour=None):
        b.add_mesh(box_mesh(lo, hi, cell=0.5, yaw=yaw, pivot=pivot), m, colour)

    add((x - w2, 0, z0), (x - w2 + t, height, z1), m_shelf)
    add((x + w2 - t, 0, z0), (x + w2, height, z1), m_shelf)
    add((x - w2, height - t, z0), (x + w2, height, z1), m_shelf)
    add((x - w2, 0, z0), (x + w2, 0.08, z1), m_shelf)
    add((x - w2, 0, z0), (x + w2, height, z0 + 0.01), m_shelf)
    n_shelves = 5
    levels = np.linspace(0.08, height - t, n_shelves + 1)
    for y in levels[1:-1]:
        add((x - w2 + t, y - t, z0), (x + w2 - t, y, z1), m_shelf)
    for y0, y1 in zip(levels[:-1], levels[1:]):
        bx = x - w2 + t + rng.uniform(0.0, 0.06)
        end = x + w2 - t - rng.uniform(0.0, 0.15)
        while bx < end - 0.02:
            bw = rng.uniform(0.018, 0.05)
            if rng.random() < 0.08:  # a gap
                bx += rng.uniform(0.05, 0.15)
                continue
            bh = min(rng.uniform(0.6, 0.92) * (y1 - y0 - t), y1 - y0 - t - 0.01)
            bd = rng.uniform(0.6, 0.95) * depth
            colour = np.array(_BOOK_COLOURS[int(rng.integers(len(_BOOK_COLOURS)))])
            colour = np.clip(colour * rng.uniform(0.8, 1.15), 0, 1)
            add((bx, y0, z0 + 0.01), (min(bx + bw, end), y0 + bh, z0 + 0.01 + bd), m_books,
                colour)
            bx += bw + rng.uniform(0.0, 0.004)
