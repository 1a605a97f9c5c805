"""A background model that needs no empty room: it learns each pixel where the person is not.

The model of :mod:`.background_model` learns the empty room from its first frames; in a
recording where somebody is in view from the first frame it learns that person into the
background. Here each pixel is learnt on its own, from the frames where it is free of the
person, and the landmark network's segmentation of the person (:class:`.person_masks.PersonMasks`)
stands in for the foreground where the pixel is not learnt yet:

1. **Person mask**: ``P`` = the network's probability above ``person_threshold``; ``G`` = ``P``
   grown by ``person_margin`` times the image's height (the network's outline is soft, and a
   pixel next to a moving limb is not yet steady) keeps pixels from being learnt; the network
   runs on a camera every ``person_period`` frames while the camera has pixels not learnt, and
   not at all once every pixel is (the last mask stands in between two runs).
2. **Learning** (:func:`learn_free_pixels`, per pixel not learnt yet): outside ``G`` the pixel's
   colour joins a running mean and variance (Welford); a colour farther than ``k_sigma`` of
   those from the mean (with the variance floored at ``(max_sigma / 2)^2``, so that sensor
   noise never breaks a run and a passing object does) starts the run over (a person the
   network does not mask walking through, a door, a flicker). After ``learn_frames`` steady
   samples the pixel is learnt: the run's mean and variance (within ``[min_sigma,
   max_sigma]``) become the background Gaussian. A pixel that has been free of the person for
   ``4 learn_frames`` frames without such a run is learnt from the longest run it had (the
   room between two passes of something moving), so that the network can stop.
3. **Classification**: learnt pixels go through the single-Gaussian model of
   :mod:`.background_model` (eq. 1-6 there: shadows, highlights, the global gain measured on
   learnt pixels only, slow adaptation, absorption); pixels not learnt take ``P``. The mask is
   then cleaned as there.

So a person standing still from the first frame is foreground from the first frame (the
network's outline), each pixel switches to background subtraction as soon as the person has
left it for ``learn_frames`` frames, and a room that is empty at the start behaves as the
empty-room model after ``learn_frames`` frames.
"""
from __future__ import annotations

import cv2
import numba as nb
import numpy as np

from hmocap_ros.segmentation.background_model import (
    GAIN_RANGE,
    check_frame,
    check_stamp,
    classify_and_update,
    estimate_gain,
)
from hmocap_ros.segmentation.mask_cleanup import clean_mask, structuring_element
from hmocap_ros.segmentation.params import ForegroundParams

__all__ = ["PersonMaskedBackground", "compile_learning", "learn_free_pixels"]

#: A pixel free of the person for this many times ``learn_frames`` frames without a steady run
#: is learnt from its longest run.
_UNSTEADY_FACTOR = 4
#: The standard deviation, as a share of ``max_sigma``, below which a run's variance does not
#: count when a new colour is tested against it.
_STEADY_SIGMA = 0.5


@nb.njit(cache=True, nogil=True, fastmath=True)
def learn_free_pixels(frame, occupied, count, age, acc_mean, acc_m2, best_count, best_mean,
                      best_m2, learnt, mean, var, fg_count, k2, steady_var, min_var, max_var,
                      n_learn, max_age):
    """Step 2 of the module docstring over every pixel not ``learnt``, in place: the running
    run (``count``, ``acc_mean``, ``acc_m2``), the longest run broken so far (``best_*``) and the
    frames free of the person (``age``). The mean of a pixel not learnt is kept at zero (it then
    takes no part in the global gain). Returns how many pixels remain not learnt."""
    h, w, nc = frame.shape
    remaining = 0
    for y in range(h):
        for x in range(w):
            if learnt[y, x]:
                continue
            if occupied[y, x] == 0:
                age[y, x] += 1
                n = count[y, x]
                if n >= 1:
                    d2 = np.float32(0.0)
                    for c in range(nc):
                        v = max(acc_m2[y, x, c] / np.float32(n), steady_var)
                        d = np.float32(frame[y, x, c]) - acc_mean[y, x, c]
                        d2 += d * d / v
                    if d2 > k2:  # the run is broken: keep it if it is the longest, start over
                        if n > best_count[y, x]:
                            best_count[y, x] = n
                            for c in range(nc):
                                best_mean[y, x, c] = acc_mean[y, x, c]
                                best_m2[y, x, c] = acc_m2[y, x, c]
                        n = 0
                        for c in range(nc):
                            acc_mean[y, x, c] = 0.0
                            acc_m2[y, x, c] = 0.0
                n += 1
                inv_n = np.float32(1.0) / np.float32(n)
                for c in range(nc):
                    v = np.float32(frame[y, x, c])
                    d = v - acc_mean[y, x, c]
                    acc_mean[y, x, c] += d * inv_n
                    acc_m2[y, x, c] += d * (v - acc_mean[y, x, c])
                count[y, x] = n
                if n >= n_learn or age[y, x] >= max_age:
                    learnt[y, x] = True
                    fg_count[y, x] = 0
                    use_best = best_count[y, x] > n
                    m = best_count[y, x] if use_best else n
                    for c in range(nc):
                        mu = best_mean[y, x, c] if use_best else acc_mean[y, x, c]
                        m2 = best_m2[y, x, c] if use_best else acc_m2[y, x, c]
                        mean[y, x, c] = mu
                        var[y, x, c] = min(max(m2 / np.float32(m), min_var), max_var)
                    continue
            for c in range(nc):
                mean[y, x, c] = 0.0
            remaining += 1
    return remaining


