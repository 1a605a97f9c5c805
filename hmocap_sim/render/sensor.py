"""Camera sensor and illumination effects on rendered 8-bit RGB frames.

Helpers that make synthetic frames behave like real ones for the foreground segmentation
(thesis sec. 2.4): signal-dependent sensor noise, global and spatially varying illumination
changes, vignetting, and anti-aliasing by supersampling. Randomness only through an explicit
``numpy.random.Generator``; the same seed gives the same bytes.
"""

from __future__ import annotations

import cv2
import numpy as np


def add_sensor_noise(rgb: np.ndarray, rng: np.random.Generator, *, read_sigma: float = 1.5,
                     shot_gain: float = 0.04) -> np.ndarray:
    """Add Poisson-Gaussian sensor noise: per pixel and channel a normal deviate with variance
    ``read_sigma^2 + shot_gain * I`` (in 8-bit digital numbers, ``I`` the clean value), then
    round and clip. Returns a new uint8 image."""
    img = np.asarray(rgb, dtype=np.float32)
    sigma = np.sqrt(np.float32(read_sigma) ** 2 + np.float32(shot_gain) * img)
    noisy = img + sigma * rng.standard_normal(img.shape, dtype=np.float32)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def apply_illumination(rgb: np.ndarray, gain=1.0, *, offset: float = 0.0,
                       gradient=(0.0, 0.0)) -> np.ndarray:
    """Change the illumination of an image (lights dimmed, clouds, auto exposure):
    ``out = I * gain * (1 + gx * (x / W - 0.5) + gy * (y / H - 0.5)) + offset``, applied to the
    linear (gamma-decoded) intensities. ``gain`` is a scalar or per-channel (3,) (colour
    temperature change); ``gradient`` a linear ramp across the image (light from one side)."""
    img = np.asarray(rgb, dtype=np.float32) / 255.0
    lin = img ** 2.2
    h, w = lin.shape[:2]
    gx, gy = gradient
    ramp = (1.0 + gx * (np.arange(w, dtype=np.float32) / w - 0.5)[None, :]
            + gy * (np.arange(h, dtype=np.float32) / h - 0.5)[:, None])
    lin = lin * np.asarray(gain, dtype=np.float32) * ramp[..., None] + np.float32(offset)
    out = np.clip(lin, 0.0, 1.0) ** (1.0 / 2.2)
    return np.clip(np.rint(out * 255.0), 0, 255).astype(np.uint8)


def random_illumination(rgb: np.ndarray, rng: np.random.Generator, *, gain_sigma: float = 0.08,
                        colour_sigma: float = 0.02, gradient_sigma: float = 0.1) -> np.ndarray:
    """:func:`apply_illumination` with a random global gain, colour cast and gradient."""
    gain = (1.0 + gain_sigma * rng.standard_normal()) * (1.0 + colour_sigma
                                                         * rng.standard_normal(3))
    gradient = tuple(gradient_sigma * rng.standard_normal(2))
    return apply_illumination(rgb, np.maximum(gain, 0.0), gradient=gradient)


def vignette(rgb: np.ndarray, strength: float = 0.3) -> np.ndarray:
    """Darken towards the corners: gain ``1 - strength * (r / r_corner)^2`` in linear light."""
    img = np.asarray(rgb, dtype=np.float32) / 255.0
    h, w = img.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    r2 = ((xx - (w - 1) / 2) ** 2 + (yy - (h - 1) / 2) ** 2) / (((w - 1) / 2) ** 2
                                                               + ((h - 1) / 2) ** 2)
    lin = img ** 2.2 * (1.0 - strength * r2)[..., None]
    return np.clip(np.rint(np.clip(lin, 0, 1) ** (1 / 2.2) * 255.0), 0, 255).astype(np.uint8)


def downsample(image: np.ndarray, factor: int) -> np.ndarray:
    """Box-filter an image rendered at ``factor`` times the output size (supersampling
    anti-aliasing; a real lens and sensor never give jagged edges)."""
    h, w = image.shape[:2]
    if h % factor or w % factor:
        raise ValueError(f"image size {w}x{h} is not a multiple of {factor}")
    return cv2.resize(image, (w // factor, h // factor), interpolation=cv2.INTER_AREA)


def downsample_mask(mask: np.ndarray, factor: int) -> np.ndarray:
    """Ground-truth mask at the output size from a supersampled one: a pixel is foreground
    when at least half of its sub-pixels are. Returns uint8 0/1."""
    h, w = mask.shape
    m = (np.asarray(mask) != 0).reshape(h // factor, factor, w // factor, factor)
    return (m.mean(axis=(1, 3)) >= 0.5).astype(np.uint8)
