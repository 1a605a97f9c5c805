"""Per-pixel skin probability: the image-based extremity detector of thesis sec. 2.5.1.

The thesis fuses the output of "a simple yet effective image-based hand detector", the skin
detector of Jones and Rehg [65], over the views (eq. 2.17); like it, this detector finds hands
and the face alike (left/right and head are told apart later, in 3D). Jones and Rehg learn
skin and non-skin RGB histograms from labelled web images; we have no labelled skin pixels,
so we use the parametric form of the same idea that the skin-detection literature reports as
nearly as good: a single Gaussian in the chrominance plane (Cb, Cr) of YCbCr, where skin of
every tone clusters tightly (Chai and Ngan's box Cb 77-127, Cr 133-173 is the usual rule):

    T(p) = exp(-0.5 * d^2(p)),  d^2 = Mahalanobis distance of (Cb, Cr) of pixel p to the mean

Choices (the thesis names the detector, not its settings): mean and spread put the centre of
the Chai-Ngan box at d = 0 and its edges at about 2 standard deviations; pixels darker than
``min_luma`` get probability 0 (their chrominance is noise); the map is computed at
``scale`` of the image (area averaging first: hands are a few pixels wide at 0.5 of 640x480)
and returned as uint8 (255 = 1.0).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["SkinParams", "skin_probability"]


@dataclass(frozen=True)
class SkinParams:
    """Skin colour model in YCbCr (8-bit units, OpenCV's full-range conversion)."""

    mean_cb: float = 102.0
    mean_cr: float = 153.0
    std_cb: float = 12.5
    std_cr: float = 10.0
    min_luma: float = 35.0
    scale: float = 0.5


def skin_probability(rgb: np.ndarray, params: SkinParams | None = None,
                     mask: np.ndarray | None = None) -> np.ndarray:
    """Skin probability map (uint8, 0-255) of an RGB image (H, W, 3) uint8.

    The map has the size of the image times ``params.scale`` (rounded). ``mask`` (H, W), if
    given, zeroes the probability outside the foreground (the fusion of eq. 2.17 only reads
    pixels inside the silhouettes anyway; zeroing makes the topic easy to look at).
    """
    p = params or SkinParams()
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f"skin_probability expects an (H, W, 3) uint8 RGB image, got "
                         f"{rgb.shape} {rgb.dtype}")
    h, w = rgb.shape[:2]
    out_w, out_h = max(1, int(round(w * p.scale))), max(1, int(round(h * p.scale)))
    small = rgb if (out_w, out_h) == (w, h) else cv2.resize(rgb, (out_w, out_h),
                                                            interpolation=cv2.INTER_AREA)
    ycrcb = cv2.cvtColor(small, cv2.COLOR_RGB2YCrCb).astype(np.float32)
    dcr = (ycrcb[..., 1] - p.mean_cr) / p.std_cr
    dcb = (ycrcb[..., 2] - p.mean_cb) / p.std_cb
    prob = np.exp(-0.5 * (dcr * dcr + dcb * dcb))
    prob[ycrcb[..., 0] < p.min_luma] = 0.0
    if mask is not None:
        if mask.shape[:2] != (h, w):
            raise ValueError(f"mask is {mask.shape[1]}x{mask.shape[0]}, image {w}x{h}")
        m = mask if (out_w, out_h) == (w, h) else cv2.resize(
            (mask > 0).astype(np.uint8), (out_w, out_h), interpolation=cv2.INTER_NEAREST)
        prob[m == 0] = 0.0
    return np.round(prob * 255.0).astype(np.uint8)
