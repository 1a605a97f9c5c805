"""The parts of the furnished room, one small builder each, in :data:`ROOM_PARTS`.

:func:`hmocap_sim.room.build_room` runs the builders in the registry's order, which is
also the order of their random draws and of their faces in the static mesh.  A builder
takes the :class:`Furnishing` under construction (mesh, materials, atlas rectangles,
furniture footprints and the positions that later parts build on) and adds its triangles;
the door builder also makes the movable :class:`Door`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hmocap_sim.room_mesh import (
    MeshBuilder,
    SceneMesh,
    box_mesh,
    cells_along,
    cone_mesh,
    textured_quad,
    turn_yaw,
    uv_sphere,
)
from hmocap_sim.room_pieces import bookshelf, chair, framed_picture, wall_with_holes

DOOR_WIDTH, DOOR_HEIGHT = 0.92, 2.05
WINDOW_WIDTH, WINDOW_SILL, WINDOW_TOP = 1.5, 0.9, 2.2
WALL_THICKNESS = 0.12  # depth of the door and window reveals
_SEAT_COLOURS = [(0.15, 0.25, 0.45), (0.45, 0.12, 0.12), (0.25, 0.25, 0.27), (0.20, 0.38, 0.30)]


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
        return turn_yaw(self.mesh.vertices, self.swing_sign * angle,
                        (self.hinge[0], 0.0, self.hinge[1]))


@dataclass(eq=False)
class Furnishing:
    """The room under construction, handed from one part builder to the next.

    ``spec`` is a :class:`hmocap_sim.room.RoomSpec`; ``material`` maps material names to
    indices, ``uv`` atlas print names (:data:`hmocap_sim.room_textures.ATLAS_PRINTS`) to
    uv rectangles; ``obstacles`` collects floor footprints ``(x0, z0, x1, z1)``.
    """

    spec: object
    rng: np.random.Generator
    mesh: MeshBuilder
    material: dict
    uv: dict
    obstacles: list = field(default_factory=list)
    door_u0: float = 0.0  # door opening along the north wall, from x = -half_x
    window_u0: float = 0.0  # window opening along the east wall, from z = -half_z
    door: Door | None = None
    table: tuple = ()  # (x0, z0, x1, z1) of the table top
    sideboard_x0: float = 0.0


def _floor_and_ceiling(f: Furnishing) -> None:
    hx, hz, H, cell = f.spec.half_x, f.spec.half_z, f.spec.height, f.spec.cell
    f.mesh.add_mesh(textured_quad((-hx, 0, -hz), (0, 0, 2 * hz), (2 * hx, 0, 0),
                                  cells_along(2 * hz, cell), cells_along(2 * hx, cell)),
                    f.material["floor"])
    f.mesh.add_mesh(textured_quad((-hx, H, -hz), (2 * hx, 0, 0), (0, 0, 2 * hz),
                                  cells_along(2 * hx, cell), cells_along(2 * hz, cell)),
                    f.material["ceiling"])


def _walls(f: Furnishing) -> None:
    """The four walls with the door and window openings (placed here), and skirting boards
    8 cm high and 1.5 cm proud, interrupted by the door."""
    hx, hz, H, cell = f.spec.half_x, f.spec.half_z, f.spec.height, f.spec.cell
    f.door_u0 = 1.15 + f.rng.uniform(-0.1, 0.1)
    f.window_u0 = 1.35 + f.rng.uniform(-0.15, 0.15)
    m_wall_a, m_wall_b = f.material["wall_a"], f.material["wall_b"]
    # (origin, unit direction along the wall, length, material, holes (u0, u1, v0, v1))
    walls = {
        "north": ((-hx, 0, -hz), (1, 0, 0), 2 * hx, m_wall_a,
                  [(f.door_u0, f.door_u0 + DOOR_WIDTH, 0, DOOR_HEIGHT)]),
        "east": ((hx, 0, -hz), (0, 0, 1), 2 * hz, m_wall_b,
                 [(f.window_u0, f.window_u0 + WINDOW_WIDTH, WINDOW_SILL, WINDOW_TOP)]),
        "south": ((hx, 0, hz), (-1, 0, 0), 2 * hx, m_wall_a, []),
        "west": ((-hx, 0, hz), (0, 0, -1), 2 * hz, m_wall_b, []),
    }
    for origin, direction, length, m, holes in walls.values():
        origin = np.asarray(origin, float)
        direction = np.asarray(direction, float)
        wall_with_holes(f.mesh, origin, direction, length, H, holes, m, cell)
        spans = [(0.0, length)]
        for u0, u1, v0, _ in holes:
            if v0 == 0:
                spans = [(a, min(c, u0)) for a, c in spans if a < u0] + \
                        [(max(a, u1), c) for a, c in spans if c > u1]
        _skirting(f, origin, direction, spans)


def _skirting(f: Furnishing, origin, direction, spans) -> None:
    """Skirting board along ``spans`` ``(u0, u1)`` of a wall: its front and its top."""
    cell, m_trim = f.spec.cell, f.material["trim"]
    inward = np.array([-direction[2], 0.0, direction[0]])  # into the room
    for a, c in spans:
        if c - a < 0.02:
            continue
        p0 = np.asarray(origin) + direction * a
        f.mesh.add_mesh(textured_quad(p0 + inward * 0.015, direction * (c - a), (0, 0.08, 0),
                                      cells_along(c - a, cell), 1), m_trim)
        f.mesh.add_mesh(textured_quad(p0 + inward * 0.015 + [0, 0.08, 0], direction * (c - a),
                                      -inward * 0.015, cells_along(c - a, cell), 1), m_trim)


def _door(f: Furnishing) -> None:
    """The north wall's door opening: reveal, architrave, a dim corridor behind it, and the
    movable door panel (:attr:`Furnishing.door`) with its handle."""
    hx, hz, H = f.spec.half_x, f.spec.half_z, f.spec.height
    b, m = f.mesh, f.material
    door_w, door_h, wall_t = DOOR_WIDTH, DOOR_HEIGHT, WALL_THICKNESS
    n_origin = np.array([-hx, 0.0, -hz])
    dx0 = n_origin[0] + f.door_u0
    dx1 = dx0 + door_w
    zw = -hz
    b.add_mesh(textured_quad((dx0, 0, zw), (0, 0, -wall_t), (0, door_h, 0), 1, 8), m["wall_a"])
    b.add_mesh(textured_quad((dx1, 0, zw - wall_t), (0, 0, wall_t), (0, door_h, 0), 1, 8),
               m["wall_a"])
    b.add_mesh(textured_quad((dx0, door_h, zw), (door_w, 0, 0), (0, 0, -wall_t), 4, 1),
               m["wall_a"])
    # architrave: three trim strips 7 cm wide, 2 cm proud
    for lo, hi in (((dx0 - 0.07, 0, zw), (dx0, door_h + 0.07, zw + 0.02)),
                   ((dx1, 0, zw), (dx1 + 0.07, door_h + 0.07, zw + 0.02)),
                   ((dx0, door_h, zw), (dx1, door_h + 0.07, zw + 0.02))):
        b.add_mesh(box_mesh(lo, hi, cell=0.5, skip=("-z",)), m["trim"])
    cz = zw - wall_t
    depth = 1.6
    b.add_mesh(textured_quad((dx0 - 0.6, 0, cz - depth), (0, 0, depth), (door_w + 1.2, 0, 0),
                             6, 8), m["floor"])
    b.add_mesh(textured_quad((dx0 - 0.6, 0, cz - depth), (door_w + 1.2, 0, 0), (0, H, 0), 8, 10),
               m["corridor"])
    b.add_mesh(textured_quad((dx0 - 0.6, 0, cz), (0, 0, -depth), (0, H, 0), 6, 10), m["corridor"])
    b.add_mesh(textured_quad((dx1 + 0.6, 0, cz - depth), (0, 0, depth), (0, H, 0), 6, 10),
               m["corridor"])
    b.add_mesh(textured_quad((dx0 - 0.6, H, cz), (door_w + 1.2, 0, 0), (0, 0, -depth), 8, 6),
               m["corridor"])
    # the panel is hinged at dx0, 4 cm thick, flush with the room side of the wall
    door_builder = MeshBuilder()
    panel_lo = (dx0 + 0.005, 0.01, zw - 0.045)
    panel_hi = (dx1 - 0.005, door_h - 0.005, zw - 0.005)
    door_builder.add_mesh(box_mesh(panel_lo, panel_hi, cell=0.35), m["door"])
    handle_x = dx1 - 0.09
    door_builder.add_mesh(box_mesh((handle_x - 0.02, 1.02, zw - 0.005),
                                   (handle_x + 0.02, 1.06, zw + 0.045), cell=1), m["metal"])
    door_builder.add_mesh(box_mesh((handle_x - 0.13, 1.025, zw + 0.045),
                                   (handle_x + 0.02, 1.055, zw + 0.065), cell=1), m["metal"])
    f.door = Door(door_builder.build(), hinge=(dx0 + 0.005, zw - 0.005), swing_sign=-1.0)
    f.obstacles.append((dx0, -hz, dx1, -hz + door_w))  # where the door swings


def _window_extent(f: Furnishing) -> tuple:
    """(z0, z1, z of the mullion) of the east wall's window."""
    e_z0 = -f.spec.half_z + f.window_u0
    e_z1 = e_z0 + WINDOW_WIDTH
    return e_z0, e_z1, 0.5 * (e_z0 + e_z1)


