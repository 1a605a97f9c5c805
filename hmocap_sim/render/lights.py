"""Scene lighting of the shaded renderer (:mod:`hmocap_sim.render.shading`): point and
directional lights, each with an optional soft shadow map (:mod:`hmocap_sim.render.shadow`),
and hemispheric ambient light.
"""

from __future__ import annotations

from dataclasses import dataclass

from hmocap_sim.render.shadow import ShadowMap

__all__ = ["DirectionalLight", "Lighting", "PointLight"]


@dataclass(frozen=True, eq=False)
class PointLight:
    """Isotropic point light at ``position``; ``colour`` is linear RGB intensity (the
    irradiance at 1 m). ``radius`` (m) softens the inverse-square falloff to
    ``1 / (d^2 + radius^2)``, like a lamp of that size (no hot spot on a nearby ceiling).
    ``shadow``: a shadow map rendered from this position, or None."""

    position: tuple
    colour: tuple = (1.0, 1.0, 1.0)
    shadow: ShadowMap | None = None
    radius: float = 0.0


@dataclass(frozen=True, eq=False)
class DirectionalLight:
    """Light travelling along ``direction`` (e.g. (0, -1, 0) from above) with linear RGB
    irradiance ``colour``; ``shadow`` from :func:`render_shadow_map` with light_direction."""

    direction: tuple
    colour: tuple = (1.0, 1.0, 1.0)
    shadow: ShadowMap | None = None


@dataclass(frozen=True, eq=False)
class Lighting:
    """Scene lighting. Ambient light is hemispheric: ``ambient_sky`` on surfaces facing up
    (+Y), ``ambient_ground`` facing down, blended by the normal. ``exposure`` scales the
    linear result before sRGB encoding. ``shadow_bias`` (m) avoids self-shadowing acne;
    ``shadow_softness_px`` is the PCF radius in shadow-map pixels, sampled with
    ``shadow_taps`` x ``shadow_taps`` taps. ``background``: sRGB colour of empty pixels."""

    lights: tuple = ()
    ambient_sky: tuple = (0.35, 0.35, 0.37)
    ambient_ground: tuple = (0.18, 0.16, 0.15)
    exposure: float = 1.0
    shadow_bias: float = 0.03
    shadow_softness_px: float = 3.0
    shadow_taps: int = 5
    background: tuple = (0.0, 0.0, 0.0)
