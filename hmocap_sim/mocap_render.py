"""One multi-view frame of the simulated smart room, with exact ground-truth silhouettes.

:class:`MocapRenderer` holds everything that does not change during a recording: the rig, the
furnished room (:mod:`hmocap_sim.room`), the people's meshes and looks
(:mod:`hmocap_sim.appearance`), the materials and the static half of the lamp's shadow
map. :meth:`MocapRenderer.render` takes what moves (:class:`FrameState`: posed vertices of each
person, the door's opening angle, the ball, the light levels) and, per camera,

1. projects the whole scene with the camera's lens distortion
   (:func:`hmocap_ros.geometry.projection.project_batch`) and z-buffers it
   (:func:`hmocap_sim.render.rasterize.rasterize`), optionally supersampled;
2. shades it (:func:`hmocap_sim.render.shading.shade`): procedural textures, Lambert light from
   a lamp with a soft shadow map (furniture and people cast shadows, people also on
   themselves), daylight through the window, hemispheric ambient light standing in for the
   light bounced off walls and ceiling (shadows keep about half the brightness, as indoors);
   window glass is painted as an emitter (overexposed sky);
3. turns it into a camera image: box-filter downsampling, a slight lens blur, vignetting and
   Poisson-Gaussian sensor noise (:mod:`hmocap_sim.render.sensor` model);
4. reads the ground-truth silhouette from the same z-buffer at the output resolution: the
   pixels whose nearest surface is the subject (``face_id`` inside the subject's face range),
   so furniture, the door or a second person in front of the subject are handled exactly; the
   same for each person with ground truth (``truth_people``).

Per-camera colour response (white balance and gain) is folded into the light intensities. All
randomness (sensor noise) comes from the generators passed in, so frames repeat bit for bit.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from hmocap_ros.geometry.pinhole_camera import look_at_pose
from hmocap_ros.geometry.projection import project_batch
from hmocap_ros.geometry.rig import camera_arrays  # noqa: F401 (re-exported)
from hmocap_sim.appearance import PERSON_MATERIALS, PersonLook
from hmocap_sim.render.meshes import vertex_normals
from hmocap_sim.render.rasterize import rasterize
from hmocap_sim.render.shading import (
    DirectionalLight,
    Lighting,
    Material,
    PointLight,
    material_table,
    shade,
)
from hmocap_sim.render.shadow import ShadowMap
from hmocap_sim.room import Room, ball_mesh

__all__ = ["RenderOptions", "FrameState", "RenderedFrame", "MocapRenderer", "BALL_RADIUS",
           "camera_arrays", "sensor_image"]

BALL_RADIUS = 0.13
_BALL_COLOURS = np.array([(0.85, 0.12, 0.10), (0.95, 0.95, 0.92), (0.10, 0.35, 0.80),
                          (0.95, 0.80, 0.10), (0.10, 0.60, 0.25), (0.95, 0.95, 0.92),
                          (0.95, 0.45, 0.10), (0.95, 0.95, 0.92)], np.float32)


@dataclass(frozen=True)
class RenderOptions:
    """How frames are rendered.

    shadows: the lamp casts shadows (furniture, people, door, ball) through a shadow map.
    supersample: render at this factor and box-filter down (anti-aliasing); 0 = automatic
        (2 up to 320 pixels wide, else 1).
    noise: add sensor noise (``read_sigma`` levels plus ``shot_gain`` times the level, as
        variances); vignette: corner darkening (linear light); blur_sigma: lens blur (px).
    shadow_map_size, shadow_fov_deg, shadow_softness_px: the lamp's shadow map (a wide
        perspective map looking down from the lamp) and its PCF filter radius.
    """

    shadows: bool = True
    supersample: int = 0
    noise: bool = True
    read_sigma: float = 1.3
    shot_gain: float = 0.05
    vignette: float = 0.25
    blur_sigma: float = 0.45
    shadow_map_size: int = 1024
    shadow_fov_deg: float = 140.0
    shadow_softness_px: float = 3.0

    def supersample_for(self, width: int) -> int:
        if self.supersample > 0:
            return int(self.supersample)
        return 2 if width <= 320 else 1


@dataclass(frozen=True, eq=False)
class FrameState:
    """What moves in one frame.

    people: posed vertices ``(V, 3)`` of each person given to the renderer (room frame), or
        None where that person is absent; people[0] is the subject.
    door_angle: the door's opening angle (radians, 0 = closed).
    ball: ``(centre (3,), spin, axis_yaw)`` of the rolling ball, or None.
    lamp_gain, window_gain: relative intensity of the lamp and of the daylight (clouds).
    exposure: global exposure (camera auto-exposure drift).
    """

    people: tuple
    door_angle: float = 0.0
    ball: tuple | None = None
    lamp_gain: float = 1.0
    window_gain: float = 1.0
    exposure: float = 1.0


@dataclass(frozen=True, eq=False)
class RenderedFrame:
    """Images (H, W, 3) uint8 RGB and the subject's ground-truth silhouettes (H, W) uint8
    0/255, per camera, and the seconds spent in each stage. ``people_silhouettes``: per camera,
    the silhouette of each person with ground truth (``MocapRenderer``'s ``truth_people``; the
    subject's first)."""

    images: tuple
    silhouettes: tuple
    timings: dict = field(default_factory=dict)
    people_silhouettes: tuple = ()


def _vignette_gain(width: int, height: int, strength: float) -> np.ndarray:
    """Per-pixel gain in sRGB levels for a ``1 - strength (r / r_corner)^2`` linear fall-off."""
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    r2 = (((xx - (width - 1) / 2) ** 2 + (yy - (height - 1) / 2) ** 2)
          / (((width - 1) / 2) ** 2 + ((height - 1) / 2) ** 2))
    lin = np.clip(1.0 - strength * r2, 0.05, 1.0)
    return (lin ** (1.0 / 2.2)).astype(np.float32)[..., None]


def sensor_image(rgb: np.ndarray, rng: np.random.Generator | None, *, gain_map=None,
                 read_sigma: float = 1.3, shot_gain: float = 0.05,
                 blur_sigma: float = 0.0) -> np.ndarray:
    """A clean rendering as a camera delivers it: lens blur, vignetting (``gain_map``
    (H, W, 1), sRGB levels) and Poisson-Gaussian noise of variance
    ``read_sigma^2 + shot_gain * level`` (no noise when ``rng`` is None)."""
    img = rgb
    if blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_sigma)
    img = img.astype(np.float32)
    if gain_map is not None:
        img *= gain_map
    if rng is not None:
        sigma = np.sqrt(np.float32(read_sigma) ** 2 + np.float32(shot_gain) * img)
        img += sigma * rng.standard_normal(img.shape, dtype=np.float32)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _scene_parts(room: Room, people: Sequence[tuple], person_base: int, ball_material: int,
                 with_ball: bool) -> list:
    """The scene's parts in mesh order: static room, door, people, ball (fixed topology).

    Each is ``(name, n_vertices, faces, face_material, face_colours, vertex_colours, uv)``;
    people's materials start at ``person_base``, the ball's is ``ball_material``.
    """
    st = room.static
    parts = [("static", len(st.vertices), st.faces, st.face_material,
              np.ones((len(st.faces), 3), np.float32), st.colours, st.uv)]
    dm = room.door.mesh
    parts.append(("door", len(dm.vertices), dm.faces, dm.face_material,
                  np.ones((len(dm.faces), 3), np.float32), dm.colours, dm.uv))
    for k, (faces, look) in enumerate(people):
        faces = np.asarray(faces, np.int32)
        if not isinstance(look, PersonLook):
            raise TypeError("people must be (faces, PersonLook) pairs")
        n_v = len(look.vertex_colours)
        parts.append((f"person_{k}", n_v, faces, look.face_material + person_base,
                      look.face_colours, look.vertex_colours, np.zeros((n_v, 2), np.float32)))
    if with_ball:
        bv, bf, seg = ball_mesh((0.0, 0.0, 0.0), BALL_RADIUS)
        parts.append(("ball", len(bv), bf, np.full(len(bf), ball_material, np.int32),
                      np.ones((len(bf), 3), np.float32), _BALL_COLOURS[seg % 8],
                      np.zeros((len(bv), 2), np.float32)))
    return parts