def _window(f: Furnishing) -> None:
    """The east wall's window: reveal, emissive glass, frame with mullion and transom, sill."""
    b, m = f.mesh, f.material
    win_w, win_sill, win_top, wall_t = WINDOW_WIDTH, WINDOW_SILL, WINDOW_TOP, WALL_THICKNESS
    e_z0, e_z1, zm = _window_extent(f)
    xw = f.spec.half_x
    b.add_mesh(textured_quad((xw, win_sill, e_z0), (wall_t, 0, 0), (0, win_top - win_sill, 0),
                             1, 5), m["wall_b"])
    b.add_mesh(textured_quad((xw + wall_t, win_sill, e_z1), (-wall_t, 0, 0),
                             (0, win_top - win_sill, 0), 1, 5), m["wall_b"])
    b.add_mesh(textured_quad((xw, win_top, e_z0), (0, 0, win_w), (wall_t, 0, 0), 6, 1), m["wall_b"])
    b.add_mesh(textured_quad((xw + wall_t, win_sill, e_z0), (-wall_t, 0, 0), (0, 0, win_w), 1, 6),
               m["trim"])
    gx = xw + 0.08
    b.add_mesh(textured_quad((gx, win_sill, e_z0), (0, 0, win_w), (0, win_top - win_sill, 0),
                             6, 5), m["glass"])
    fw = 0.06
    ym = win_sill + 0.62 * (win_top - win_sill)
    for lo, hi in (((gx - 0.05, win_sill, e_z0), (gx, win_top, e_z0 + fw)),
                   ((gx - 0.05, win_sill, e_z1 - fw), (gx, win_top, e_z1)),
                   ((gx - 0.05, win_sill, e_z0), (gx, win_sill + fw, e_z1)),
                   ((gx - 0.05, win_top - fw, e_z0), (gx, win_top, e_z1)),
                   ((gx - 0.05, win_sill, zm - 0.03), (gx, win_top, zm + 0.03)),
                   ((gx - 0.05, ym - 0.03, e_z0), (gx, ym + 0.03, e_z1))):
        b.add_mesh(box_mesh(lo, hi, cell=0.5, skip=("+x",)), m["trim"])
    b.add_mesh(box_mesh((xw - 0.06, win_sill - 0.04, e_z0 - 0.06), (xw + 0.02, win_sill,
                                                                    e_z1 + 0.06), cell=0.5),
               m["trim"])


