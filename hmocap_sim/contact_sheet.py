"""PNG contact sheets: a grid of frames (rows) x views (columns) with ground-truth overlays.

Shared by the simulators (multi-view RGB here, depth gestures elsewhere) so every generated
bag comes with a picture that shows at a glance what is in it and whether the ground truth
fits: each :class:`Tile` is an image plus optional overlays drawn after scaling the tile to
the sheet's tile width (so they stay crisp on small images):

- ``mask``: a ground-truth mask drawn as its outline;
- ``points`` + ``parents``: a projected skeleton (joints as dots, bones as lines to the parent
  joint, -1 for none); ``point_valid`` hides points that are not visible;
- ``boxes``: ``(x0, y0, x1, y1, label)`` rectangles (e.g. gesture locations);
- ``label``: a caption in the tile's corner.

    sheet = contact_sheet([[Tile(img, mask=sil, points=uv, parents=parents, label="cam_1")]],
                          row_labels=["t = 1.20 s"], title="13_26, seed 0")
    save_png("run.contact.png", sheet)

Images may be RGB uint8, grey uint8, or float/uint16 depth (use :func:`colorize_depth`
first for a colour map with invalid pixels in black).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

__all__ = ["Tile", "contact_sheet", "colorize_depth", "save_png", "draw_skeleton",
           "draw_mask_outline"]

MASK_COLOUR = (255, 220, 0)
BONE_COLOUR = (0, 255, 120)
JOINT_COLOUR = (255, 40, 40)
BOX_COLOUR = (0, 200, 255)
TEXT_COLOUR = (255, 255, 255)


@dataclass(frozen=True, eq=False)
class Tile:
    """One image of the sheet with its overlays (coordinates in the image's own pixels)."""

    image: np.ndarray
    mask: np.ndarray | None = None
    points: np.ndarray | None = None
    parents: Sequence[int] | None = None
    point_valid: np.ndarray | None = None
    boxes: Sequence[tuple] = field(default_factory=tuple)
    label: str | None = None


def colorize_depth(depth: np.ndarray, max_value: float | None = None,
                   colormap: int = cv2.COLORMAP_TURBO) -> np.ndarray:
    """RGB uint8 picture of a depth image (any unit); zero / non-finite pixels are black."""
    d = np.asarray(depth, dtype=np.float32)
    valid = np.isfinite(d) & (d > 0)
    top = float(max_value) if max_value else (float(d[valid].max()) if valid.any() else 1.0)
    scaled = np.zeros(d.shape, np.uint8)
    scaled[valid] = np.clip(d[valid] / max(top, 1e-9) * 255.0, 0, 255).astype(np.uint8)
    rgb = cv2.applyColorMap(scaled, colormap)[..., ::-1].copy()
    rgb[~valid] = 0
    return rgb


def _as_rgb(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.dtype != np.uint8:
        return colorize_depth(img)
    if img.ndim == 2:
        return np.repeat(img[..., None], 3, axis=2)
    if img.ndim == 3 and img.shape[2] == 1:
        return np.repeat(img, 3, axis=2)
    return img.copy()


def draw_mask_outline(image: np.ndarray, mask: np.ndarray, colour=MASK_COLOUR,
                      thickness: int = 1) -> None:
    """Draw the outline of a binary mask (already at the image's size) onto an RGB image."""
    m = (np.asarray(mask) != 0).astype(np.uint8)
    contours, _ = cv2.findContours(m, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(image, contours, -1, colour, thickness, cv2.LINE_AA)


def draw_skeleton(image: np.ndarray, points: np.ndarray, parents: Sequence[int] | None = None,
                  valid: np.ndarray | None = None, *, radius: int = 2, thickness: int = 1,
                  bone_colour=BONE_COLOUR, joint_colour=JOINT_COLOUR) -> None:
    """Draw joints (dots) and bones (lines to the parent) onto an RGB image in place."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    ok = np.isfinite(pts).all(axis=1)
    if valid is not None:
        ok &= np.asarray(valid, bool).reshape(-1)
    shift = 4  # sub-pixel drawing
    ip = np.round(np.nan_to_num(pts) * (1 << shift)).astype(np.int64)
    if parents is not None:
        for j, p in enumerate(parents):
            if p is not None and 0 <= p < len(pts) and ok[j] and ok[p]:
                cv2.line(image, tuple(ip[j]), tuple(ip[p]), bone_colour, thickness, cv2.LINE_AA,
                         shift)
    for j in np.flatnonzero(ok):
        cv2.circle(image, tuple(ip[j]), radius << shift, joint_colour, -1, cv2.LINE_AA, shift)


def _render_tile(tile: Tile, width: int) -> np.ndarray:
    img = _as_rgb(tile.image)
    h, w = img.shape[:2]
    scale = width / w
    height = max(1, int(round(h * scale)))
    out = cv2.resize(img, (width, height),
                     interpolation=cv2.INTER_NEAREST if scale >= 2 else cv2.INTER_AREA)
    thick = 1 if width < 480 else 2
    if tile.mask is not None:
        m = cv2.resize((np.asarray(tile.mask) != 0).astype(np.uint8), (width, height),
                       interpolation=cv2.INTER_NEAREST)
        draw_mask_outline(out, m, thickness=thick)
    if tile.points is not None:
        # Pixel centres at integer coordinates: u' = (u + 0.5) s - 0.5.
        pts = (np.asarray(tile.points, float) + 0.5) * scale - 0.5
        draw_skeleton(out, pts, tile.parents, tile.point_valid, radius=max(2, thick + 1),
                      thickness=thick)
    for box in tile.boxes:
        x0, y0, x1, y1 = ((np.asarray(box[:4], float) + 0.5) * scale - 0.5).round().astype(int)
        cv2.rectangle(out, (x0, y0), (x1, y1), BOX_COLOUR, thick, cv2.LINE_AA)
        if len(box) > 4 and box[4]:
            _text(out, str(box[4]), (x0 + 2, max(y0 - 4, 12)), 0.4, BOX_COLOUR)
    if tile.label:
        _text(out, tile.label, (5, 16), 0.45)
    return out


def _text(img, text, org, scale=0.45, colour=TEXT_COLOUR):
    # A dark halo of shifted copies (a thicker stroke would also widen the glyph advances).
    x, y = org
    for dx, dy in ((-1, -1), (-1, 1), (1, -1), (1, 1), (0, 1), (1, 0)):
        cv2.putText(img, text, (x + dx, y + dy), cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 1,
                    cv2.LINE_AA)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, colour, 1, cv2.LINE_AA)


def contact_sheet(rows: Sequence[Sequence[Tile]], *, tile_width: int | None = None,
                  row_labels: Sequence[str] | None = None, title: str | None = None,
                  gap: int = 4, background=(24, 24, 24)) -> np.ndarray:
    """Assemble rows of tiles into one RGB uint8 image.

    Args:
        rows: tiles per row (rows may have different lengths; missing cells stay empty).
        tile_width: width of every tile in the sheet; default: the first image's width, at
            least 320 px (small images are enlarged, nearest-neighbour, before overlays).
        row_labels: a caption per row, drawn at the row's left.
        title: a line of text above the grid.
        gap: pixels between tiles.
    """
    rows = [list(r) for r in rows if len(r)]
    if not rows:
        raise ValueError("a contact sheet needs at least one tile")
    if tile_width is None:
        tile_width = max(320, int(np.asarray(rows[0][0].image).shape[1]))
    rendered = [[_render_tile(t, tile_width) for t in r] for r in rows]
    n_cols = max(len(r) for r in rendered)
    row_h = [max(t.shape[0] for t in r) for r in rendered]
    label_w = 0
    if row_labels:
        label_w = 10 + max(cv2.getTextSize(s, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)[0][0]
                           for s in row_labels)
    title_h = 28 if title else 0
    width = label_w + n_cols * tile_width + (n_cols + 1) * gap
    height = title_h + sum(row_h) + (len(rows) + 1) * gap
    sheet = np.empty((height, width, 3), np.uint8)
    sheet[:] = background
    if title:
        _text(sheet, title, (gap + 2, 19), 0.55)
    y = title_h + gap
    for i, (r, h) in enumerate(zip(rendered, row_h)):
        if row_labels and i < len(row_labels):
            _text(sheet, row_labels[i], (6, y + h // 2 + 5), 0.5)
        x = label_w + gap
        for t in r:
            sheet[y:y + t.shape[0], x:x + t.shape[1]] = t
            x += tile_width + gap
        y += h + gap
    return sheet


def save_png(path: str | Path, rgb: np.ndarray) -> Path:
    """Write an RGB uint8 image as PNG (creating the folder); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), np.ascontiguousarray(np.asarray(rgb)[..., ::-1]),
                       [cv2.IMWRITE_PNG_COMPRESSION, 9]):
        raise OSError(f"cannot write {path}")
    return path
