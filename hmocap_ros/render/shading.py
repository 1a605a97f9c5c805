"""Per-pixel shading of a rasterised scene into an 8-bit RGB image.

Input is the z-buffer rasteriser's output (:func:`hmocap_ros.render.rasterize.rasterize`) for the
concatenated scene, plus the scene's world-space vertices and per-face material indices. Per
pixel: the world position and normal are interpolated with the perspective-correct
barycentrics; the albedo comes from the face's :class:`Material` (procedural texture on the
world position, optionally times per-vertex / per-face colours, or an image atlas with
per-vertex UVs); light is a hemispheric ambient term plus Lambert (and optional Blinn-Phong
highlight) from point and directional lights, each optionally attenuated by a soft shadow map
(:mod:`hmocap_ros.render.shadow`). Shading runs in linear light; the output is sRGB uint8.
Sensor noise, illumination changes and anti-aliasing are in :mod:`hmocap_ros.render.sensor`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from hmocap_ros.render.meshes import face_normals
from hmocap_ros.render.shadow import ShadowMap, shadow_visibility
from hmocap_ros.render.textures import (KIND_FABRIC, KIND_IMAGE, KIND_PLASTER, KIND_TILES,
                                        KIND_WOOD, KINDS, atlas_bilinear, fabric, fbm3, plaster,
                                        tiles, wood_planks)

MATERIAL_FIELDS = 14  # kind, colour (3), colour2 (3), scale, noise, angle, vc, smooth, spec, seed

GAMMA = 2.2
# Look-up tables instead of a pow() per channel and pixel (half the shading time otherwise):
# sRGB-ish value -> linear on [0, 2] (textures may exceed 1), and linear -> uint8 indexed by
# sqrt(linear), which keeps the steep dark end of the curve finely sampled.
_TO_LINEAR_MAX = 2.0
_TO_LINEAR = (np.linspace(0.0, _TO_LINEAR_MAX, 2049) ** GAMMA).astype(np.float64)
_ENCODE = np.rint(np.linspace(0.0, 1.0, 4097) ** (2.0 / GAMMA) * 255.0).astype(np.uint8)


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


@nb.njit(cache=True, nogil=True)
def _to_linear(c, lut):
    if not c > 0.0:
        return 0.0
    x = min(c, _TO_LINEAR_MAX) * ((lut.shape[0] - 1) / _TO_LINEAR_MAX)
    i = min(int(x), lut.shape[0] - 2)
    f = x - i
    return lut[i] + f * (lut[i + 1] - lut[i])


@nb.njit(cache=True, nogil=True)
def _encode(v, lut):
    if not v > 0.0:
        return lut[0]
    if v >= 1.0:
        return lut[lut.shape[0] - 1]
    return lut[int(math.sqrt(v) * (lut.shape[0] - 1) + 0.5)]


@nb.njit(cache=True, nogil=True)
def _albedo(mat, px, py, pz, gnx, gny, gnz, s_uv, t_uv, atlas, has_uv):
    kind = int(mat[0])
    r1 = np.float64(mat[1])
    g1 = np.float64(mat[2])
    b1 = np.float64(mat[3])
    r2 = np.float64(mat[4])
    g2 = np.float64(mat[5])
    b2 = np.float64(mat[6])
    scale = max(np.float64(mat[7]), 1e-6)
    amp = np.float64(mat[8])
    angle = np.float64(mat[9])
    seed = np.int64(mat[13])
    # Planar texture coordinates on the plane of the face's dominant axis.
    ax = abs(gnx)
    ay = abs(gny)
    az = abs(gnz)
    if ay >= ax and ay >= az:
        u0 = px
        v0 = pz
    elif ax >= az:
        u0 = pz
        v0 = py
    else:
        u0 = px
        v0 = py
    ca = math.cos(angle)
    sa = math.sin(angle)
    u = ca * u0 + sa * v0
    v = -sa * u0 + ca * v0
    if kind == KIND_WOOD:
        return wood_planks(u, v, r1, g1, b1, r2, g2, b2, scale, seed)
    if kind == KIND_TILES:
        return tiles(u, v, r1, g1, b1, r2, g2, b2, scale, amp, seed)
    if kind == KIND_PLASTER:
        return plaster(u, v, r1, g1, b1, r2, g2, b2, scale, amp, seed)
    if kind == KIND_FABRIC:
        return fabric(px, py, pz, u, v, r1, g1, b1, scale, amp, seed)
    if kind == KIND_IMAGE and has_uv:
        ar, ag, ab = atlas_bilinear(atlas, s_uv, t_uv)
        return np.float64(ar) * r1, np.float64(ag) * g1, np.float64(ab) * b1
    if amp > 0.0:
        k = 1.0 + amp * 2.0 * (fbm3(px / scale, py / scale, pz / scale, 3, seed) - 0.5)
        return r1 * k, g1 * k, b1 * k
    return r1, g1, b1


@nb.njit(cache=True, nogil=True, parallel=True)
def _shade_kernel(face_id, bary, vertices, faces, fnormals, vnormals, vcolours, fcolours, vuv,
                  atlas, face_material, materials, cam, lights, sm_depth, sm_K, sm_R, sm_t,
                  sm_ortho, amb_sky, amb_ground, exposure, bias, softness, taps, background,
                  lut_linear, lut_encode, out):
    height = face_id.shape[0]
    width = face_id.shape[1]
    has_vn = vnormals.shape[0] > 0
    has_vc = vcolours.shape[0] > 0
    has_fc = fcolours.shape[0] > 0
    has_uv = vuv.shape[0] > 0
    bg0 = np.uint8(min(max(background[0], 0.0), 1.0) * 255.0 + 0.5)
    bg1 = np.uint8(min(max(background[1], 0.0), 1.0) * 255.0 + 0.5)
    bg2 = np.uint8(min(max(background[2], 0.0), 1.0) * 255.0 + 0.5)
    for y in nb.prange(height):
        for x in range(width):
            f = face_id[y, x]
            if f < 0:
                out[y, x, 0] = bg0
                out[y, x, 1] = bg1
                out[y, x, 2] = bg2
                continue
            w0 = np.float64(bary[y, x, 0])
            w1 = np.float64(bary[y, x, 1])
            w2 = np.float64(bary[y, x, 2])
            i0 = faces[f, 0]
            i1 = faces[f, 1]
            i2 = faces[f, 2]
            px = w0 * vertices[i0, 0] + w1 * vertices[i1, 0] + w2 * vertices[i2, 0]
            py = w0 * vertices[i0, 1] + w1 * vertices[i1, 1] + w2 * vertices[i2, 1]
            pz = w0 * vertices[i0, 2] + w1 * vertices[i1, 2] + w2 * vertices[i2, 2]
            mat = materials[face_material[f]]
            gnx = np.float64(fnormals[f, 0])
            gny = np.float64(fnormals[f, 1])
            gnz = np.float64(fnormals[f, 2])
            if mat[11] > 0.5 and has_vn:
                nx = w0 * vnormals[i0, 0] + w1 * vnormals[i1, 0] + w2 * vnormals[i2, 0]
                ny = w0 * vnormals[i0, 1] + w1 * vnormals[i1, 1] + w2 * vnormals[i2, 1]
                nz = w0 * vnormals[i0, 2] + w1 * vnormals[i1, 2] + w2 * vnormals[i2, 2]
                norm = math.sqrt(nx * nx + ny * ny + nz * nz)
                if norm > 0.0:
                    nx /= norm
                    ny /= norm
                    nz /= norm
                else:
                    nx = gnx
                    ny = gny
                    nz = gnz
            else:
                nx = gnx
                ny = gny
                nz = gnz
            vx = cam[0] - px
            vy = cam[1] - py
            vz = cam[2] - pz
            vlen = math.sqrt(vx * vx + vy * vy + vz * vz)
            vx /= vlen
            vy /= vlen
            vz /= vlen
            # Two-sided: light the side the camera sees.
            if gnx * vx + gny * vy + gnz * vz < 0.0:
                gnx = -gnx
                gny = -gny
                gnz = -gnz
            if nx * gnx + ny * gny + nz * gnz < 0.0:
                nx = -nx
                ny = -ny
                nz = -nz
            s_uv = 0.0
            t_uv = 0.0
            if has_uv:
                s_uv = w0 * vuv[i0, 0] + w1 * vuv[i1, 0] + w2 * vuv[i2, 0]
                t_uv = w0 * vuv[i0, 1] + w1 * vuv[i1, 1] + w2 * vuv[i2, 1]
            ar, ag, ab = _albedo(mat, px, py, pz, gnx, gny, gnz, s_uv, t_uv, atlas, has_uv)
            if mat[10] > 0.5 and has_vc:
                ar *= w0 * vcolours[i0, 0] + w1 * vcolours[i1, 0] + w2 * vcolours[i2, 0]
                ag *= w0 * vcolours[i0, 1] + w1 * vcolours[i1, 1] + w2 * vcolours[i2, 1]
                ab *= w0 * vcolours[i0, 2] + w1 * vcolours[i1, 2] + w2 * vcolours[i2, 2]
            if has_fc:
                ar *= fcolours[f, 0]
                ag *= fcolours[f, 1]
                ab *= fcolours[f, 2]
            ar = _to_linear(ar, lut_linear)
            ag = _to_linear(ag, lut_linear)
            ab = _to_linear(ab, lut_linear)
            h = 0.5 + 0.5 * ny
            lr = amb_ground[0] + h * (amb_sky[0] - amb_ground[0])
            lg = amb_ground[1] + h * (amb_sky[1] - amb_ground[1])
            lb = amb_ground[2] + h * (amb_sky[2] - amb_ground[2])
            sr = 0.0
            sg = 0.0
            sb = 0.0
            spec = mat[12]
            for k in range(lights.shape[0]):
                if lights[k, 0] < 0.5:  # directional: xyz is the travel direction
                    lx = -lights[k, 1]
                    ly = -lights[k, 2]
                    lz = -lights[k, 3]
                    llen = math.sqrt(lx * lx + ly * ly + lz * lz)
                    atten = 1.0
                else:
                    lx = lights[k, 1] - px
                    ly = lights[k, 2] - py
                    lz = lights[k, 3] - pz
                    llen = math.sqrt(lx * lx + ly * ly + lz * lz)
                    atten = 1.0 / max(llen * llen + lights[k, 8] * lights[k, 8], 1e-4)
                lx /= llen
                ly /= llen
                lz /= llen
                ndl = nx * lx + ny * ly + nz * lz
                if ndl <= 0.0:
                    continue
                vis = 1.0
                si = int(lights[k, 7])
                if si >= 0:
                    vis = shadow_visibility(px, py, pz, sm_depth[si], sm_K[si], sm_R[si],
                                            sm_t[si], sm_ortho[si], bias, softness, taps)
                    if vis <= 0.0:
                        continue
                e = atten * vis
                lr += lights[k, 4] * e * ndl
                lg += lights[k, 5] * e * ndl
                lb += lights[k, 6] * e * ndl
                if spec > 0.0:
                    hx = lx + vx
                    hy = ly + vy
                    hz = lz + vz
                    hl = math.sqrt(hx * hx + hy * hy + hz * hz)
                    ndh = max((nx * hx + ny * hy + nz * hz) / max(hl, 1e-12), 0.0)
                    s = spec * e * ndh ** 32
                    sr += lights[k, 4] * s
                    sg += lights[k, 5] * s
                    sb += lights[k, 6] * s
            r = (ar * lr + sr) * exposure
            g = (ag * lg + sg) * exposure
            b = (ab * lb + sb) * exposure
            out[y, x, 0] = _encode(r, lut_encode)
            out[y, x, 1] = _encode(g, lut_encode)
            out[y, x, 2] = _encode(b, lut_encode)


def _f32(a, shape_tail, name, n=None):
    if a is None:
        return np.zeros((0,) + shape_tail, dtype=np.float32)
    a = np.ascontiguousarray(a, dtype=np.float32)
    if a.shape[1:] != shape_tail or (n is not None and a.shape[0] != n):
        raise ValueError(f"{name} must have shape ({n}, {', '.join(map(str, shape_tail))}), "
                         f"got {a.shape}")
    return a


def shade(raster, vertices: np.ndarray, faces: np.ndarray, face_material: np.ndarray,
          materials, camera_centre, lighting: Lighting, *, vertex_colours=None,
          face_colours=None, vertex_normals=None, vertex_uv=None,
          texture_atlas=None) -> np.ndarray:
    """Shade a rasterised view into an sRGB image.

    Args:
        raster: ``(zbuf, face_id, barycentrics)`` from :func:`rasterize` (with barycentrics).
        vertices: world-space vertices ``(V, 3)`` of the rasterised (concatenated) scene.
        faces: ``(F, 3)``, the same faces that were rasterised.
        face_material: ``(F,)`` index into ``materials`` per face.
        materials: sequence of :class:`Material` or a table from :func:`material_table`.
        camera_centre: the camera's position in the world (``-R.T @ t``), for two-sided
            lighting and highlights.
        lighting: :class:`Lighting`.
        vertex_colours: optional ``(V, 3)`` sRGB colours, used by materials with
            ``vertex_colour=True``.
        face_colours: optional ``(F, 3)`` sRGB multipliers for every face.
        vertex_normals: optional ``(V, 3)`` normals for materials with ``smooth=True``.
        vertex_uv: optional ``(V, 2)`` atlas coordinates for 'image' materials.
        texture_atlas: optional ``(h, w, 3)`` atlas, float in [0, 1] or uint8.

    Returns:
        uint8 ``(H, W, 3)`` RGB.
    """
    _, face_id, bary = raster
    if bary is None:
        raise ValueError("shading needs the barycentrics: rasterize(..., with_barycentrics=True)")
    vertices = _f32(vertices, (3,), "vertices")
    faces = np.ascontiguousarray(faces, dtype=np.int32)
    n_v = len(vertices)
    n_f = len(faces)
    face_material = np.ascontiguousarray(face_material, dtype=np.int32)
    table = materials if isinstance(materials, np.ndarray) else material_table(materials)
    table = np.ascontiguousarray(table, dtype=np.float32)
    if face_material.shape != (n_f,):
        raise ValueError(f"face_material must have shape ({n_f},), got {face_material.shape}")
    if n_f and (face_material.min() < 0 or face_material.max() >= len(table)):
        raise ValueError("face_material indexes outside the material table")
    if table.ndim != 2 or table.shape[1] != MATERIAL_FIELDS:
        raise ValueError(f"material table must be (n, {MATERIAL_FIELDS})")
    if texture_atlas is None:
        atlas = np.zeros((1, 1, 3), dtype=np.float32)
    else:
        atlas = np.asarray(texture_atlas)
        atlas = np.ascontiguousarray(atlas / 255.0 if atlas.dtype == np.uint8 else atlas,
                                     dtype=np.float32)
    # Per light: type (0 directional, 1 point), xyz, rgb, shadow map index, radius.
    lights = np.zeros((len(lighting.lights), 9), dtype=np.float64)
    maps = []
    for k, light in enumerate(lighting.lights):
        if isinstance(light, PointLight):
            lights[k, :4] = (1.0, *light.position)
            lights[k, 8] = light.radius
        elif isinstance(light, DirectionalLight):
            lights[k, :4] = (0.0, *light.direction)
        else:
            raise TypeError(f"unknown light {light!r}")
        lights[k, 4:7] = light.colour
        lights[k, 7] = -1
        if light.shadow is not None:
            lights[k, 7] = len(maps)
            maps.append(light.shadow)
    if maps:
        shape = maps[0].depth.shape
        if any(m.depth.shape != shape for m in maps):
            raise ValueError("all shadow maps must have the same size")
        sm_depth = np.stack([m.depth for m in maps]).astype(np.float32)
        sm_K = np.stack([m.K for m in maps]).astype(np.float64)
        sm_R = np.stack([m.R for m in maps]).astype(np.float64)
        sm_t = np.stack([m.t for m in maps]).astype(np.float64)
        sm_ortho = np.array([m.orthographic for m in maps], dtype=np.bool_)
    else:
        sm_depth = np.zeros((1, 1, 1), np.float32)
        sm_K = np.zeros((1, 3, 3))
        sm_R = np.zeros((1, 3, 3))
        sm_t = np.zeros((1, 3))
        sm_ortho = np.zeros(1, dtype=np.bool_)
    out = np.empty(face_id.shape + (3,), dtype=np.uint8)
    _shade_kernel(np.ascontiguousarray(face_id, dtype=np.int32),
                  np.ascontiguousarray(bary, dtype=np.float32), vertices, faces,
                  face_normals(vertices, faces), _f32(vertex_normals, (3,), "vertex_normals", n_v),
                  _f32(vertex_colours, (3,), "vertex_colours", n_v),
                  _f32(face_colours, (3,), "face_colours", n_f),
                  _f32(vertex_uv, (2,), "vertex_uv", n_v), atlas, face_material, table,
                  np.asarray(camera_centre, dtype=np.float64).reshape(3), lights, sm_depth, sm_K,
                  sm_R, sm_t, sm_ortho, np.asarray(lighting.ambient_sky, dtype=np.float64),
                  np.asarray(lighting.ambient_ground, dtype=np.float64), float(lighting.exposure),
                  float(lighting.shadow_bias), float(lighting.shadow_softness_px),
                  int(max(lighting.shadow_taps, 1)),
                  np.asarray(lighting.background, dtype=np.float64), _TO_LINEAR, _ENCODE, out)
    return out
