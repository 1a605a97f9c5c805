"""Per-pixel single-Gaussian background model with shadow and illumination handling.

The silhouettes of thesis sec. 2.4 come from "a single-Gaussian version of the algorithm
proposed by Xu et al. [128]" (Xu, Landabaso, Pardas, ICASSP 2005: background subtraction,
chromatic shadow removal in the manner of Horprasert et al., morphological error correction).
Per camera and pixel ``p`` the background is a Gaussian with mean ``mu_p`` and diagonal
variance ``s2_p`` over the three colour channels (any channel order), learned from the first
``learn_frames`` frames (Welford) and then kept up to date. For a frame ``I`` with global gain
``g`` (illumination change, below):

    (1) d2_p = sum_c (I_pc - g mu_pc)^2 / s2_pc               background iff d2_p <= k_sigma^2
    (2) a_p  = <I_p, mu_p> / <mu_p, mu_p>                      brightness distortion
    (3) cd_p = || I_p - a_p mu_p ||                            chromaticity distortion
    (4) shadow iff  tau_low <= a_p / g < tau_high  and
                    cd_p^2 <= (tau_c a_p |mu_p|)^2 + k_c^2 (2/3) sum_c s2_pc
        highlight iff  tau_high <= a_p / g <= tau_hl  and the same chromaticity test
    (5) foreground = not background and not shadow and not highlight

(4) is Horprasert's test with the chromaticity distortion measured as an angle (scale-free, so
the same threshold fits bright and dark surfaces) plus a sensor-noise allowance; like
Horprasert's "highlighted background", a pixel a little brighter than the gain-scaled
background along its colour is background too: light sources do not all change together (the
lamp dims, the daylight through a window does not), so one global gain leaves surfaces lit by
the other source brighter or darker than predicted. ``shadow_mask`` marks shadows and
highlights.

Illumination change: ``g`` is the median of ``a_p`` over a sparse grid of pixels that were
background in the previous frame (all grid pixels when too few were), so a sudden global
brightening or dimming (lights, camera auto-exposure) scales the model instead of flooding the
mask. The model itself keeps tracking the scene (6), so ``g`` returns to 1 as it adapts.

Adaptation, per frame with rate ``rho`` (``learning_rate``), only at background pixels that
were not foreground in the previous (cleaned) mask:

    (6) mu <- mu + rho (I - mu),   s2 <- clip(s2 + rho ((I - g mu)^2 - s2), min_sigma^2, max_sigma^2)

(the variance learns the residual after the gain, so a global change does not inflate it).
A pixel that is not background for ``absorb_frames`` consecutive frames (a moved object, a new
persistent shadow) has its mean pulled to the new colour with ``absorb_rate`` until it matches.

The raw per-pixel mask is then cleaned (:mod:`hmocap_ros.segmentation.mask_cleanup`).
Classification and update run in one fused numba pass (no temporaries, ``nogil`` so several
cameras can run in threads).
"""

from __future__ import annotations

import dataclasses

import numba as nb
import numpy as np

from hmocap_ros.segmentation.mask_cleanup import clean_mask, structuring_element
from hmocap_ros.segmentation.params import ForegroundParams

__all__ = ["GAIN_RANGE", "BackgroundModel", "ForegroundParams", "check_frame", "check_stamp",
           "classify_and_update", "compile_background_kernels", "estimate_gain", "learn_step"]

#: Background colours with a smaller squared norm (about 8 levels per channel) are too dark
#: for a brightness ratio to mean anything: no shadow and no gain sample there.
_MIN_MEAN_NORM2 = np.float32(192.0)
#: the camera gain estimate (frame brightness over the background's) is clipped to this range
GAIN_RANGE = (0.25, 4.0)
_COUNT_MAX = np.iinfo(np.uint16).max


@nb.njit(cache=True, nogil=True, fastmath=True)
def learn_step(frame, n, mean, m2):
    """Add frame number ``n`` (1-based) to the running mean and sum of squared deviations (Welford)."""
    inv_n = np.float32(1.0) / np.float32(n)
    h, w, nc = frame.shape
    for y in range(h):
        for x in range(w):
            for c in range(nc):
                v = np.float32(frame[y, x, c])
                d = v - mean[y, x, c]
                mean[y, x, c] += d * inv_n
                m2[y, x, c] += d * (v - mean[y, x, c])