class MocapRenderer:
    """Renders frames of one recording: fixed rig, room and people (module docstring).

    Args:
        rig: the cameras (:class:`hmocap_ros.geometry.rig.Rig`).
        room: the furnished room (:func:`hmocap_sim.room.build_room`).
        people: ``(faces (F, 3), look)`` per person, the subject first; their vertices come
            with every :class:`FrameState`.
        options: :class:`RenderOptions`.
        camera_gains: ``(M, 3)`` per-camera colour response (white balance x gain), default 1.
        with_ball: whether the scene has the rolling ball (a distractor).
        truth_people: the first this many people have ground-truth silhouettes.
    """

    def __init__(self, rig, room: Room, people: Sequence[tuple], options: RenderOptions =
                 RenderOptions(), camera_gains=None, with_ball: bool = False,
                 truth_people: int = 1):
        self.rig = rig
        self.truth_people = int(truth_people)
        self.room = room
        self.options = options
        self.width = int(rig[0].width)
        self.height = int(rig[0].height)
        if any((c.width, c.height) != (self.width, self.height) for c in rig):
            raise ValueError("all cameras of the rig must have the same resolution")
        self.n_cameras = len(rig)
        self.K, self.R, self.t, self.dist = camera_arrays(rig)
        self.centres = np.stack([c.position for c in rig])
        self.camera_gains = (np.ones((self.n_cameras, 3)) if camera_gains is None
                             else np.asarray(camera_gains, float).reshape(self.n_cameras, 3))
        self.supersample = options.supersample_for(self.width)

        materials = list(room.materials)
        person_base = len(materials)
        materials += list(PERSON_MATERIALS)
        ball_material = len(materials)
        materials.append(Material("plain", (1.0, 1.0, 1.0), vertex_colour=True, smooth=True,
                                  specular=0.35))
        self.materials = tuple(materials)
        self.material_table = material_table(materials)
        self._assemble(_scene_parts(room, people, person_base, ball_material, with_ball))
        st = room.static
        s0, s1 = self.ranges["static"][:2]
        self._vertices[s0:s1] = st.vertices
        smooth = self.material_table[st.face_material, 11] > 0.5
        if smooth.any():
            self._normals[s0:s1] = vertex_normals(st.vertices, st.faces)
        emissive = np.zeros(len(self.materials), bool)
        self._emissive_colour = np.zeros((len(self.materials), 3), np.float32)
        for m, colour in room.emissive.items():
            emissive[m] = True
            self._emissive_colour[m] = colour
        self._face_emissive = emissive[self.face_material]
        self._people_faces = [np.asarray(f, np.int32) for f, _ in people]
        self._people_looks = [look for _, look in people]

        # ---- the lamp's shadow map: fixed view, static casters rendered once
        self._lamp_view = self._lamp_camera()
        casters = st.faces[room.shadow_casters]
        self._static_depth = self._lamp_depth(st.vertices, casters)
        self._vignette = (_vignette_gain(self.width, self.height, options.vignette)
                          if options.vignette > 0 else None)
        self.last_timings: dict = {}

    def _assemble(self, parts: list) -> None:
        """Concatenate the scene's parts (``_scene_parts``) into one mesh; ``ranges`` maps each
        part's name to its ``(first vertex, end vertex, first face, end face)``."""
        v_off = np.concatenate([[0], np.cumsum([p[1] for p in parts])]).astype(np.int64)
        f_off = np.concatenate([[0], np.cumsum([len(p[2]) for p in parts])]).astype(np.int64)
        self.ranges = {p[0]: (int(v_off[i]), int(v_off[i + 1]), int(f_off[i]), int(f_off[i + 1]))
                       for i, p in enumerate(parts)}
        self.faces = np.ascontiguousarray(np.concatenate(
            [p[2] + v_off[i] for i, p in enumerate(parts)]), dtype=np.int32)
        self.face_material = np.ascontiguousarray(np.concatenate([p[3] for p in parts]),
                                                  dtype=np.int32)
        self.face_colours = np.ascontiguousarray(np.concatenate([p[4] for p in parts]),
                                                 dtype=np.float32)
        self.vertex_colours = np.ascontiguousarray(np.concatenate([p[5] for p in parts]),
                                                   dtype=np.float32)
        self.vertex_uv = np.ascontiguousarray(np.concatenate([p[6] for p in parts]),
                                              dtype=np.float32)
        self.n_vertices = int(v_off[-1])
        self._vertices = np.zeros((self.n_vertices, 3), np.float32)
        self._normals = np.zeros((self.n_vertices, 3), np.float32)

    # ------------------------------------------------------------------ shadow map

    def _lamp_camera(self):
        size = int(self.options.shadow_map_size)
        lamp = np.asarray(self.room.lamp, float)
        R, t = look_at_pose(lamp, lamp - [0.0, 1.0, 0.0], up=(0.0, 0.0, 1.0))
        half = 0.5 * (size - 1)
        focal = 0.5 * size / math.tan(math.radians(0.5 * self.options.shadow_fov_deg))
        K = np.array([[focal, 0.0, half], [0.0, focal, half], [0.0, 0.0, 1.0]])
        return K, R, t, size

    def _lamp_depth(self, vertices, faces) -> np.ndarray:
        K, R, t, size = self._lamp_view
        if len(faces) == 0:
            return np.full((size, size), np.inf, np.float32)
        xc = np.asarray(vertices, np.float64) @ R.T + t
        with np.errstate(invalid="ignore", divide="ignore"):
            uv = xc[:, :2] / xc[:, 2:3] * K[0, 0] + K[0, 2]
        depth, _, _ = rasterize(uv, xc[:, 2], faces, size, size, near=0.05,
                                with_barycentrics=False)
        return depth

    def shadow_map(self, vertices: np.ndarray) -> ShadowMap:
        """The lamp's shadow map for the scene ``vertices`` (static part cached)."""
        K, R, t, _ = self._lamp_view
        dyn = []
        for name, (_v0, _v1, f0, f1) in self.ranges.items():
            if name == "static":
                continue
            dyn.append(self.faces[f0:f1])
        depth = self._static_depth
        if dyn:
            depth = np.minimum(depth, self._lamp_depth(vertices, np.concatenate(dyn)))
        return ShadowMap(depth=depth, K=K, R=R, t=t, orthographic=False)

    # ------------------------------------------------------------------ frames

    def scene_vertices(self, state: FrameState) -> np.ndarray:
        """All scene vertices (room frame) for a frame; absent things are NaN."""
        v = self._vertices
        d0, d1 = self.ranges["door"][:2]
        v[d0:d1] = self.room.door.vertices(float(state.door_angle))
        for k in range(len(self._people_faces)):
            p0, p1 = self.ranges[f"person_{k}"][:2]
            pv = state.people[k] if k < len(state.people) else None
            if pv is None:
                v[p0:p1] = np.nan
            else:
                pv = np.asarray(pv, np.float32)
                if pv.shape != (p1 - p0, 3):
                    raise ValueError(f"person {k}: expected ({p1 - p0}, 3) vertices, "
                                     f"got {pv.shape}")
                v[p0:p1] = pv
        if "ball" in self.ranges:
            b0, b1 = self.ranges["ball"][:2]
            if state.ball is None:
                v[b0:b1] = np.nan
            else:
                centre, spin, yaw = state.ball
                v[b0:b1] = ball_mesh(centre, BALL_RADIUS, spin, yaw)[0]
        return v

    def _update_normals(self, vertices: np.ndarray) -> None:
        for name, (v0, v1, f0, f1) in self.ranges.items():
            if name == "static" or name == "door":
                continue
            local = self.faces[f0:f1] - v0
            pv = vertices[v0:v1]
            if np.isfinite(pv[:1]).all():
                self._normals[v0:v1] = vertex_normals(pv, local)

    def _lighting(self, m: int, state: FrameState, shadow: ShadowMap | None) -> Lighting:
        room = self.room
        gain = self.camera_gains[m]
        lamp = np.asarray(room.lamp_colour) * state.lamp_gain * gain
        window = np.asarray(room.window_colour) * state.window_gain * gain
        daylight = 0.6 + 0.4 * state.window_gain  # part of the ambient light is daylight
        return Lighting(
            lights=(PointLight(tuple(room.lamp), tuple(lamp), shadow, radius=0.4),
                    DirectionalLight(tuple(room.window_direction), tuple(window))),
            ambient_sky=tuple(np.asarray(room.ambient_sky) * daylight * gain),
            ambient_ground=tuple(np.asarray(room.ambient_ground) * daylight * gain),
            exposure=float(state.exposure), shadow_bias=0.02,
            shadow_softness_px=self.options.shadow_softness_px, shadow_taps=5)

    def subject_mask(self, face_id: np.ndarray, person: int = 0) -> np.ndarray:
        """uint8 0/255 mask of the pixels whose nearest surface is a person (default the
        subject, person 0)."""
        f0, f1 = self.ranges[f"person_{person}"][2:]
        return (((face_id >= f0) & (face_id < f1)) * np.uint8(255)).astype(np.uint8)

    def render(self, state: FrameState, rngs: Sequence[np.random.Generator] | None = None
               ) -> RenderedFrame:
        """Render every camera for one frame. ``rngs``: one generator per camera for the
        sensor noise (required when ``options.noise``)."""
        opt = self.options
        if opt.noise and (rngs is None or len(rngs) != self.n_cameras):
            raise ValueError(f"noise needs one generator per camera ({self.n_cameras})")
        timings = {"pose": 0.0, "shadow": 0.0, "raster": 0.0, "shade": 0.0, "sensor": 0.0}
        t0 = time.perf_counter()
        vertices = self.scene_vertices(state)
        self._update_normals(vertices)
        t1 = time.perf_counter()
        timings["pose"] += t1 - t0
        shadow = self.shadow_map(vertices) if opt.shadows else None
        t2 = time.perf_counter()
        timings["shadow"] += t2 - t1
        ss = self.supersample
        uv, z = project_batch(vertices[None], self.K, self.R, self.t, self.dist, scale=ss)
        if ss > 1:
            uv1, z1 = project_batch(vertices[None], self.K, self.R, self.t, self.dist)
        timings["raster"] += time.perf_counter() - t2
        images, masks, people_masks = [], [], []
        h, w = self.height, self.width
        for m in range(self.n_cameras):
            ta = time.perf_counter()
            raster = rasterize(uv[0, m], z[0, m], self.faces, h * ss, w * ss)
            tb = time.perf_counter()
            rgb = shade(raster, vertices, self.faces, self.face_material, self.material_table,
                        self.centres[m], self._lighting(m, state, shadow),
                        vertex_colours=self.vertex_colours, face_colours=self.face_colours,
                        vertex_normals=self._normals, vertex_uv=self.vertex_uv,
                        texture_atlas=self.room.atlas)
            self._paint_emitters(rgb, raster[1], m, state)
            tc = time.perf_counter()
            if ss > 1:
                rgb = cv2.resize(rgb, (w, h), interpolation=cv2.INTER_AREA)
                face_id = rasterize(uv1[0, m], z1[0, m], self.faces, h, w,
                                    with_barycentrics=False)[1]
            else:
                face_id = raster[1]
            masks.append(self.subject_mask(face_id))
            people_masks.append((masks[-1],) + tuple(self.subject_mask(face_id, p)
                                                     for p in range(1, self.truth_people)))
            td = time.perf_counter()
            images.append(sensor_image(
                rgb, rngs[m] if opt.noise else None, gain_map=self._vignette,
                read_sigma=opt.read_sigma, shot_gain=opt.shot_gain, blur_sigma=opt.blur_sigma))
            te = time.perf_counter()
            timings["raster"] += (tb - ta) + (td - tc)
            timings["shade"] += tc - tb
            timings["sensor"] += te - td
        self.last_timings = timings
        return RenderedFrame(tuple(images), tuple(masks), timings, tuple(people_masks))

    def _paint_emitters(self, rgb: np.ndarray, face_id: np.ndarray, m: int,
                        state: FrameState) -> None:
        hit = face_id >= 0
        em = np.zeros(face_id.shape, bool)
        em[hit] = self._face_emissive[face_id[hit]]
        if not em.any():
            return
        radiance = self._emissive_colour[self.face_material[face_id[em]]]
        lin = radiance.astype(np.float64) * (state.window_gain * state.exposure
                                             * self.camera_gains[m])
        rgb[em] = np.clip(np.rint(np.clip(lin, 0, 1) ** (1 / 2.2) * 255), 0, 255).astype(np.uint8)