def _radiator(f: Furnishing) -> None:
    """A finned radiator under the window."""
    xw, m_radiator = f.spec.half_x, f.material["radiator"]
    _, _, zm = _window_extent(f)
    r_z0, r_z1 = zm - 0.55, zm + 0.55
    f.mesh.add_mesh(box_mesh((xw - 0.09, 0.15, r_z0), (xw - 0.03, 0.72, r_z1), cell=0.5,
                             skip=("+x",)), m_radiator)
    for z in np.arange(r_z0 + 0.03, r_z1 - 0.02, 0.05):
        f.mesh.add_mesh(box_mesh((xw - 0.11, 0.17, z - 0.008), (xw - 0.09, 0.70, z + 0.008),
                                 cell=1, skip=("+x", "-y")), m_radiator)


def _table(f: Furnishing) -> None:
    """A table by the east wall, south of the window, with an open laptop and a mug."""
    hx, hz, b, m = f.spec.half_x, f.spec.half_z, f.mesh, f.material
    tx0, tx1 = hx - 0.95, hx - 0.15
    tz0 = hz - 1.85 + f.rng.uniform(-0.1, 0.1)
    tz1 = tz0 + 1.4
    top_y = 0.74
    f.table = (tx0, tz0, tx1, tz1)
    b.add_mesh(box_mesh((tx0, top_y, tz0), (tx1, top_y + 0.035, tz1), cell=0.5), m["table"])
    for lx, lz in ((tx0 + 0.04, tz0 + 0.04), (tx1 - 0.08, tz0 + 0.04), (tx0 + 0.04, tz1 - 0.08),
                   (tx1 - 0.08, tz1 - 0.08)):
        b.add_mesh(box_mesh((lx, 0, lz), (lx + 0.045, top_y, lz + 0.045), cell=0.5,
                            skip=("-y", "+y")), m["table"])
    f.obstacles.append((tx0, tz0, tx1, tz1))
    lap_x, lap_z = tx0 + 0.35, tz0 + 0.45
    b.add_mesh(box_mesh((lap_x - 0.16, top_y + 0.035, lap_z - 0.12),
                        (lap_x + 0.16, top_y + 0.05, lap_z + 0.12), cell=1), m["dark"])
    lid = box_mesh((lap_x - 0.16, top_y + 0.05, lap_z - 0.12),
                   (lap_x + 0.16, top_y + 0.065, lap_z + 0.12), cell=1)
    # tilt the lid up about its hinge edge (towards +x, facing the room)
    lv = lid[0] - [lap_x + 0.16, top_y + 0.05, 0]
    a = math.radians(-105.0)
    rot = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    b.add(lv @ rot.T + [lap_x + 0.16, top_y + 0.05, 0], lid[1], m["dark"])
    b.add_mesh(cone_mesh((tx0 + 0.3, top_y + 0.035, tz1 - 0.3), 0.04, 0.045, 0.1, 12), m["pot"])


