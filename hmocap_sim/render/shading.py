"""Per-pixel shading of a rasterised scene into an 8-bit RGB image.

Input is the z-buffer rasteriser's output (:func:`hmocap_sim.render.rasterize.rasterize`) for the
concatenated scene, plus the scene's world-space vertices and per-face material indices. Per
pixel: the world position and normal are interpolated with the perspective-correct
barycentrics; the albedo comes from the face's :class:`Material` (procedural texture on the
world position, optionally times per-vertex / per-face colours, or an image atlas with
per-vertex UVs); light is a hemispheric ambient term plus Lambert (and optional Blinn-Phong
highlight) from point and directional lights, each optionally attenuated by a soft shadow map
(:mod:`hmocap_sim.render.shadow`). Shading runs in linear light; the output is sRGB uint8.
Materials and lights are described in :mod:`hmocap_sim.render.materials` and
:mod:`hmocap_sim.render.lights`; sensor noise, illumination changes and anti-aliasing are in
:mod:`hmocap_sim.render.sensor`.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from hmocap_sim.render.lights import DirectionalLight, Lighting, PointLight
from hmocap_sim.render.materials import MATERIAL_FIELDS, Material, material_table
from hmocap_sim.render.meshes import face_normals
from hmocap_sim.render.shadow import shadow_visibility
from hmocap_sim.render.textures import (
    KIND_FABRIC,
    KIND_IMAGE,
    KIND_PLASTER,
    KIND_TILES,
    KIND_WOOD,
    atlas_bilinear,
    fabric,
    fbm3,
    plaster,
    tiles,
    wood_planks,
)

__all__ = ["DirectionalLight", "Lighting", "MATERIAL_FIELDS", "Material", "PointLight",
           "material_table", "shade"]

GAMMA = 2.2
# Look-up tables instead of a pow() per channel and pixel (half the shading time otherwise):
# sRGB-ish value -> linear on [0, 2] (textures may exceed 1), and linear -> uint8 indexed by
# sqrt(linear), which keeps the steep dark end of the curve finely sampled.
_TO_LINEAR_MAX = 2.0
_TO_LINEAR = (np.linspace(0.0, _TO_LINEAR_MAX, 2049) ** GAMMA).astype(np.float64)
_ENCODE = np.rint(np.linspace(0.0, 1.0, 4097) ** (2.0 / GAMMA) * 255.0).astype(np.uint8)


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


@nb.njit(cache=True, nogil=True, inline="always")
def _interpolate3(values, i0, i1, i2, w0, w1, w2):
    """Barycentric interpolation of a per-vertex 3-vector at one pixel."""
    x = w0 * values[i0, 0] + w1 * values[i1, 0] + w2 * values[i2, 0]
    y = w0 * values[i0, 1] + w1 * values[i1, 1] + w2 * values[i2, 1]
    z = w0 * values[i0, 2] + w1 * values[i1, 2] + w2 * values[i2, 2]
    return x, y, z


@nb.njit(cache=True, nogil=True, inline="always")
def _shading_normal(smooth, vnormals, i0, i1, i2, w0, w1, w2, gnx, gny, gnz):
    """The interpolated vertex normal for smooth materials (``smooth``), else (or where it
    vanishes) the face normal ``gn``."""
    if smooth:
        nx, ny, nz = _interpolate3(vnormals, i0, i1, i2, w0, w1, w2)
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
    return nx, ny, nz


@nb.njit(cache=True, nogil=True, inline="always")
def _towards_camera(cam, px, py, pz, gnx, gny, gnz, nx, ny, nz):
    """Unit direction to the camera, and the face and shading normals turned to the side the
    camera sees (surfaces are two-sided)."""
    vx = cam[0] - px
    vy = cam[1] - py
    vz = cam[2] - pz
    vlen = math.sqrt(vx * vx + vy * vy + vz * vz)
    vx /= vlen
    vy /= vlen
    vz /= vlen
    if gnx * vx + gny * vy + gnz * vz < 0.0:
        gnx = -gnx
        gny = -gny
        gnz = -gnz
    if nx * gnx + ny * gny + nz * gnz < 0.0:
        nx = -nx
        ny = -ny
        nz = -nz
    return vx, vy, vz, gnx, gny, gnz, nx, ny, nz


@nb.njit(cache=True, nogil=True, inline="always")
def _linear_albedo(mat, f, i0, i1, i2, w0, w1, w2, px, py, pz, gnx, gny, gnz, vcolours,
                   fcolours, vuv, atlas, lut_linear):
    """Linear-light albedo of face ``f`` at one pixel: the material's texture, times the
    interpolated vertex colour (materials with ``vertex_colour``) and the face colour."""
    has_vc = vcolours.shape[0] > 0
    has_fc = fcolours.shape[0] > 0
    has_uv = vuv.shape[0] > 0
    s_uv = 0.0
    t_uv = 0.0
    if has_uv:
        s_uv = w0 * vuv[i0, 0] + w1 * vuv[i1, 0] + w2 * vuv[i2, 0]
        t_uv = w0 * vuv[i0, 1] + w1 * vuv[i1, 1] + w2 * vuv[i2, 1]
    ar, ag, ab = _albedo(mat, px, py, pz, gnx, gny, gnz, s_uv, t_uv, atlas, has_uv)
    if mat[10] > 0.5 and has_vc:
        cr, cg, cb = _interpolate3(vcolours, i0, i1, i2, w0, w1, w2)
        ar *= cr
        ag *= cg
        ab *= cb
    if has_fc:
        ar *= fcolours[f, 0]
        ag *= fcolours[f, 1]
        ab *= fcolours[f, 2]
    return _to_linear(ar, lut_linear), _to_linear(ag, lut_linear), _to_linear(ab, lut_linear)


@nb.njit(cache=True, nogil=True, inline="always")
def _irradiance(px, py, pz, nx, ny, nz, vx, vy, vz, spec, lights, sm_depth, sm_K, sm_R, sm_t,
                sm_ortho, amb_sky, amb_ground, bias, softness, taps):
    """Diffuse irradiance (hemispheric ambient + Lambert) and Blinn-Phong highlight (strength
    ``spec``) at a surface point, each light attenuated by its soft shadow map."""
    h = 0.5 + 0.5 * ny
    lr = amb_ground[0] + h * (amb_sky[0] - amb_ground[0])
    lg = amb_ground[1] + h * (amb_sky[1] - amb_ground[1])
    lb = amb_ground[2] + h * (amb_sky[2] - amb_ground[2])
    sr = 0.0
    sg = 0.0
    sb = 0.0
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
    return lr, lg, lb, sr, sg, sb


@nb.njit(cache=True, nogil=True, parallel=True)
def _shade_kernel(face_id, bary, vertices, faces, fnormals, vnormals, vcolours, fcolours, vuv,
                  atlas, face_material, materials, cam, lights, sm_depth, sm_K, sm_R, sm_t,
                  sm_ortho, amb_sky, amb_ground, exposure, bias, softness, taps, background,
                  lut_linear, lut_encode, out):
    height = face_id.shape[0]
    width = face_id.shape[1]
    has_vn = vnormals.shape[0] > 0
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
            px, py, pz = _interpolate3(vertices, i0, i1, i2, w0, w1, w2)
            mat = materials[face_material[f]]
            gnx = np.float64(fnormals[f, 0])
            gny = np.float64(fnormals[f, 1])
            gnz = np.float64(fnormals[f, 2])
            nx, ny, nz = _shading_normal(mat[11] > 0.5 and has_vn, vnormals, i0, i1, i2,
                                         w0, w1, w2, gnx, gny, gnz)
            vx, vy, vz, gnx, gny, gnz, nx, ny, nz = _towards_camera(cam, px, py, pz, gnx, gny,
                                                                    gnz, nx, ny, nz)
            ar, ag, ab = _linear_albedo(mat, f, i0, i1, i2, w0, w1, w2, px, py, pz, gnx, gny,
                                        gnz, vcolours, fcolours, vuv, atlas, lut_linear)
            lr, lg, lb, sr, sg, sb = _irradiance(px, py, pz, nx, ny, nz, vx, vy, vz, mat[12],
                                                 lights, sm_depth, sm_K, sm_R, sm_t, sm_ortho,
                                                 amb_sky, amb_ground, bias, softness, taps)
            out[y, x, 0] = _encode((ar * lr + sr) * exposure, lut_encode)
            out[y, x, 1] = _encode((ag * lg + sg) * exposure, lut_encode)
            out[y, x, 2] = _encode((ab * lb + sb) * exposure, lut_encode)


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
    atlas = _atlas(texture_atlas)
    lights, (sm_depth, sm_K, sm_R, sm_t, sm_ortho) = _light_table(lighting.lights)
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


def _atlas(texture_atlas) -> np.ndarray:
    """The texture atlas as float32 in [0, 1] (a 1x1 black one if None)."""
    if texture_atlas is None:
        return np.zeros((1, 1, 3), dtype=np.float32)
    atlas = np.asarray(texture_atlas)
    return np.ascontiguousarray(atlas / 255.0 if atlas.dtype == np.uint8 else atlas,
                                dtype=np.float32)


def _light_table(scene_lights) -> tuple:
    """The kernel's light rows and stacked shadow maps.

    One row of 9 per light: type (0 directional, 1 point), xyz (position or travel
    direction), rgb, shadow map index (-1 for none), radius. Shadow maps are stacked as
    (depth, K, R, t, orthographic), a single empty map when no light has one.
    """
    lights = np.zeros((len(scene_lights), 9), dtype=np.float64)
    maps = []
    for k, light in enumerate(scene_lights):
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
    if not maps:
        return lights, (np.zeros((1, 1, 1), np.float32), np.zeros((1, 3, 3)), np.zeros((1, 3, 3)),
                        np.zeros((1, 3)), np.zeros(1, dtype=np.bool_))
    shape = maps[0].depth.shape
    if any(m.depth.shape != shape for m in maps):
        raise ValueError("all shadow maps must have the same size")
    return lights, (np.stack([m.depth for m in maps]).astype(np.float32),
                    np.stack([m.K for m in maps]).astype(np.float64),
                    np.stack([m.R for m in maps]).astype(np.float64),
                    np.stack([m.t for m in maps]).astype(np.float64),
                    np.array([m.orthographic for m in maps], dtype=np.bool_))
