"""Procedural prints of the furnished room (posters, whiteboard, clock face, rug) and the
texture atlas that holds them; :data:`ATLAS_PRINTS` lists them in the order they are drawn."""

from __future__ import annotations

import math

import cv2
import numpy as np

ATLAS_CELLS = 4  # the atlas is ATLAS_CELLS x ATLAS_CELLS square cells
ATLAS_CELL_PX = 256


class Atlas:
    """A square float32 sRGB atlas of ``ATLAS_CELLS^2`` cells; :meth:`add` returns the uv
    rectangle of a cell (with a half-texel inset so bilinear lookups stay inside)."""

    def __init__(self) -> None:
        n = ATLAS_CELLS * ATLAS_CELL_PX
        self.image = np.ones((n, n, 3), np.float32)
        self._next = 0

    def add(self, image: np.ndarray, aspect: float = 1.0) -> tuple:
        """Store ``image`` (uint8 RGB, any size) in the next cell; return its uv rectangle."""
        if self._next >= ATLAS_CELLS * ATLAS_CELLS:
            raise ValueError("texture atlas is full")
        row, col = divmod(self._next, ATLAS_CELLS)
        self._next += 1
        px = ATLAS_CELL_PX
        cell = cv2.resize(image, (px, px), interpolation=cv2.INTER_AREA)
        self.image[row * px:(row + 1) * px, col * px:(col + 1) * px] = cell / 255.0
        n = float(ATLAS_CELLS * px)
        inset = 1.0 / n
        return (col * px / n + inset, row * px / n + inset,
                (col + 1) * px / n - inset, (row + 1) * px / n - inset)


def _poster_circles(rng, size=(360, 256)) -> np.ndarray:
    """Abstract print: overlapping coloured discs on a light ground."""
    h, w = size
    ground = rng.choice([(236, 232, 220), (245, 240, 232), (40, 44, 52), (226, 222, 210)])
    img = np.zeros((h, w, 3), np.uint8)
    img[:] = ground
    palette = [(72, 52, 120), (38, 120, 60), (200, 120, 140), (110, 90, 200), (60, 180, 170),
               (220, 170, 60), (190, 70, 50), (40, 90, 150)]
    for _ in range(int(rng.integers(6, 11))):
        c = palette[int(rng.integers(len(palette)))]
        centre = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        cv2.circle(img, centre, int(rng.integers(w // 10, w // 4)), c, -1, cv2.LINE_AA)
    return img


def _poster_landscape(rng, size=(256, 360)) -> np.ndarray:
    """A simple landscape print: sky gradient, sun, layered hills."""
    h, w = size
    y = np.linspace(0, 1, h)[:, None, None]
    top = np.array(rng.choice([(120, 170, 220), (235, 160, 120), (150, 190, 230)]), float)
    bottom = np.array([235, 230, 215], float)
    img = (top + (bottom - top) * y).repeat(w, axis=1).astype(np.uint8)
    cv2.circle(img, (int(w * rng.uniform(0.2, 0.8)), int(h * 0.3)), h // 10, (250, 240, 200), -1,
               cv2.LINE_AA)
    greens = [(90, 130, 80), (60, 100, 60), (40, 70, 45)]
    for k, g in enumerate(greens):
        base = h * (0.55 + 0.15 * k)
        xs = np.arange(0, w + 8, 8)
        ys = base - h * 0.08 * np.sin(xs / w * math.pi * (1.5 + k) + rng.uniform(0, 6))
        pts = np.concatenate([np.stack([xs, ys], 1), [[w, h], [0, h]]]).astype(np.int32)
        cv2.fillPoly(img, [pts], g, cv2.LINE_AA)
    return img


def _whiteboard(rng, size=(256, 360)) -> np.ndarray:
    """A used whiteboard: rows of handwriting-like strokes and a boxed sketch."""
    h, w = size
    img = np.full((h, w, 3), 246, np.uint8)
    colours = [(30, 60, 170), (20, 20, 20), (170, 40, 40), (30, 120, 60)]
    y = int(h * 0.12)
    while y < h * 0.85:
        x0 = int(w * rng.uniform(0.06, 0.3))
        x1 = int(w * rng.uniform(0.55, 0.94))
        c = colours[int(rng.integers(len(colours)))]
        xs = np.linspace(x0, x1, 24)
        ys = y + 2.0 * np.sin(xs * 0.3 + rng.uniform(0, 6))
        cv2.polylines(img, [np.stack([xs, ys], 1).astype(np.int32)], False, c, 2, cv2.LINE_AA)
        y += int(h * rng.uniform(0.08, 0.14))
    cv2.rectangle(img, (int(w * 0.62), int(h * 0.55)), (int(w * 0.9), int(h * 0.85)),
                  colours[0], 2, cv2.LINE_AA)
    return img


def _clock_face(rng=None, size=256) -> np.ndarray:
    """A wall clock's face: rim, hour marks and two hands; it is fixed, ``rng`` is not used."""
    img = np.full((size, size, 3), 250, np.uint8)
    c = size // 2
    cv2.circle(img, (c, c), c - 2, (30, 30, 30), 10, cv2.LINE_AA)
    for k in range(12):
        a = k * math.pi / 6
        p0 = (int(c + 0.78 * c * math.sin(a)), int(c - 0.78 * c * math.cos(a)))
        p1 = (int(c + 0.9 * c * math.sin(a)), int(c - 0.9 * c * math.cos(a)))
        cv2.line(img, p0, p1, (30, 30, 30), 6, cv2.LINE_AA)
    cv2.line(img, (c, c), (int(c + 0.45 * c), int(c - 0.2 * c)), (20, 20, 20), 8, cv2.LINE_AA)
    cv2.line(img, (c, c), (int(c - 0.15 * c), int(c - 0.7 * c)), (20, 20, 20), 5, cv2.LINE_AA)
    return img


def _rug(rng, size=256) -> np.ndarray:
    """A patterned rug: border bands and a diamond lattice."""
    base = np.array(rng.choice([(150, 50, 45), (60, 70, 120), (90, 100, 80)]), float)
    img = np.zeros((size, size, 3), np.uint8)
    img[:] = base
    light = tuple(int(x) for x in np.clip(base * 1.8 + 30, 0, 255))
    dark = tuple(int(x) for x in base * 0.5)
    for k, col in enumerate((light, dark, light)):
        m = 10 + 12 * k
        cv2.rectangle(img, (m, m), (size - m, size - m), col, 4)
    for i in range(-size, 2 * size, 40):
        cv2.line(img, (i, 46), (i + size, 46 + size), dark, 3, cv2.LINE_AA)
        cv2.line(img, (i, 46 + size), (i + size, 46), dark, 3, cv2.LINE_AA)
    img[:46] = cv2.resize(img[46:92], (size, 46))
    return img


#: The atlas prints in the order they are drawn from the room's generator: name -> print(rng).
ATLAS_PRINTS = {
    "poster1": _poster_circles,
    "poster2": _poster_landscape,
    "poster3": _poster_circles,
    "whiteboard": _whiteboard,
    "clock": _clock_face,
    "rug": _rug,
}
