"""Scanline coverage of one screen-space triangle, shared by every rasteriser here.

Pixel convention (OpenCV): pixel ``(x, y)`` has its centre at the integer coordinates
``(x, y)``; a pixel is covered when its centre lies inside the triangle. Ties follow the
top-left rule, written as half-open intervals: a row ``y`` is covered for
``y_top <= y < y_bottom`` and, on that row, columns ``x_left <= x < x_right``. Two triangles
sharing an edge therefore never both cover (nor both miss) a pixel centre on that edge, and
the silhouette, z-buffer and reference rasterisers agree pixel for pixel.
"""

from __future__ import annotations

import math

import numba as nb


@nb.njit(cache=True, nogil=True)
def sort_by_y(ax, ay, bx, by, cx, cy):
    """Return the three vertices ordered by increasing y (top to bottom in the image)."""
    if ay > by:
        ax, ay, bx, by = bx, by, ax, ay
    if by > cy:
        bx, by, cx, cy = cx, cy, bx, by
    if ay > by:
        ax, ay, bx, by = bx, by, ax, ay
    return ax, ay, bx, by, cx, cy


@nb.njit(cache=True, nogil=True)
def row_range(ay, cy, y_min, y_max):
    """Rows ``[y0, y1)`` whose centres lie in ``[ay, cy)``, clipped to ``[y_min, y_max)``."""
    # Clamp in floating point first: converting a huge float to int is undefined.
    y0 = min(max(math.ceil(ay), y_min), y_max)
    y1 = min(max(math.ceil(cy), y_min), y_max)
    return int(y0), int(y1)


@nb.njit(cache=True, nogil=True)
def row_span(py, ax, ay, bx, by, cx, cy, x_min, x_max):
    """Columns ``[x0, x1)`` covered on row ``py`` of a y-sorted triangle, clipped.

    Must only be called for rows returned by :func:`row_range` (so ``ay <= py < cy``) and
    finite coordinates.
    """
    xl = ax + (py - ay) * (cx - ax) / (cy - ay)
    if py < by:
        xs = ax + (py - ay) * (bx - ax) / (by - ay)
    else:
        xs = bx + (py - by) * (cx - bx) / (cy - by)
    if xs < xl:
        xl, xs = xs, xl
    x0 = min(max(math.ceil(xl), x_min), x_max)
    x1 = min(max(math.ceil(xs), x_min), x_max)
    return int(x0), int(x1)
