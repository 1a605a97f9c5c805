"""Shadow maps: depth of the occluders seen from a light, and soft (PCF) visibility lookups.

Render the occluders (typically only the person, so the room does not shadow itself) from the
light with :func:`render_shadow_map`; the shader then tests each lit point against that depth
(percentage-closer filtering over a small grid for a soft edge, like the wide penumbra of
ceiling lights in the reference frames).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from hmocap_ros.geometry.pinhole_camera import look_at_pose
from hmocap_sim.render.rasterize import rasterize


@dataclass(frozen=True, eq=False)
class ShadowMap:
    """Depth seen from a light: ``depth (h, w)`` float32 (inf = nothing), the light's
    world -> light ``R (3, 3)``, ``t (3,)`` and ``K (3, 3)``; ``orthographic`` for directional
    lights (then ``u = K[0,0] x + K[0,2]``, in pixels per metre)."""

    depth: np.ndarray
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    orthographic: bool


def _up_for(direction):
    direction = np.asarray(direction, dtype=np.float64)
    vertical = abs(direction[1]) > 0.9 * np.linalg.norm(direction)
    return (0.0, 0.0, 1.0) if vertical else (0.0, 1.0, 0.0)


def render_shadow_map(vertices: np.ndarray, faces: np.ndarray, *, light_position=None,
                      light_direction=None, size: int = 512, margin: float = 1.15) -> ShadowMap:
    """Render the depth of occluders ``(vertices (V, 3), faces (F, 3))`` from a point light at
    ``light_position`` (perspective) or a directional light travelling along
    ``light_direction`` (orthographic). The map is fitted to the occluders' bounding sphere
    (times ``margin``), so its resolution is spent on them."""
    v = np.asarray(vertices, dtype=np.float64)
    centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
    radius = float(np.linalg.norm(v - centre, axis=1).max()) * margin
    half = 0.5 * (size - 1)
    if light_position is not None:
        eye = np.asarray(light_position, dtype=np.float64)
        distance = float(np.linalg.norm(centre - eye))
        if distance <= radius:
            raise ValueError("the point light is inside the occluders' bounding sphere")
        R, t = look_at_pose(eye, centre, _up_for(centre - eye))
        focal = 0.5 * size / math.tan(math.asin(radius / distance))
        K = np.array([[focal, 0.0, half], [0.0, focal, half], [0.0, 0.0, 1.0]])
        xc = v @ R.T + t
        uv = xc[:, :2] / xc[:, 2:3] * focal + half
        orthographic = False
    elif light_direction is not None:
        d = np.asarray(light_direction, dtype=np.float64)
        d = d / np.linalg.norm(d)
        R, t = look_at_pose(centre - 4.0 * radius * d, centre, _up_for(d))
        scale = 0.5 * size / radius
        K = np.array([[scale, 0.0, half], [0.0, scale, half], [0.0, 0.0, 1.0]])
        xc = v @ R.T + t
        uv = xc[:, :2] * scale + half
        orthographic = True
    else:
        raise ValueError("give light_position or light_direction")
    depth, _, _ = rasterize(uv, xc[:, 2], faces, size, size, perspective=not orthographic,
                            with_barycentrics=False)
    return ShadowMap(depth=depth, K=K, R=R, t=t, orthographic=orthographic)


@nb.njit(cache=True, nogil=True)
def shadow_visibility(px, py, pz, depth, K, R, t, orthographic, bias, radius_px, taps):
    """Fraction in [0, 1] of a ``taps x taps`` PCF grid (spanning +-``radius_px`` map pixels)
    that sees world point ``(px, py, pz)`` lit; points outside the map are lit."""
    xl = R[0, 0] * px + R[0, 1] * py + R[0, 2] * pz + t[0]
    yl = R[1, 0] * px + R[1, 1] * py + R[1, 2] * pz + t[1]
    zl = R[2, 0] * px + R[2, 1] * py + R[2, 2] * pz + t[2]
    if orthographic:
        u = K[0, 0] * xl + K[0, 2]
        v = K[1, 1] * yl + K[1, 2]
    else:
        if zl <= 0.0:
            return 1.0
        u = K[0, 0] * xl / zl + K[0, 2]
        v = K[1, 1] * yl / zl + K[1, 2]
    h = depth.shape[0]
    w = depth.shape[1]
    if u < -radius_px - 1 or v < -radius_px - 1 or u > w + radius_px or v > h + radius_px:
        return 1.0
    zt = zl - bias
    # Probe a coarse 3 x 3 grid first: most points are fully lit or fully shadowed (features
    # smaller than half the filter width can be missed there, an accepted approximation).
    lit_probe = 0
    for a in range(3):
        for b in range(3):
            iu = int(math.floor(u + (a - 1) * radius_px + 0.5))
            iv = int(math.floor(v + (b - 1) * radius_px + 0.5))
            if iu < 0 or iv < 0 or iu >= w or iv >= h or not (depth[iv, iu] < zt):
                lit_probe += 1
    if lit_probe == 9:
        return 1.0
    if lit_probe == 0:
        return 0.0
    lit = 0
    step = 2.0 * radius_px / (taps - 1) if taps > 1 else 0.0
    for a in range(taps):
        for b in range(taps):
            iu = int(math.floor(u - radius_px + a * step + 0.5))
            iv = int(math.floor(v - radius_px + b * step + 0.5))
            if iu < 0 or iv < 0 or iu >= w or iv >= h or not (depth[iv, iu] < zt):
                lit += 1
    return lit / (taps * taps)