@nb.njit(cache=True, nogil=True)
def estimate_gain(frame, mean, prev_raw, prev_shadow, step, buf):
    """Global illumination gain: median brightness ratio (eq. 2) on a ``step`` grid.

    Uses the grid pixels that were background (neither foreground nor shadow) in the previous
    frame; when they are fewer than a tenth of the grid, all grid pixels. ``buf`` is float32
    scratch of at least the grid size. Returns 1.0 when nothing is usable.
    """
    h, w, _ = frame.shape
    off = step // 2
    for use_all in (False, True):
        n = 0
        total = 0
        for y in range(off, h, step):
            for x in range(off, w, step):
                total += 1
                if not use_all and (prev_raw[y, x] != 0 or prev_shadow[y, x] != 0):
                    continue
                m0 = mean[y, x, 0]
                m1 = mean[y, x, 1]
                m2 = mean[y, x, 2]
                mm = m0 * m0 + m1 * m1 + m2 * m2
                if mm < _MIN_MEAN_NORM2:
                    continue
                dot = (np.float32(frame[y, x, 0]) * m0 + np.float32(frame[y, x, 1]) * m1
                       + np.float32(frame[y, x, 2]) * m2)
                buf[n] = dot / mm
                n += 1
        if n * 10 >= total:
            break
    if n == 0:
        return 1.0
    return float(np.median(buf[:n]))


@nb.njit(cache=True, nogil=True, fastmath=True)
def classify_and_update(frame, mean, var, fg_count, prev_mask, gain, k2, min_var, max_var,
                        shadow, tau_low, tau_high, tau_highlight, chroma_tan2, chroma_noise2,
                        rate, absorb_frames, absorb_rate, raw_out, shadow_out):
    """One fused pass: eqs. (1)-(5) per pixel into ``raw_out``/``shadow_out`` (0/255; shadow or
    highlight), then the
    update (6) and the absorption of persistent changes, in place on ``mean``/``var``/``fg_count``.

    ``prev_mask`` (cleaned mask of the previous frame, 0/255) blocks the update inside the
    foreground. ``var`` is kept clipped to ``[min_var, max_var]``.
    """
    h, w, _ = frame.shape
    g = np.float32(gain)
    inv_g = np.float32(1.0) / g
    third2 = np.float32(2.0 / 3.0)
    for y in range(h):
        for x in range(w):
            i0 = np.float32(frame[y, x, 0])
            i1 = np.float32(frame[y, x, 1])
            i2 = np.float32(frame[y, x, 2])
            m0 = mean[y, x, 0]
            m1 = mean[y, x, 1]
            m2 = mean[y, x, 2]
            v0 = var[y, x, 0]
            v1 = var[y, x, 1]
            v2 = var[y, x, 2]
            e0 = i0 - g * m0
            e1 = i1 - g * m1
            e2 = i2 - g * m2
            d2 = e0 * e0 / v0 + e1 * e1 / v1 + e2 * e2 / v2
            is_bg = d2 <= k2
            is_shadow = False
            if not is_bg and shadow:
                mm = m0 * m0 + m1 * m1 + m2 * m2
                if mm >= _MIN_MEAN_NORM2:
                    a = (i0 * m0 + i1 * m1 + i2 * m2) / mm
                    ratio = a * inv_g
                    if ratio >= tau_low and (ratio < tau_high or ratio <= tau_highlight):
                        p0 = i0 - a * m0
                        p1 = i1 - a * m1
                        p2 = i2 - a * m2
                        perp2 = p0 * p0 + p1 * p1 + p2 * p2
                        allowed = chroma_tan2 * a * a * mm + chroma_noise2 * third2 * (v0 + v1 + v2)
                        is_shadow = perp2 <= allowed
            raw_out[y, x] = 0 if (is_bg or is_shadow) else 255
            shadow_out[y, x] = 255 if is_shadow else 0
            if is_bg:
                fg_count[y, x] = 0
                if rate > 0.0 and prev_mask[y, x] == 0:
                    mean[y, x, 0] = m0 + rate * (i0 - m0)
                    mean[y, x, 1] = m1 + rate * (i1 - m1)
                    mean[y, x, 2] = m2 + rate * (i2 - m2)
                    var[y, x, 0] = min(max(v0 + rate * (e0 * e0 - v0), min_var), max_var)
                    var[y, x, 1] = min(max(v1 + rate * (e1 * e1 - v1), min_var), max_var)
                    var[y, x, 2] = min(max(v2 + rate * (e2 * e2 - v2), min_var), max_var)
            else:
                count = fg_count[y, x]
                if count < _COUNT_MAX:
                    count += 1
                    fg_count[y, x] = count
                if absorb_frames > 0 and count >= absorb_frames:
                    mean[y, x, 0] = m0 + absorb_rate * (i0 - m0)
                    mean[y, x, 1] = m1 + absorb_rate * (i1 - m1)
                    mean[y, x, 2] = m2 + absorb_rate * (i2 - m2)


