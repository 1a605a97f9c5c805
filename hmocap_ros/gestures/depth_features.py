"""Depth binary tests of the gesture forest (thesis sec. 3.2.2, eq. 3.3; sec. 3.2.5, eq. 3.6).

For a reference pixel ``x`` with depth ``d = d_I(x)`` and a test ``(u, v)`` (two offsets in
pixel*metres, i.e. pixels at 1 m):

    plain    (eq. 3.3)  f = d_I(x + u/d) - d_I(x + v/d)
    clipped  (eq. 3.6)  f = c(d_I(x + u/d)) - c(d_I(x + v/d)),  c(z) = max(min(z, d + kappa), d - kappa)

Dividing the offsets by ``d`` makes the test see the same part of an object at any distance;
clipping makes everything further than ``kappa`` behind (or in front of) the reference pixel
read the same, so the forest cannot learn the clutter behind the gestures of its training set.

Depth convention (all kernels): images are float32 metres as made by :func:`depth_to_metres`,
in which every invalid pixel (no depth, NaN, out of the sensor range) holds the constant
``background_depth_m`` (default 10 m, beyond any valid depth). A probe that falls on such a
pixel reads that constant: "far background", which with clipping is ``d + kappa`` like any real
clutter. A probe outside the image reads the nearest pixel of the image
(``FeatureParams.outside = "border"``: the scene goes on beyond the frame, so a person cut by the
image edge does not look like a hand-sized object in front of far background) or, with
``"background"`` (forest files of version 1), the background constant. Reference pixels are the
valid ones (``d < background``). Probe coordinates are rounded to the nearest pixel.

Training frame stacks may instead be compact uint16 millimetres with 0 = invalid
(:func:`depth_to_millimetres`, half the memory of metres for the thousands of 640x480 frames of
a training set): the kernels read a pixel through :func:`pixel_metres`, which gives the very
float32 that :func:`depth_to_metres` gives for that millimetre value, so training and
detection see the same numbers.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numba import types
from numba.extending import overload

from hmocap_ros.gestures.params import DepthFormat, FeatureParams

__all__ = ["depth_to_metres", "depth_to_millimetres", "evaluate_tests", "evaluate_tests_at_pixels", "pixel_metres",
           "random_offsets", "stack_metres", "valid_mask"]

#: Metres per unit of a compact (uint16 millimetre) training frame, as a float32.
MM = np.float32(0.001)


def depth_to_metres(depth: np.ndarray, fmt: DepthFormat, background_depth_m: float) -> np.ndarray:
    """Raw depth image (any unit, any numeric dtype) -> float32 metres, invalid = ``background_depth_m``.

    Invalid: equal to ``fmt.invalid_value``, NaN/inf, or outside ``[min_depth_m, max_depth_m]``.
    Raises ``ValueError`` for an image that is not 2-D and numeric.
    """
    depth = np.asarray(depth)
    if depth.ndim != 2 or not (np.issubdtype(depth.dtype, np.integer) or np.issubdtype(depth.dtype, np.floating)):
        raise ValueError(f"depth image must be a 2-D numeric array, got shape {depth.shape} dtype {depth.dtype}")
    if fmt.max_depth_m >= background_depth_m:
        raise ValueError("max_depth_m must be below background_depth_m")
    unit = np.float32(fmt.unit_for(depth.dtype))
    metres = depth.astype(np.float32)
    bad = metres == np.float32(fmt.invalid_value) if np.isfinite(fmt.invalid_value) else None
    metres *= unit
    with np.errstate(invalid="ignore"):
        # NaN fails both comparisons: one expression catches NaN and out-of-range.
        out = ~((metres >= np.float32(fmt.min_depth_m)) & (metres <= np.float32(fmt.max_depth_m)))
    if bad is not None:
        out |= bad
    metres[out] = np.float32(background_depth_m)
    return metres


def depth_to_millimetres(depth: np.ndarray, fmt: DepthFormat, background_depth_m: float) -> np.ndarray:
    """Raw depth image -> compact uint16 millimetres, 0 = invalid (as :func:`depth_to_metres`).

    Depths are rounded to the millimetre (exact for 16UC1 millimetre images); a sensor range
    beyond 65.535 m is refused."""
    if fmt.max_depth_m > 65.535:
        raise ValueError("uint16 millimetres cannot hold depths beyond 65.535 m")
    metres = depth_to_metres(depth, fmt, background_depth_m)
    mm = np.rint(metres * np.float32(1000.0))
    mm[metres >= np.float32(background_depth_m)] = 0
    return mm.astype(np.uint16)


def stack_metres(frame: np.ndarray, background_depth_m: float | np.floating) -> np.ndarray:
    """One frame of a training stack (float32 metres or uint16 mm) as float32 metres."""
    if frame.dtype == np.uint16:
        out = frame.astype(np.float32) * MM
        out[frame == 0] = np.float32(background_depth_m)
        return out
    return frame


def check_stack(frames: np.ndarray) -> np.ndarray:
    """A frame stack the kernels take: C-contiguous (F, H, W) float32 metres or uint16 mm."""
    frames = np.asarray(frames)
    if frames.ndim == 2:
        frames = frames[None]
    if frames.dtype != np.uint16:
        frames = frames.astype(np.float32, copy=False)
    return np.ascontiguousarray(frames)


def pixel_metres(v, background):
    """A pixel of a frame stack in metres (float32 metres as they are; uint16 mm converted)."""
    return v


@overload(pixel_metres)
def _pixel_metres(v, background):
    if isinstance(v, types.Integer):
        def impl(v, background):
            return background if v == 0 else np.float32(v) * np.float32(0.001)
    else:
        def impl(v, background):
            return v
    return impl


def valid_mask(depth_m: np.ndarray, background_depth_m: float) -> np.ndarray:
    """Pixels of a :func:`depth_to_metres` image that can be reference pixels."""
    return depth_m < np.float32(background_depth_m)


def random_offsets(rng: np.random.Generator, n: int, params: FeatureParams) -> np.ndarray:
    """``n`` random tests (u_x, u_y, v_x, v_y) in pixel*metres, uniform in the patch square.

    Python-side counterpart of the in-kernel draws of the offline trainer, for callers that
    keep their own candidate tests (the online forest, alg. 6).
    """
    r = np.float32(params.patch_half_size_px_m)
    return rng.uniform(-r, r, size=(int(n), 4)).astype(np.float32)


@nb.njit(inline="always")
def probe_index(coord, ofs, inv_d, size):
    """``floor(coord + ofs / d + 0.5)`` clamped to ``[-1, size]`` (-1 and ``size`` mean outside).

    Clamping before rounding keeps the float -> int conversion in range for any offset, and
    truncating the clamped value plus one is the floor without a floor instruction; the
    detection kernel uses the same arithmetic (plus one, on its padded image), so training and
    detection read the same pixels bit for bit.
    """
    t = min(max(coord + ofs * inv_d + 0.5, -1.0), size + 0.5)
    return int(t + 1.0) - 1


@nb.njit(inline="always")
def probe(img, x, y, ox, oy, inv_d, background, border):
    """Depth at ``(x, y) + (ox, oy) / d``, rounded; outside the image the nearest border pixel
    (``border``) or ``background``."""
    h, w = img.shape
    px = probe_index(x, ox, inv_d, w)
    py = probe_index(y, oy, inv_d, h)
    if border:
        return pixel_metres(img[min(max(py, 0), h - 1), min(max(px, 0), w - 1)], background)
    if px < 0 or py < 0 or px >= w or py >= h:
        return background
    return pixel_metres(img[py, px], background)


@nb.njit(inline="always")
def test_value(img, x, y, d, inv_d, ux, uy, vx, vy, clipped, kappa, background, border):
    """Eq. 3.3 (``clipped`` false) or eq. 3.6 at reference pixel ``(x, y)`` of depth ``d``."""
    a = probe(img, x, y, ux, uy, inv_d, background, border)
    b = probe(img, x, y, vx, vy, inv_d, background, border)
    if clipped:
        lo = d - kappa
        hi = d + kappa
        a = max(min(a, hi), lo)
        b = max(min(b, hi), lo)
    return a - b


@nb.njit(cache=True, nogil=True)
def _evaluate_tests(frames, s_frame, s_x, s_y, offsets, clipped, kappa, background, border, out):
    for i in range(s_frame.shape[0]):
        img = frames[s_frame[i]]
        x = np.float64(s_x[i])
        y = np.float64(s_y[i])
        d = pixel_metres(img[s_y[i], s_x[i]], np.float32(background))
        inv_d = 1.0 / np.float64(d)
        for t in range(offsets.shape[0]):
            out[i, t] = test_value(img, x, y, d, inv_d, offsets[t, 0], offsets[t, 1],
                                   offsets[t, 2], offsets[t, 3], clipped, np.float32(kappa),
                                   np.float32(background), border)


def evaluate_tests(frames: np.ndarray, s_frame, s_x, s_y, offsets: np.ndarray,
                   params: FeatureParams) -> np.ndarray:
    """Feature matrix (S, T) float32: ``T`` tests at ``S`` sample pixels of a frame stack.

    ``frames`` (F, H, W) float32 metres (:func:`depth_to_metres`) or uint16 mm
    (:func:`depth_to_millimetres`); sample ``i`` is pixel ``(s_x[i], s_y[i])`` (column, row) of
    frame ``s_frame[i]`` and must be valid; ``offsets`` (T, 4) pixel*metres.
    """
    frames = check_stack(frames)
    s_frame = np.ascontiguousarray(s_frame, dtype=np.int32)
    s_x = np.ascontiguousarray(s_x, dtype=np.int32)
    s_y = np.ascontiguousarray(s_y, dtype=np.int32)
    offsets = np.ascontiguousarray(offsets, dtype=np.float32).reshape(-1, 4)
    out = np.empty((s_frame.shape[0], offsets.shape[0]), np.float32)
    _evaluate_tests(frames, s_frame, s_x, s_y, offsets, params.clipped, params.kappa_m,
                    params.background_depth_m, params.border, out)
    return out


def evaluate_tests_at_pixels(depth_m: np.ndarray, xs, ys, offsets: np.ndarray,
                             params: FeatureParams) -> np.ndarray:
    """:func:`evaluate_tests` on one image: feature matrix (S, T) at pixels ``(xs, ys)``."""
    xs = np.asarray(xs)
    return evaluate_tests(depth_m, np.zeros(xs.shape[0], np.int32), xs, ys, offsets, params)
