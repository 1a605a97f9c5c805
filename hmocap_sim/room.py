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

Everything is meshed by :mod:`hmocap_sim.room_mesh` (finely tessellated: the rasteriser
does not clip at the near plane and lens distortion bends long edges) and carries a material
index into :attr:`Room.materials` and per-vertex coordinates into one procedural texture atlas
(:mod:`hmocap_sim.room_textures`: posters, whiteboard, clock face, rug).  The parts of the
room are small builders in :data:`hmocap_sim.room_furnishing.ROOM_PARTS`.  Window panes
are emissive: the renderer paints them with :attr:`Room.emissive` instead of shading them.

The moving parts used as distractors are described here too: :class:`Door` (hinged panel)
and :func:`ball_mesh` (a beach ball rolling on the floor). Free floor space for the person is
given by :meth:`Room.clearance`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hmocap_sim.render.shading import Material
from hmocap_sim.room_furnishing import ROOM_PARTS, Door, Furnishing
from hmocap_sim.room_mesh import (
    MeshBuilder,
    SceneMesh,
    ball_mesh,
    box_mesh,
    textured_quad,
    uv_sphere,
)
from hmocap_sim.room_textures import ATLAS_CELL_PX, ATLAS_CELLS, ATLAS_PRINTS, Atlas

__all__ = [
    "ATLAS_CELLS",
    "ATLAS_CELL_PX",
    "Door",
    "MeshBuilder",
    "Room",
    "RoomSpec",
    "SceneMesh",
    "ball_mesh",
    "box_mesh",
    "build_room",
    "textured_quad",
    "uv_sphere",
]


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

#: Materials every room shares, by name, after the drawn floor and wall paints.
_FIXED_MATERIALS = {
    "ceiling": Material("plaster", (0.93, 0.93, 0.91), (0.89, 0.89, 0.87), scale=0.6, noise=0.02,
                        seed=4),
    "trim": Material("plain", (0.93, 0.92, 0.89), noise=0.02, scale=0.05, specular=0.08),
    "door": Material("wood", (0.50, 0.31, 0.17), (0.33, 0.19, 0.09), scale=0.3, angle=math.pi / 2,
                     seed=5, specular=0.05),
    "metal": Material("plain", (0.62, 0.62, 0.64), specular=0.6),
    "corridor": Material("plaster", (0.55, 0.53, 0.50), (0.48, 0.46, 0.44), scale=0.4, noise=0.04,
                         seed=6),
    "glass": Material("plain", (0.9, 0.95, 1.0)),
    "image": Material("image", (1.0, 1.0, 1.0), specular=0.04),
    "frame": Material("plain", (0.10, 0.10, 0.10), specular=0.1),
    "shelf": Material("wood", (0.62, 0.44, 0.28), (0.45, 0.30, 0.18), scale=0.25, angle=0.0,
                      seed=7),
    "white_furniture": Material("plain", (0.88, 0.88, 0.86), noise=0.02, scale=0.1, specular=0.1),
    "table": Material("wood", (0.72, 0.55, 0.36), (0.55, 0.38, 0.22), scale=0.35, seed=8,
                      specular=0.08),
    "chair": Material("plain", (1.0, 1.0, 1.0), vertex_colour=True, specular=0.1),
    "upholstery": Material("fabric", (1.0, 1.0, 1.0), scale=0.06, noise=0.12, vertex_colour=True,
                           seed=9),
    "books": Material("plain", (1.0, 1.0, 1.0), vertex_colour=True, noise=0.03, scale=0.02),
    "plant": Material("fabric", (0.22, 0.42, 0.18), scale=0.05, noise=0.35, smooth=False, seed=10),
    "pot": Material("plain", (0.62, 0.32, 0.22), noise=0.05, scale=0.05, specular=0.1),
    "radiator": Material("plain", (0.92, 0.92, 0.90), specular=0.15),
    "dark": Material("plain", (0.12, 0.12, 0.13), specular=0.3),
}
#: Materials of the faces in the lamp's shadow map: the furniture, not the room's shell.
SHADOW_CASTERS = ("door", "metal", "shelf", "white_furniture", "table", "chair", "upholstery",
                  "books", "plant", "pot", "radiator", "dark")


def _materials(rng: np.random.Generator) -> dict:
    """The room's materials by name, in index order: floor and two wall paints drawn from
    ``rng``, then :data:`_FIXED_MATERIALS`."""
    paint_a, paint_b = (_WALL_PAINTS[i] for i in rng.choice(len(_WALL_PAINTS), 2, replace=False))
    floor = _FLOORS[int(rng.integers(len(_FLOORS)))]
    drawn = {
        "floor": Material(floor.kind, floor.colour, floor.colour2, scale=floor.scale,
                          noise=floor.noise, seed=int(rng.integers(1000))),
        "wall_a": Material("plaster", *paint_a, scale=0.45, noise=0.04, seed=2),
        "wall_b": Material("plaster", *paint_b, scale=0.45, noise=0.04, seed=3),
    }
    return {**drawn, **_FIXED_MATERIALS}


def build_room(rng: np.random.Generator, spec: RoomSpec = RoomSpec()) -> Room:
    """A seeded variation of the furnished room (layout in the module docstring).

    Colours, floor type, poster prints, book sizes and small placement offsets come from
    ``rng``; the layout itself is fixed, so that the person's floor area is always free.
    Materials, atlas prints (:data:`~hmocap_sim.room_textures.ATLAS_PRINTS`), the parts
    (:data:`~hmocap_sim.room_furnishing.ROOM_PARTS`) and the lights draw from ``rng`` in
    that order.
    """
    named = _materials(rng)
    index = {name: i for i, name in enumerate(named)}
    atlas = Atlas()
    uv = {name: atlas.add(draw(rng)) for name, draw in ATLAS_PRINTS.items()}
    room = Furnishing(spec, rng, MeshBuilder(), index, uv)
    for build_part in ROOM_PARTS.values():
        build_part(room)
    static = room.mesh.build()
    casters = [index[name] for name in SHADOW_CASTERS]
    return Room(
        spec=spec, static=static,
        shadow_casters=np.flatnonzero(np.isin(static.face_material, casters)),
        door=room.door, materials=tuple(named.values()),
        material_index=index, atlas=atlas.image, emissive={index["glass"]: (1.25, 1.32, 1.45)},
        lamp=(rng.uniform(-0.9, -0.4), spec.height - 0.45, rng.uniform(-0.8, -0.3)),
        lamp_colour=(4.0, 3.9, 3.7),
        window_direction=tuple(_unit([-1.0, -0.55, rng.uniform(-0.4, 0.4)])),
        window_colour=(0.30, 0.32, 0.36),
        ambient_sky=(0.46, 0.46, 0.47), ambient_ground=(0.30, 0.29, 0.27),
        obstacles=tuple(room.obstacles))


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)