def _chairs(f: Furnishing) -> None:
    """Two chairs at the table's room side, upholstered in one random colour."""
    tx0, tz0, _, tz1 = f.table
    rng = f.rng
    seat_colour = _SEAT_COLOURS[int(rng.integers(4))]
    for cz_, yaw in ((tz0 + 0.35, math.pi / 2 + rng.uniform(-0.25, 0.25)),
                     (tz1 - 0.35, math.pi / 2 + rng.uniform(-0.25, 0.25))):
        cx_ = tx0 - 0.25 + rng.uniform(-0.05, 0.1)
        chair(f.mesh, (cx_, cz_), yaw, f.material["chair"], f.material["upholstery"], seat_colour)
        f.obstacles.append((cx_ - 0.3, cz_ - 0.3, cx_ + 0.3, cz_ + 0.3))


def _bookshelves(f: Furnishing) -> None:
    """A wooden bookshelf on the north wall's east part, a white one on the west wall."""
    hx, hz, rng, m = f.spec.half_x, f.spec.half_z, f.rng, f.material
    bookshelf(f.mesh, rng, (hx - 1.45 + rng.uniform(-0.2, 0.1), -hz), 0.0, 0.9, 1.95, 0.34,
               m["shelf"], m["books"])
    f.obstacles.append((hx - 1.7, -hz, hx - 0.4, -hz + 0.4))
    wz = -0.2 + rng.uniform(-0.15, 0.15)
    bookshelf(f.mesh, rng, (-hx, wz), math.pi / 2, 1.0, 1.8, 0.32, m["white_furniture"],
               m["books"])
    f.obstacles.append((-hx, wz - 0.6, -hx + 0.4, wz + 0.6))


