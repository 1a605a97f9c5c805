"""Surface materials of the shaded renderer (:mod:`hmocap_sim.render.shading`): a
:class:`Material` per surface kind, packed into the float32 table the shading kernel reads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hmocap_sim.render.textures import KINDS

__all__ = ["MATERIAL_FIELDS", "Material", "material_table"]

MATERIAL_FIELDS = 14  # kind, colour (3), colour2 (3), scale, noise, angle, vc, smooth, spec, seed


@dataclass(frozen=True)
class Material:
    """Surface appearance. ``kind``: 'plain', 'wood', 'tiles', 'plaster', 'fabric' or 'image'.

    colour / colour2: sRGB in [0, 1] (wood: light and dark tone; tiles: tile and grout;
        plaster: the two mottling tones; plain / fabric: colour2 unused; image: tint).
    scale: pattern size in metres (plank width, tile side, blotch or fold size).
    noise: relative amplitude of fine noise (plain, tiles, plaster grain, fabric folds).
    angle: rotation of the planar texture coordinates (radians), e.g. vertical grain on doors.
    vertex_colour: multiply by the interpolated per-vertex colours (clothes, skin).
    smooth: use interpolated vertex normals (curved surfaces) instead of the face normal.
    specular: strength of a Blinn-Phong highlight (0 = matte).
    seed: pattern seed, so two walls of the same material differ.
    """

    kind: str = "plain"
    colour: tuple = (0.8, 0.8, 0.8)
    colour2: tuple = (0.5, 0.5, 0.5)
    scale: float = 0.1
    noise: float = 0.0
    angle: float = 0.0
    vertex_colour: bool = False
    smooth: bool = False
    specular: float = 0.0
    seed: int = 0

    def to_row(self) -> np.ndarray:
        if self.kind not in KINDS:
            raise ValueError(f"unknown material kind {self.kind!r}; one of {sorted(KINDS)}")
        return np.array([KINDS[self.kind], *self.colour, *self.colour2, self.scale, self.noise,
                         self.angle, float(self.vertex_colour), float(self.smooth),
                         self.specular, self.seed], dtype=np.float32)


def material_table(materials) -> np.ndarray:
    """Stack :class:`Material` objects into the ``(n, MATERIAL_FIELDS)`` float32 table."""
    return np.stack([m.to_row() for m in materials]).astype(np.float32)