class PersonMaskedBackground:
    """Foreground of one camera without empty frames (module docstring); the interface of
    :class:`~hmocap_ros.segmentation.BackgroundModel` (``apply``, ``relearn``, ``shape``,
    ``is_learning``).

    ``masks``: a :class:`~.person_masks.PersonMasks` shared by several cameras (default: one
    of its own) and ``key``, this camera's key in it. ``learnt_fraction``: the share of pixels
    learnt; ``person``: the last person mask (0/255); ``network_runs``: frames the network
    ran on.
    """

    def __init__(self, params: ForegroundParams | None = None, masks=None, key=None):
        from hmocap_ros.segmentation.person_masks import PersonMasks

        self.params = params if params is not None else ForegroundParams()
        p = self.params
        self._masks = masks if masks is not None else PersonMasks()
        self._key = id(self) if key is None else key
        self._opening = structuring_element(p.opening_size)
        self._closing = structuring_element(p.closing_size)
        self._k2 = np.float32(p.k_sigma ** 2)
        self._min_var = np.float32(p.min_sigma ** 2)
        self._max_var = np.float32(p.max_sigma ** 2)
        self._steady_var = np.float32((_STEADY_SIGMA * p.max_sigma) ** 2)
        self.relearn()

    def relearn(self) -> None:
        """Forget the background: every pixel is learnt anew from the frames that come next."""
        self.shape: tuple[int, int] | None = None
        self.last_stamp_ns: int | None = None
        self.gain = 1.0
        self.frames = 0
        self.network_runs = 0
        self._remaining = 1
        self._since_run: int | None = None
        self.person: np.ndarray | None = None
        self._occupied: np.ndarray | None = None
        self._masks.reset(self._key)

    @property
    def learnt_fraction(self) -> float:
        return 0.0 if self.shape is None else float(self._learnt.mean())

    @property
    def is_learning(self) -> bool:
        """Whether some pixel still waits to be learnt."""
        return self.shape is None or self._remaining > 0

    def _allocate(self, shape: tuple[int, int]) -> None:
        h, w = shape
        self.shape = (h, w)
        self.mean = np.zeros((h, w, 3), np.float32)
        self.variance = np.full((h, w, 3), self._max_var, np.float32)
        self._acc_mean = np.zeros((h, w, 3), np.float32)
        self._acc_m2 = np.zeros((h, w, 3), np.float32)
        self._count = np.zeros((h, w), np.int32)
        self._best_count = np.zeros((h, w), np.int32)
        self._best_mean = np.zeros((h, w, 3), np.float32)
        self._best_m2 = np.zeros((h, w, 3), np.float32)
        self._age = np.zeros((h, w), np.int32)
        self._learnt = np.zeros((h, w), np.bool_)
        self._fg_count = np.zeros((h, w), np.uint16)
        self.raw_mask = np.zeros((h, w), np.uint8)
        self.shadow_mask = np.zeros((h, w), np.uint8)
        self._mask = np.zeros((h, w), np.uint8)
        self.person = np.zeros((h, w), np.uint8)
        self._occupied = np.zeros((h, w), np.uint8)
        self._margin = structuring_element(2 * int(round(self.params.person_margin * h)) + 1)
        step = self.params.gain_sample_step
        self._gain_buf = np.empty(((h + step - 1) // step) * ((w + step - 1) // step), np.float32)

    def _person(self, frame: np.ndarray) -> None:
        """This frame's person mask ``P`` and its grown ``G`` (step 1), from the network or its
        last run."""
        p = self.params
        if self._remaining > 0 and (self._since_run is None or self._since_run + 1 >= p.person_period):
            probability = self._masks.probability(self._key, frame)
            self._since_run = 0
            self.network_runs += 1
            assert self.shape is not None  # apply() allocates before it asks for the person
            self.person = np.zeros(self.shape, np.uint8)
            if probability is not None:
                self.person[probability > p.person_threshold] = 255
            self._occupied = (cv2.dilate(self.person, self._margin) if self._margin is not None
                              else self.person)
        elif self._since_run is not None:
            self._since_run += 1

    def apply(self, rgb: np.ndarray, stamp_ns: int) -> np.ndarray:
        """Segment one frame and learn from it; the uint8 0/255 foreground mask. ValueError,
        the model unchanged, for a frame that is not uint8 (H, W, 3), has another size than the
        model's, or a stamp older than the last one."""
        stamp = check_stamp(stamp_ns)
        frame = check_frame(rgb, self.shape)
        if self.last_stamp_ns is not None and stamp < self.last_stamp_ns:
            raise ValueError(f"stamp {stamp} is older than the previous frame's {self.last_stamp_ns}; "
                             "call relearn() if the stream restarted")
        self.last_stamp_ns = stamp
        if self.shape is None:
            self._allocate(frame.shape[:2])
        self.frames += 1
        p = self.params
        self._person(frame)
        self._remaining = learn_free_pixels(
            frame, self._occupied, self._count, self._age, self._acc_mean, self._acc_m2,
            self._best_count, self._best_mean, self._best_m2, self._learnt, self.mean,
            self.variance, self._fg_count, self._k2, self._steady_var, self._min_var,
            self._max_var, p.learn_frames, _UNSTEADY_FACTOR * p.learn_frames)
        if p.illumination_compensation:
            gain = estimate_gain(frame, self.mean, self.raw_mask, self.shadow_mask,
                                 p.gain_sample_step, self._gain_buf)
            self.gain = float(min(max(gain, GAIN_RANGE[0]), GAIN_RANGE[1]))
        classify_and_update(
            frame, self.mean, self.variance, self._fg_count, self._mask, np.float32(self.gain),
            self._k2, self._min_var, self._max_var, p.shadow_suppression,
            np.float32(p.shadow_min_brightness), np.float32(p.shadow_max_brightness),
            np.float32(p.highlight_max_brightness), np.float32(p.shadow_max_chroma ** 2),
            np.float32(p.shadow_chroma_sigma ** 2), np.float32(p.learning_rate), p.absorb_frames,
            np.float32(p.absorb_rate), self.raw_mask, self.shadow_mask)
        if self._remaining:
            assert self.person is not None  # set by _allocate
            unknown = ~self._learnt
            self.raw_mask[unknown] = self.person[unknown]
            self.shadow_mask[unknown] = 0
        self._mask = clean_mask(self.raw_mask, self._opening, self._closing, p.min_blob_area,
                                p.max_hole_area)
        return self._mask.copy()


def compile_learning() -> None:
    """Compile (or load from numba's cache) :func:`learn_free_pixels` now, on a tiny frame that
    takes its branches (a steady run learnt, a restart, an occupied pixel)."""
    h, w = 4, 4
    frame = np.full((h, w, 3), 100, np.uint8)
    occupied = np.zeros((h, w), np.uint8)
    occupied[0, 0] = 255
    counts = [np.zeros((h, w), np.int32) for _ in range(3)]
    sums = [np.zeros((h, w, 3), np.float32) for _ in range(4)]
    arrays = (counts[0], counts[1], sums[0], sums[1], counts[2], sums[2], sums[3],
              np.zeros((h, w), np.bool_), np.zeros((h, w, 3), np.float32),
              np.zeros((h, w, 3), np.float32), np.zeros((h, w), np.uint16))
    for value in (100, 100, 200, 100, 200):
        frame[1:] = value
        learn_free_pixels(frame, occupied, *arrays, np.float32(12.25), np.float32(225.0),
                          np.float32(9.0), np.float32(900.0), 3, 4)