def _sideboard(f: Furnishing) -> None:
    """A low white sideboard on a dark plinth, with door gaps, by the south wall."""
    hz, b, m = f.spec.half_z, f.mesh, f.material
    sb_x0 = -1.6 + f.rng.uniform(-0.2, 0.2)
    f.sideboard_x0 = sb_x0
    b.add_mesh(box_mesh((sb_x0, 0.08, hz - 0.45), (sb_x0 + 1.6, 0.8, hz - 0.01), cell=0.5),
               m["white_furniture"])
    b.add_mesh(box_mesh((sb_x0 + 0.05, 0, hz - 0.4), (sb_x0 + 1.55, 0.08, hz - 0.06), cell=0.5,
                        skip=("-y",)), m["dark"])
    for k in range(1, 4):
        x = sb_x0 + 0.4 * k
        b.add_mesh(box_mesh((x - 0.004, 0.1, hz - 0.455), (x + 0.004, 0.78, hz - 0.45), cell=1),
                   m["dark"])
    f.obstacles.append((sb_x0, hz - 0.45, sb_x0 + 1.6, hz))


def _plant(f: Furnishing) -> None:
    """A potted plant (a pot and a bush of ellipsoids) in the south-west corner."""
    hx, hz, rng = f.spec.half_x, f.spec.half_z, f.rng
    px_, pz_ = -hx + 0.35, hz - 0.35
    f.mesh.add_mesh(cone_mesh((px_, 0.0, pz_), 0.15, 0.2, 0.42, 16), f.material["pot"])
    for _ in range(7):
        ang = rng.uniform(0, 2 * math.pi)
        r = rng.uniform(0.0, 0.16)
        centre = (px_ + r * math.sin(ang), 0.55 + rng.uniform(0.0, 0.7), pz_ + r * math.cos(ang))
        f.mesh.add_mesh(uv_sphere(centre, (rng.uniform(0.14, 0.22), rng.uniform(0.16, 0.28),
                                           rng.uniform(0.14, 0.22)), 6, 9), f.material["plant"])
    f.obstacles.append((px_ - 0.3, pz_ - 0.3, hx, hz))


def _whiteboard(f: Furnishing) -> None:
    """A whiteboard in a metal frame on the south wall, above the sideboard."""
    bw, bh = 1.5, 1.0
    bx0 = f.sideboard_x0 + 0.05
    framed_picture(f.mesh, (bx0 + bw, 1.0, f.spec.half_z), (-1, 0, 0), bw, bh, f.uv["whiteboard"],
                    f.material["image"], f.material["metal"], 0.025)


def _pictures(f: Furnishing) -> None:
    """Three framed posters (north, west and east walls) and the clock on the west wall."""
    hx, hz, rng, uv = f.spec.half_x, f.spec.half_z, f.rng, f.uv
    m_image, m_frame = f.material["image"], f.material["frame"]
    framed_picture(f.mesh, (-hx + 3.3 + rng.uniform(-0.2, 0.2), 1.25, -hz), (1, 0, 0), 0.55, 0.75,
                    uv["poster1"], m_image, m_frame, 0.02)
    framed_picture(f.mesh, (-hx, 1.2, hz - 0.6 + rng.uniform(-0.1, 0.1)), (0, 0, -1), 0.9, 0.64,
                    uv["poster2"], m_image, m_frame, 0.025)
    framed_picture(f.mesh, (hx, 1.15, hz - 0.25), (0, 0, -1), 0.5, 0.7, uv["poster3"], m_image,
                    m_frame, 0.02)
    framed_picture(f.mesh, (-hx, 1.85, -hz + 1.3), (0, 0, 1), 0.32, 0.32, uv["clock"], m_image,
                    m_frame, 0.02)


def _rug(f: Furnishing) -> None:
    """A patterned rug on the floor in front of the table."""
    tx0, tz0, _, tz1 = f.table
    rug_x0, rug_z0 = tx0 - 1.0, tz0 - 0.3
    f.mesh.add_mesh(textured_quad((rug_x0, 0.004, rug_z0), (0, 0, tz1 - tz0 + 0.6), (1.9, 0, 0),
                                  4, 4, f.uv["rug"]), f.material["image"])


#: The room's parts in build order: name -> builder(furnishing).  Later parts read what
#: earlier ones placed (the openings of the walls, the table, the sideboard).
ROOM_PARTS = {
    "floor_and_ceiling": _floor_and_ceiling,
    "walls": _walls,
    "door": _door,
    "window": _window,
    "radiator": _radiator,
    "table": _table,
    "chairs": _chairs,
    "bookshelves": _bookshelves,
    "sideboard": _sideboard,
    "plant": _plant,
    "whiteboard": _whiteboard,
    "pictures": _pictures,
    "rug": _rug,
}
