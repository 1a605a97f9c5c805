"""Kinect-like depth images (uint16 millimetres) from a rendered z-buffer.

A structured-light sensor (Kinect v1 style) measures disparity ``d = f b / z`` between its IR
camera and projector (focal length ``f`` in pixels, baseline ``b``). Modelled here:
- noise of constant standard deviation in disparity, i.e. depth noise growing as ``z^2``
  (default 1.5 mm at 1 m, 13.5 mm at 3 m), and subpixel disparity quantisation (1/8 pixel,
  depth steps of ~3 mm at 1 m, ~2.6 cm at 3 m);
- projector shadows: surfaces that the projector cannot see because a nearer object is in the
  way read 0 (a band on one side of every foreground object, of width
  ``f b (1/z_near - 1/z_far)`` pixels);
- holes at depth discontinuities and random dropouts;
- the working range (0 outside it); 0 means invalid, as in ROS 16UC1 depth images.
Randomness only through an explicit ``numpy.random.Generator``: same seed, same bytes.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class KinectNoise:
    """Parameters of :func:`kinect_depth`.

    sigma_at_1m: depth noise std (m) at 1 m; grows as z^2 (constant disparity noise).
    disparity_step_px: disparity quantisation in pixels of the depth image (1/8 for
        Kinect v1 at 640x480); 0 disables (then only millimetre rounding).
    baseline_m: projector-camera baseline (m); the projector is on the camera's +x side, so
        projector shadows fall on the left of objects. 0 disables projector shadows.
    min_depth, max_depth: working range (m); outside it reads 0.
    edge_threshold: a pixel is on a depth discontinuity when its 3x3 neighbourhood spans
        more than this fraction of its depth.
    edge_dropout: probability that a discontinuity pixel reads 0.
    dropout: probability that any pixel reads 0.
    """

    sigma_at_1m: float = 0.0015
    disparity_step_px: float = 0.125
    baseline_m: float = 0.075
    min_depth: float = 0.5
    max_depth: float = 4.5
    edge_threshold: float = 0.05
    edge_dropout: float = 0.6
    dropout: float = 0.002


def depth_to_millimetres(zbuf: np.ndarray, min_depth: float = 0.0,
                         max_depth: float = 65.535) -> np.ndarray:
    """Noise-free uint16 millimetres from a z-buffer in metres (0 where empty / out of range)."""
    z = np.asarray(zbuf, dtype=np.float64)
    valid = np.isfinite(z) & (z >= min_depth) & (z <= max_depth) & (z > 0)
    mm = np.where(valid, np.rint(np.where(valid, z, 0.0) * 1000.0), 0.0)
    return np.clip(mm, 0, 65535).astype(np.uint16)


def projector_shadow(zbuf: np.ndarray, fx: float, baseline_m: float,
                     tolerance_px: float = 0.5) -> np.ndarray:
    """Pixels the projector (``baseline_m`` to the camera's +x side, rectified) cannot
    illuminate. On each row, pixel ``u`` with depth ``z`` sits at projector column
    ``u - f b / z``; it is occluded when some pixel to its right maps to a column at least
    ``tolerance_px`` further left (a nearer surface on the same projector ray)."""
    z = np.asarray(zbuf, dtype=np.float64)
    valid = np.isfinite(z) & (z > 0)
    h, w = z.shape
    cols = np.arange(w, dtype=np.float64)[None, :]
    up = np.where(valid, cols - fx * baseline_m / np.where(valid, z, 1.0), np.inf)
    right_min = np.minimum.accumulate(up[:, ::-1], axis=1)[:, ::-1]
    right_min = np.concatenate([right_min[:, 1:], np.full((h, 1), np.inf)], axis=1)
    return valid & (right_min < up - tolerance_px)


def depth_discontinuities(zbuf: np.ndarray, threshold: float) -> np.ndarray:
    """Pixels whose 3x3 neighbourhood (empty pixels count as far away) spans more than
    ``threshold`` times their own depth."""
    z = np.asarray(zbuf, dtype=np.float32)
    zf = np.where(np.isfinite(z) & (z > 0), z, np.float32(1e3))
    kernel = np.ones((3, 3), np.uint8)
    spread = cv2.dilate(zf, kernel) - cv2.erode(zf, kernel)
    return spread > threshold * zf


def kinect_depth(zbuf: np.ndarray, rng: np.random.Generator, fx: float,
                 params: KinectNoise = KinectNoise()) -> np.ndarray:
    """Simulate a Kinect-like depth image from a z-buffer.

    Args:
        zbuf: camera depth (m) per pixel, inf/NaN/<=0 where nothing (from :func:`rasterize`).
        rng: seeded generator; always draws the same three images, so frames repeat.
        fx: the depth camera's focal length in pixels at this image size (~580 at 640x480).
        params: :class:`KinectNoise`.

    Returns:
        uint16 ``(H, W)`` depth in millimetres, 0 = invalid.
    """
    z = np.asarray(zbuf, dtype=np.float64)
    if z.ndim != 2:
        raise ValueError(f"zbuf must be (H, W), got {z.shape}")
    noise = rng.standard_normal(z.shape)
    u_edge = rng.random(z.shape)
    u_drop = rng.random(z.shape)
    valid = np.isfinite(z) & (z > 0)
    if params.baseline_m > 0:
        valid &= ~projector_shadow(z, fx, params.baseline_m)
    valid &= ~(depth_discontinuities(z, params.edge_threshold) & (u_edge < params.edge_dropout))
    valid &= u_drop >= params.dropout
    zs = np.where(valid, z, 1.0)
    # Disparity-like units: focal * baseline; any positive value works when no baseline is set.
    fb = fx * (params.baseline_m if params.baseline_m > 0 else 0.075)
    disparity = fb / zs + (params.sigma_at_1m * fb) * noise
    if params.disparity_step_px > 0:
        disparity = np.rint(disparity / params.disparity_step_px) * params.disparity_step_px
    valid &= disparity > 0
    zn = fb / np.where(valid, disparity, 1.0)
    valid &= (zn >= params.min_depth) & (zn <= params.max_depth)
    mm = np.where(valid, np.rint(zn * 1000.0), 0.0)
    return np.clip(mm, 0, 65535).astype(np.uint16)