def check_stamp(stamp_ns) -> int:
    """The stamp as an int; ValueError unless it is an integer number of nanoseconds."""
    if isinstance(stamp_ns, (bool, np.bool_)) or not isinstance(stamp_ns, (int, np.integer)):
        raise ValueError(f"stamp_ns must be an integer number of nanoseconds, got {type(stamp_ns).__name__}")
    return int(stamp_ns)


def check_frame(rgb, shape) -> np.ndarray:
    """The frame, checked to be a non-empty (H, W, 3) uint8 image of the model's ``shape`` (None:
    any); ValueError naming what is wrong."""
    if not isinstance(rgb, np.ndarray):
        raise ValueError(f"frame must be a numpy array, got {type(rgb).__name__}")
    if rgb.dtype != np.uint8:
        raise ValueError(f"frame must be uint8, got {rgb.dtype}")
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"frame must be a (H, W, 3) colour image, got shape {rgb.shape}")
    if rgb.shape[0] < 1 or rgb.shape[1] < 1:
        raise ValueError(f"frame is empty: shape {rgb.shape}")
    if shape is not None and rgb.shape[:2] != shape:
        raise ValueError(f"frame is {rgb.shape[1]}x{rgb.shape[0]} but the background model is "
                         f"{shape[1]}x{shape[0]}; call relearn() to start over at the new size")
    return np.ascontiguousarray(rgb)


