"""What a real depth sensor does to a rendered z-buffer, per sensor family.

Structured-light (Kinect v1, PrimeSense) and active-IR stereo (RealSense D4xx) cameras both
measure a disparity ``d = f b / z`` (focal length ``f`` in the sensor's own pixels, baseline
``b``) by matching a window of an IR image, so they share one model with per-family numbers
(:data:`SENSORS`, ``docs/gestures.md`` gives the sources):

- **disparity noise and quantisation**: a disparity error of ``disparity_sigma_px`` (RMS) and
  steps of ``disparity_step_px``, in the sensor's pixels, hence a depth error
  ``sigma_z = z^2 sigma_d / (f b)`` and depth steps ``z^2 step / (f b)`` growing as ``z^2``
  (Khoshelham & Elberink 2012, eq. 9; Intel's D400 RMS error formula);
- **speckle**: a share ``speckle_share`` of the disparity noise variance is correlated over
  blobs of ``speckle_px`` (Gaussian std), the size of the matching window;
- **edge fattening**: the matching window at a depth edge locks on the nearer surface, which
  spreads ``fattening_px`` into the background;
- **holes** (0 = no data, as in ROS 16UC1 depth): the band beside a nearer object that the
  projector (or the second imager) does not see, of width ``f b (1/z_near - 1/z_far)`` on
  the object's left; depth discontinuities (``edge_dropout``); a surface that returns too
  little IR, ``albedo x cos(incidence) < min_return x u`` with ``u`` uniform in (0, 1): dark or
  shiny (low diffuse albedo) surfaces and surfaces seen at a grazing angle, i.e. the rims of
  fingers and arms; random pixels (``dropout``); outside ``[min_depth, max_depth]``.

:func:`sensor_depth` is a pure function of the z-buffer, a per-pixel albedo (near-infrared
diffuse reflectance, 0-1; without one every surface is matte at :data:`DEFAULT_ALBEDO`) and
a ``numpy.random.Generator``; it draws the same five images for every frame, so the same
seed gives the same bytes. The ``ideal`` sensor returns the z-buffer in millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from hmocap_sim.render.depth import (
    KinectNoise,
    depth_discontinuities,
    depth_to_millimetres,
    kinect_depth,
    projector_shadow,
)

#: Near-infrared diffuse reflectance of a surface when the renderer gives none (skin and light
#: matte surfaces reflect 0.4-0.6 of the projector's 830 nm light).
DEFAULT_ALBEDO = 0.5
#: the image width the plain model's disparity steps belong to: a smaller image keeps the
#: sensor's depth steps
PLAIN_WIDTH = 640


@dataclass(frozen=True)
class DepthSensor:
    """One sensor family's parameters (pixels are the sensor's own, ``native_fx`` focal).

    baseline_m: projector-camera (structured light) or imager-imager (stereo) baseline; the
        second viewpoint is on the camera's +x side. 0 means the ideal sensor.
    native_fx: the depth sensor's focal length in its own pixels; disparities and the sizes
        below are in those pixels and scale to the rendered image by ``fx / native_fx``.
    disparity_sigma_px: RMS disparity error. disparity_step_px: disparity quantisation.
    speckle_share: share of the disparity noise variance correlated over blobs of
        ``speckle_px`` (Gaussian std).
    fattening_px: how far the nearer surface spreads over a depth edge.
    edge_threshold: a pixel is on a depth discontinuity when its 3x3 neighbourhood spans
        more than this fraction of its depth. edge_dropout: probability such a pixel reads 0.
    min_return: albedo x cos(incidence) under which a pixel may read 0 (never above it).
    dropout: probability that any pixel reads 0.
    min_depth, max_depth: working range (m).
    plain: the plain Kinect model of :func:`hmocap_sim.render.kinect_depth` (disparity noise and
        steps, projector shadows, holes at depth edges and at random; no speckle, fattening or
        material holes), with this set's noise, steps, baseline, edge and range parameters: the
        depth the shipped gesture forest was trained on.
    """

    baseline_m: float = 0.0
    native_fx: float = 575.0
    disparity_sigma_px: float = 0.0
    disparity_step_px: float = 0.0
    speckle_share: float = 0.0
    speckle_px: float = 0.0
    fattening_px: float = 0.0
    edge_threshold: float = 0.05
    edge_dropout: float = 0.0
    min_return: float = 0.0
    dropout: float = 0.0
    min_depth: float = 0.0
    max_depth: float = 65.535
    plain: bool = False

    @property
    def ideal(self) -> bool:
        return self.baseline_m <= 0.0

    def depth_sigma(self, z):
        """Depth noise std (m) at depth ``z`` (m): ``z^2 sigma_d / (f b)``."""
        return np.square(z) * self.disparity_sigma_px / (self.native_fx * self.baseline_m)

    def depth_step(self, z):
        """Depth quantisation step (m) at depth ``z`` (m): ``z^2 step_d / (f b)``."""
        return np.square(z) * self.disparity_step_px / (self.native_fx * self.baseline_m)


#: The sensor families by name (``hmocap sim gestures --sensor``); ``docs/gestures.md`` states
#: where each number comes from.
SENSORS = {
    "ideal": DepthSensor(),
    # Kinect v1 / PrimeSense at 640x480: f 580 px, b 7.5 cm, 1/8 px disparity steps,
    # 0.065 px RMS (1.5 mm at 1 m, 4 cm at 5 m), 9x9 correlation window.
    "structured_light": DepthSensor(baseline_m=0.075, native_fx=580.0, disparity_sigma_px=0.065,
                                    disparity_step_px=0.125, speckle_share=0.5, speckle_px=3.0,
                                    fattening_px=2.0, edge_threshold=0.05, edge_dropout=0.6,
                                    min_return=0.15, dropout=0.002, min_depth=0.5, max_depth=4.5),
    # The plain Kinect v1 model (``plain``): 1.5 mm at 1 m, 1/8 px steps, 7.5 cm baseline.
    "structured_light_plain": DepthSensor(baseline_m=0.075, native_fx=580.0,
                                          disparity_sigma_px=0.0015 * 580.0 * 0.075,
                                          disparity_step_px=0.125, edge_threshold=0.05,
                                          edge_dropout=0.6, dropout=0.002, min_depth=0.5,
                                          max_depth=4.5, plain=True),
    # RealSense D435 at 848x480: f 430 px (87 deg HFOV), b 5 cm, subpixel RMS 0.08 px, depth in
    # 1 mm units (no coarser disparity step); its second imager sees the occlusion band.
    "stereo": DepthSensor(baseline_m=0.050, native_fx=430.0, disparity_sigma_px=0.08,
                          disparity_step_px=0.0, speckle_share=0.6, speckle_px=2.0,
                          fattening_px=2.0, edge_threshold=0.05, edge_dropout=0.3,
                          min_return=0.10, dropout=0.002, min_depth=0.3, max_depth=6.0),
}
SENSOR_NAMES = tuple(SENSORS)
#: The sensor the simulator renders with unless told otherwise: the thesis' Kinect, whose
#: intrinsics the simulated camera has.
DEFAULT_SENSOR = "structured_light"


def sensor_by_name(name: str) -> DepthSensor:
    """The :data:`SENSORS` entry ``name``, or a ValueError naming the choices."""
    if name not in SENSORS:
        raise ValueError(f"unknown depth sensor {name!r}; choose among {', '.join(SENSOR_NAMES)}")
    return SENSORS[name]


def _one_sided_slope(z: np.ndarray, axis: int) -> np.ndarray:
    """Depth change per pixel along ``axis``, from the neighbour on the same surface (the
    smaller of the forward and backward differences), so a depth edge is not a slope."""
    fwd = np.diff(z, axis=axis, append=np.take(z, [-1], axis=axis))
    bwd = np.diff(z, axis=axis, prepend=np.take(z, [0], axis=axis))
    return np.where(np.abs(fwd) < np.abs(bwd), fwd, bwd)


def incidence_cosine(zbuf: np.ndarray, fx: float, cx: float, cy: float) -> np.ndarray:
    """cos of the angle between each pixel's viewing ray and its surface normal, from the
    depth slopes (fx = fy): the normal of ``P = z (u - cx, v - cy, f) / f`` is proportional to
    ``(-f z_u, -f z_v, z + (u - cx) z_u + (v - cy) z_v)``; 1 where there is no surface."""
    z = np.asarray(zbuf, dtype=np.float32)
    valid = np.isfinite(z) & (z > 0)
    z = np.where(valid, z, np.float32(1e3))
    zu, zv = _one_sided_slope(z, 1), _one_sided_slope(z, 0)
    h, w = z.shape
    u = np.arange(w, dtype=np.float32)[None, :] - np.float32(cx)
    v = np.arange(h, dtype=np.float32)[:, None] - np.float32(cy)
    nz = z + u * zu + v * zv
    n_norm = np.sqrt(np.square(fx * zu) + np.square(fx * zv) + np.square(nz))
    ray_norm = np.sqrt(np.square(u) + np.square(v) + fx * fx) / fx
    cos = z / np.maximum(n_norm * ray_norm, np.float32(1e-12))
    return np.where(valid, np.clip(cos, 0.0, 1.0), np.float32(1.0))


def fatten_edges(zbuf: np.ndarray, radius_px: float, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """The nearer surface spread over depth edges by ``radius_px``: each pixel within the
    radius of a surface nearer by more than ``threshold`` x its depth takes that depth.
    Returns (depth, mask of the pixels that took a nearer depth); empty pixels count as far."""
    z = np.asarray(zbuf, dtype=np.float32)
    far = np.float32(1e3)
    zf = np.where(np.isfinite(z) & (z > 0), z, far)
    r = int(round(radius_px))
    if r < 1:
        return zf, np.zeros(z.shape, bool)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    nearest = cv2.erode(zf, kernel, borderType=cv2.BORDER_REPLICATE)
    took = (zf - nearest) > threshold * zf
    return np.where(took, nearest, zf), took


def correlated_noise(rng: np.random.Generator, shape: tuple, sigma_px: float) -> np.ndarray:
    """Unit-variance Gaussian noise correlated over blobs of ``sigma_px`` (white noise
    blurred by a Gaussian of that std and rescaled by ``2 sqrt(pi) sigma``)."""
    white = rng.standard_normal(shape, dtype=np.float32)
    if sigma_px < 0.3:
        return white
    blurred = cv2.GaussianBlur(white, (0, 0), sigma_px, borderType=cv2.BORDER_REFLECT)
    return blurred * np.float32(2.0 * np.sqrt(np.pi) * sigma_px)


def sensor_depth(zbuf: np.ndarray, rng: np.random.Generator, fx: float, sensor: DepthSensor,
                 albedo: np.ndarray | float | None = None, principal_point: tuple | None = None) -> np.ndarray:
    """The depth image ``sensor`` measures of a z-buffer (see the module docstring).

    Args:
        zbuf: (H, W) camera depth (m), inf/NaN/<= 0 where nothing.
        rng: seeded generator (five images drawn per call, whatever the scene).
        fx: the rendered camera's focal length in pixels (fx = fy).
        sensor: a :class:`DepthSensor` (:data:`SENSORS`).
        albedo: near-infrared diffuse reflectance per pixel (H, W) or one value; None:
            :data:`DEFAULT_ALBEDO`.
        principal_point: (cx, cy); None: the image centre.

    Returns:
        uint16 (H, W) millimetres, 0 = no data.
    """
    z = np.asarray(zbuf, dtype=np.float64)
    if z.ndim != 2:
        raise ValueError(f"zbuf must be (H, W), got {z.shape}")
    if sensor.ideal:
        return depth_to_millimetres(z, sensor.min_depth, sensor.max_depth)
    h, w = z.shape
    if sensor.plain:
        return kinect_depth(z, rng, fx, KinectNoise(
            sigma_at_1m=sensor.disparity_sigma_px / (sensor.native_fx * sensor.baseline_m),
            disparity_step_px=sensor.disparity_step_px * w / PLAIN_WIDTH,
            baseline_m=sensor.baseline_m, min_depth=sensor.min_depth, max_depth=sensor.max_depth,
            edge_threshold=sensor.edge_threshold, edge_dropout=sensor.edge_dropout,
            dropout=sensor.dropout))
    cx, cy = ((w - 1) / 2.0, (h - 1) / 2.0) if principal_point is None else principal_point
    scale = fx / sensor.native_fx  # rendered pixels per sensor pixel
    white = rng.standard_normal(z.shape, dtype=np.float32)
    blobs = correlated_noise(rng, z.shape, sensor.speckle_px * scale)
    u_edge, u_return, u_drop = (rng.random(z.shape, dtype=np.float32) for _ in range(3))

    surface = np.isfinite(z) & (z > 0)
    shadow = projector_shadow(z, fx, sensor.baseline_m)
    zf, fattened = fatten_edges(z, sensor.fattening_px * scale, sensor.edge_threshold)
    valid = (surface | fattened) & (~shadow | fattened)
    valid &= ~(depth_discontinuities(zf, sensor.edge_threshold) & (u_edge < sensor.edge_dropout))
    if sensor.min_return > 0:
        a = DEFAULT_ALBEDO if albedo is None else np.asarray(albedo, dtype=np.float32)
        signal = a * incidence_cosine(zf, fx, cx, cy)
        valid &= signal >= sensor.min_return * u_return
    valid &= u_drop >= sensor.dropout

    fb = sensor.native_fx * sensor.baseline_m
    noise = (np.float32(np.sqrt(1.0 - sensor.speckle_share)) * white
             + np.float32(np.sqrt(sensor.speckle_share)) * blobs)
    disparity = fb / np.where(valid, zf, 1.0) + sensor.disparity_sigma_px * noise
    if sensor.disparity_step_px > 0:
        disparity = np.rint(disparity / sensor.disparity_step_px) * sensor.disparity_step_px
    valid &= disparity > 0
    zn = fb / np.where(valid, disparity, 1.0)
    valid &= (zn >= sensor.min_depth) & (zn <= sensor.max_depth)
    return np.clip(np.where(valid, np.rint(zn * 1000.0), 0.0), 0, 65535).astype(np.uint16)