class BackgroundModel:
    """Foreground segmentation of one camera (thesis sec. 2.4, Xu et al. [128]); see the module doc.

    ``apply(frame, stamp_ns)`` takes a uint8 (H, W, 3) colour frame and its stamp and returns the
    cleaned foreground mask, uint8 (H, W) with 0 / 255. While the model is learning (the first
    ``params.learn_frames`` frames, again after :meth:`relearn`) the mask is all zeros.

    State after each call: ``frames_learned``, ``is_learning``, ``gain`` (global illumination
    gain of the last frame against the model), ``last_stamp_ns``, ``shape`` (H, W), ``mean`` /
    ``variance`` (float32 (H, W, 3), the background as adapted so far; ``variance`` holds the
    sum of squared deviations while learning), and the last
    frame's ``raw_mask`` (before clean-up) and ``shadow_mask`` (0/255). The arrays are the
    model's own buffers, overwritten by the next call: copy them to keep them.
    """

    def __init__(self, params: ForegroundParams | None = None):
        self.params = params if params is not None else ForegroundParams()
        p = self.params
        self._opening = structuring_element(p.opening_size)
        self._closing = structuring_element(p.closing_size)
        self._k2 = np.float32(p.k_sigma ** 2)
        self._min_var = np.float32(p.min_sigma ** 2)
        self._max_var = np.float32(p.max_sigma ** 2)
        self.relearn()

    def relearn(self) -> None:
        """Forget the background and the last stamp: the next ``learn_frames`` frames (of any
        size, any stamps) learn it anew."""
        self.shape: tuple[int, int] | None = None
        self.last_stamp_ns: int | None = None
        self.frames_learned = 0
        self.gain = 1.0
        self.mean: np.ndarray | None = None
        self.variance: np.ndarray | None = None
        self.raw_mask: np.ndarray | None = None
        self.shadow_mask: np.ndarray | None = None
        self._fg_count: np.ndarray | None = None
        self._mask: np.ndarray | None = None
        self._gain_buf: np.ndarray | None = None

    @property
    def is_learning(self) -> bool:
        return self.frames_learned < self.params.learn_frames

    def apply(self, rgb: np.ndarray, stamp_ns: int) -> np.ndarray:
        """Segment one frame (and learn from it); returns the uint8 0/255 foreground mask.

        Raises ValueError, leaving the model unchanged, for a frame that is not uint8 (H, W, 3),
        has another size than the learned background, or a stamp older than the last one.
        """
        stamp = check_stamp(stamp_ns)
        frame = check_frame(rgb, self.shape)
        if self.last_stamp_ns is not None and stamp < self.last_stamp_ns:
            raise ValueError(f"stamp {stamp} is older than the previous frame's {self.last_stamp_ns}; "
                             "call relearn() if the stream restarted")
        self.last_stamp_ns = stamp
        if self.shape is None:
            self._allocate(frame.shape[:2])
        if self.is_learning:
            return self._learn(frame)
        return self._segment(frame)

    def _allocate(self, shape: tuple[int, int]) -> None:
        h, w = shape
        self.shape = (h, w)
        self.mean = np.zeros((h, w, 3), np.float32)
        self.variance = np.zeros((h, w, 3), np.float32)
        self.raw_mask = np.zeros((h, w), np.uint8)
        self.shadow_mask = np.zeros((h, w), np.uint8)
        self._fg_count = np.zeros((h, w), np.uint16)
        self._mask = np.zeros((h, w), np.uint8)
        step = self.params.gain_sample_step
        self._gain_buf = np.empty(((h + step - 1) // step) * ((w + step - 1) // step), np.float32)

    def _learn(self, frame: np.ndarray) -> np.ndarray:
        assert self.variance is not None and self.shape is not None  # allocated by the first frame
        self.frames_learned += 1
        learn_step(frame, self.frames_learned, self.mean, self.variance)
        if not self.is_learning:
            # variance held the sum of squared deviations while learning
            self.variance /= np.float32(self.frames_learned)
            np.clip(self.variance, self._min_var, self._max_var, out=self.variance)
        return np.zeros(self.shape, np.uint8)

    def _segment(self, frame: np.ndarray) -> np.ndarray:
        p = self.params
        if p.illumination_compensation:
            gain = estimate_gain(frame, self.mean, self.raw_mask, self.shadow_mask,
                                 p.gain_sample_step, self._gain_buf)
            self.gain = float(min(max(gain, GAIN_RANGE[0]), GAIN_RANGE[1]))
        classify_and_update(
            frame, self.mean, self.variance, self._fg_count, self._mask, np.float32(self.gain),
            self._k2, self._min_var, self._max_var, p.shadow_suppression,
            np.float32(p.shadow_min_brightness), np.float32(p.shadow_max_brightness),
            np.float32(p.highlight_max_brightness), np.float32(p.shadow_max_chroma ** 2),
            np.float32(p.shadow_chroma_sigma ** 2),
            np.float32(p.learning_rate), p.absorb_frames, np.float32(p.absorb_rate),
            self.raw_mask, self.shadow_mask)
        assert self.raw_mask is not None  # allocated by the first frame
        self._mask = clean_mask(self.raw_mask, self._opening, self._closing, p.min_blob_area, p.max_hole_area)
        return self._mask.copy()


def compile_background_kernels(params: ForegroundParams | None = None) -> None:
    """Compile (or load from numba's cache) every kernel :class:`BackgroundModel` calls, now
    (:func:`hmocap_ros.segmentation.compile_kernels` adds those of the person-masked model).

    numba compiles a kernel on its first call. On a fresh checkout (no cache yet) that is
    seconds per kernel, and the clean-up kernels run only once a mask holds a small blob or
    an enclosed hole, i.e. on the first frames with a person: a live node would stall there
    and drop the frames that arrive meanwhile. This runs a tiny synthetic sequence that takes
    every branch (learning, gain, classification with shadow test, small blob removed, hole
    filled) with the argument types of ``params`` (defaults if None).
    """
    base = params if params is not None else ForegroundParams()
    p = dataclasses.replace(base, learn_frames=2, opening_size=0, closing_size=0,
                            min_blob_area=8, max_hole_area=16)
    model = BackgroundModel(p)
    frame = np.full((32, 32, 3), 120, np.uint8)
    frame[::2, ::2] = 124  # some texture, so the variance is not all zero
    model.apply(frame, 0)
    model.apply(frame, 1)
    scene = frame.copy()
    scene[8:24, 8:24] = (230, 40, 40)   # a blob with an enclosed hole ...
    scene[14:17, 14:17] = frame[14:17, 14:17]
    scene[2:4, 28:30] = (20, 200, 20)   # ... a speck below min_blob_area ...
    scene[26:30, 2:8] = 60              # ... and a shadow-like darker patch
    model.apply(scene, 2)
    model.apply(scene, 3)
