"""Pictures of what the room saw: the tracked skeleton over every camera, gestures over depth.

Plain numpy and OpenCV, no rclpy, no bags: :mod:`hmocap_ros.viz.overlay_bag` reads a bag into
the frames drawn here and writes the video. One picture per frame set:

- **Multi-view** (:func:`multiview_picture`): each camera's image, scaled to ``tile_width``, with
  every tracked body's skeleton projected through the camera (its own lens distortion,
  :meth:`PinholeCamera.project <hmocap_ros.geometry.pinhole_camera.PinholeCamera.project>`): bones as
  lines, joints as dots. With ground truth each joint is coloured by its 3D error
  (:func:`error_colours`: green at 0, yellow at half of :data:`ERROR_SCALE_MM`, red from it on)
  and the true skeleton is drawn thin in white beneath; without, the joints too have their
  body's colour. Each body's bones have its colour (:data:`BODY_COLOURS`, by the body's index, as
  the skeleton markers) and its id is written above its head in that colour. The labelled
  extremities (the detector's 3D head, hands, feet and the keypoint joints) are small magenta
  crosses. The views are tiled in a grid (:func:`tile`) under a banner with the stamp, the bodies
  and the mean error, and a legend: each body id in its colour, the truth, the extremities, and
  the joint error scale.
- **Depth** (:func:`depth_picture`): the depth image false-coloured (near warm, far cold), each
  detected gesture a box centred on its pixel, sized as a hand at its depth, with its name and
  score; true gestures as white boxes.

Pixel centres are at integer coordinates (a pixel ``u`` of the image is ``(u + 0.5) s - 0.5``
at scale ``s``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import cast

import cv2
import numpy as np

from hmocap_ros.gestures.trainer_feedback import colour_depth

__all__ = ["BODY_COLOURS", "ERROR_SCALE_MM", "Banner", "BodyDrawing", "DepthGesture", "body_colour", "camera_tile",
           "depth_picture", "error_colours", "multiview_picture", "tile"]

#: Joint error (mm) drawn red; 0 is green, half of it yellow.
ERROR_SCALE_MM = 150.0
#: RGB colour of each body when there is no ground truth, in turn (as the skeleton markers).
BODY_COLOURS = ((255, 77, 0), (51, 230, 51), (255, 204, 26), (77, 128, 255))
TRUTH_COLOUR = (255, 255, 255)
EXTREMITY_COLOUR = (255, 0, 255)
GESTURE_COLOUR = (0, 255, 0)
#: Half side (m) of a gesture's box: a hand, whatever its depth.
GESTURE_HALF_SIZE_M = 0.12


@dataclass
class BodyDrawing:
    """One body to draw: its id, 3D joints (J, 3) in the rig's room frame, the parent of each
    joint (-1 for the root), optionally each joint's error in mm (J,) (NaN: unknown), and its
    index into :data:`BODY_COLOURS` (None: its place among the bodies drawn)."""

    body_id: str
    joints: np.ndarray
    parents: Sequence[int]
    errors_mm: np.ndarray | None = None
    colour_index: int | None = None


@dataclass
class DepthGesture:
    """A gesture on the depth image: its pixel, name, score (None for a true one) and depth (m,
    0 when unknown)."""

    u: float
    v: float
    name: str
    score: float | None = None
    depth_m: float = 0.0


@dataclass
class Banner:
    """The text above a picture: one line, and a second (optional) with figures; ``legend``: the
    joint error scale; ``keys``: ``(RGB colour, what it marks)`` pairs drawn as a legend below."""

    title: str
    detail: str = ""
    legend: bool = False
    extra: list = field(default_factory=list)
    keys: list = field(default_factory=list)


def error_colours(errors_mm) -> np.ndarray:
    """RGB uint8 (N, 3) of joint errors in mm: green (0) -> yellow (:data:`ERROR_SCALE_MM` / 2)
    -> red (:data:`ERROR_SCALE_MM` and more); grey where the error is unknown (NaN)."""
    e = np.asarray(errors_mm, np.float64)
    t = np.clip(np.nan_to_num(e, nan=0.0) / ERROR_SCALE_MM, 0.0, 1.0)
    red = np.clip(2.0 * t, 0.0, 1.0)
    green = np.clip(2.0 - 2.0 * t, 0.0, 1.0)
    out = np.stack([red, green, np.zeros_like(t)], axis=-1) * 255.0
    out[~np.isfinite(e)] = 160.0
    return out.round().astype(np.uint8)


def _rgb(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    if img.dtype != np.uint8:
        img = np.clip(img, 0, 255).astype(np.uint8)
    return np.ascontiguousarray(img[:, :, :3])


def _text(img: np.ndarray, text: str, org, scale: float, colour=(255, 255, 255)) -> None:
    thick = max(1, int(round(scale * 2)))
    org = (int(org[0]), int(org[1]))
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), thick + 2, cv2.LINE_AA)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, tuple(int(c) for c in colour), thick, cv2.LINE_AA)


SHIFT = 4  # sub-pixel drawing: coordinates in 1/16 pixel


def _fixed(points: np.ndarray) -> np.ndarray:
    return np.round(np.nan_to_num(points) * (1 << SHIFT)).astype(np.int64)


def _draw_skeleton(img: np.ndarray, pixels: np.ndarray, ok: np.ndarray, parents: Sequence[int],
                   joint_colours: np.ndarray, bone_colour, radius: int, thickness: int) -> None:
    ip = _fixed(pixels)
    for j, p in enumerate(parents):
        if 0 <= p < len(ip) and ok[j] and ok[p]:
            cv2.line(img, tuple(ip[p]), tuple(ip[j]), tuple(int(c) for c in bone_colour), thickness, cv2.LINE_AA, SHIFT)
    for k in np.flatnonzero(ok):
        cv2.circle(img, tuple(ip[k]), radius << SHIFT, tuple(int(c) for c in joint_colours[k]), -1, cv2.LINE_AA, SHIFT)


def _project(camera, points: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (N, 2) of room points at the tile's scale, and which are in front of the camera
    and near the image (a bone may leave the image, a point far outside is not drawn)."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    finite = cast(np.ndarray, np.isfinite(points).all(axis=1))  # (N,): all() over one axis of a 2-D array
    pixels, depth = camera.project(np.where(finite[:, None], points, 0.0))
    margin = 0.5 * max(camera.width, camera.height)
    near = ((pixels[:, 0] > -margin) & (pixels[:, 0] < camera.width + margin)
            & (pixels[:, 1] > -margin) & (pixels[:, 1] < camera.height + margin))
    ok = finite & (depth > 0.05) & near & np.isfinite(pixels).all(axis=1)
    return (pixels + 0.5) * scale - 0.5, ok


def body_colour(body: BodyDrawing, place: int) -> tuple[int, int, int]:
    """The RGB colour of ``body``, the ``place``-th body drawn: :data:`BODY_COLOURS` by its
    ``colour_index``, else by ``place``."""
    index = place if body.colour_index is None else body.colour_index
    return BODY_COLOURS[index % len(BODY_COLOURS)]


def _label_body(img: np.ndarray, body_id: str, pixels: np.ndarray, ok: np.ndarray, colour, scale: float,
                gap: int) -> None:
    """``body_id`` in ``colour`` ``gap`` pixels above the body's highest joint in the picture
    (the head's centre: the gap clears the top of the head)."""
    if not ok.any():
        return
    top = pixels[ok][np.argmin(pixels[ok][:, 1])]
    (w, h), _ = cv2.getTextSize(body_id, cv2.FONT_HERSHEY_SIMPLEX, scale, max(1, int(round(scale * 2))))
    x = float(np.clip(top[0] - w / 2, 0, img.shape[1] - w))
    y = float(np.clip(top[1] - gap, h + 2, img.shape[0] - 2))
    _text(img, body_id, (x, y), scale, colour)


def camera_tile(camera, image: np.ndarray | None, bodies: Sequence[BodyDrawing], truth: BodyDrawing | None,
                extremities: tuple[Sequence[str], np.ndarray] | None, tile_width: int) -> np.ndarray:
    """One camera's image at ``tile_width`` with the bodies, the truth and the extremities drawn
    (module docstring); a dark tile saying so where the frame set has no image of it."""
    scale = tile_width / camera.width
    height = int(round(camera.height * scale))
    if image is None:
        out: np.ndarray = np.full((height, tile_width, 3), 40, np.uint8)
        _text(out, "no image", (tile_width // 3, height // 2), max(0.4, tile_width / 800))
    else:
        out = cv2.resize(_rgb(image), (tile_width, height),
                         interpolation=cv2.INTER_NEAREST if scale >= 2 else cv2.INTER_AREA)
    thick = max(1, tile_width // 240)
    radius = max(2, tile_width // 120)
    if truth is not None:
        pixels, ok = _project(camera, truth.joints, scale)
        _draw_skeleton(out, pixels, ok, truth.parents, np.full((len(pixels), 3), TRUTH_COLOUR), TRUTH_COLOUR,
                       max(1, radius // 2), 1)
    for k, body in enumerate(bodies):
        pixels, ok = _project(camera, body.joints, scale)
        colour = body_colour(body, k)
        joint_colours = (error_colours(body.errors_mm) if body.errors_mm is not None
                         else np.tile(np.asarray(colour, np.uint8), (len(pixels), 1)))
        _draw_skeleton(out, pixels, ok, body.parents, joint_colours, colour, radius, thick)
        _label_body(out, body.body_id, pixels, ok, colour, max(0.35, tile_width / 900), 6 * radius)
    if extremities is not None:
        labels, positions = extremities
        pixels, ok = _project(camera, positions, scale)
        size = radius + 3
        for (u, v), good in zip(pixels, ok):
            if good:
                cv2.drawMarker(out, (int(round(u)), int(round(v))), EXTREMITY_COLOUR, cv2.MARKER_TILTED_CROSS,
                               size, 1, cv2.LINE_AA)
    _text(out, camera.name, (4, 4 + int(14 * max(0.4, tile_width / 800) / 0.4)), max(0.4, tile_width / 800))
    return out


def tile(images: Sequence[np.ndarray], columns: int | None = None) -> np.ndarray:
    """The images (all of one width) in a grid, row by row (``columns`` default: the smallest
    square that holds them); rows padded to the tallest image, the last row with black."""
    if not images:
        raise ValueError("nothing to tile")
    columns = columns or int(np.ceil(np.sqrt(len(images))))
    width = images[0].shape[1]
    height = max(im.shape[0] for im in images)
    rows = int(np.ceil(len(images) / columns))
    out = np.zeros((rows * height, columns * width, 3), np.uint8)
    for k, im in enumerate(images):
        r, c = divmod(k, columns)
        out[r * height:r * height + im.shape[0], c * width:(c + 1) * width] = im
    return out


def _key_rows(width: int, keys: Sequence, scale: float, swatch: int) -> list[list[tuple[int, tuple, str]]]:
    """The legend's keys placed in rows that fit ``width``: (x, colour, label) each."""
    rows: list[list[tuple[int, tuple, str]]] = [[]]
    x = 6
    for colour, label in keys:
        (text_w, _), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, scale, max(1, int(round(scale * 2))))
        step = swatch + 4 + text_w + 12
        if rows[-1] and x + step > width:
            rows.append([])
            x = 6
        rows[-1].append((x, tuple(int(c) for c in colour), label))
        x += step
    return rows if rows[0] else []


def _banner(width: int, banner: Banner) -> np.ndarray:
    scale = max(0.45, width / 1600)
    line = int(round(26 * scale / 0.5))
    lines = [banner.title] + ([banner.detail] if banner.detail else []) + list(banner.extra)
    key_scale = scale * 0.8
    swatch = max(6, line // 2)
    key_rows = _key_rows(width, banner.keys, key_scale, swatch)
    out = np.zeros((line * (len(lines) + len(key_rows)) + line // 2, width, 3), np.uint8)
    for k, text in enumerate(lines):
        _text(out, text, (6, line * (k + 1) - line // 4), scale)
    for r, row in enumerate(key_rows):
        base = line * (len(lines) + r + 1) - line // 4
        for x, colour, label in row:
            out[base - swatch:base, x:x + swatch] = colour
            _text(out, label, (x + swatch + 4, base), key_scale)
    if banner.legend:  # the error scale, right-aligned on the first line
        bar = np.linspace(0.0, ERROR_SCALE_MM, 101)
        w = min(width // 4, 300)
        colours = error_colours(bar)
        x0 = width - w - 8
        h = max(6, line // 3)
        strip = cv2.resize(colours[None], (w, h), interpolation=cv2.INTER_LINEAR)
        out[line // 3:line // 3 + h, x0:x0 + w] = strip
        label = "joint error  0"
        (label_w, _), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, scale * 0.8, max(1, int(round(scale * 1.6))))
        _text(out, label, (x0 - label_w - 6, line // 3 + h), scale * 0.8)
        _text(out, f"{ERROR_SCALE_MM:.0f} mm", (x0 + w - int(70 * scale / 0.45), line // 3 + h + line * 2 // 3),
              scale * 0.8)
    return out


def multiview_picture(cameras: Sequence, images: Sequence[np.ndarray | None], bodies: Sequence[BodyDrawing],
                      banner: Banner, truth: BodyDrawing | None = None,
                      extremities: tuple[Sequence[str], np.ndarray] | None = None,
                      tile_width: int = 480) -> np.ndarray:
    """(H, W, 3) uint8 RGB: every camera's tile (:func:`camera_tile`), tiled, under the banner."""
    tiles = [camera_tile(cam, img, bodies, truth, extremities, tile_width) for cam, img in zip(cameras, images)]
    grid = tile(tiles)
    return np.vstack([_banner(grid.shape[1], banner), grid])


def depth_picture(depth_m: np.ndarray, gestures: Sequence[DepthGesture], truth: Sequence[DepthGesture],
                  banner: Banner, fx: float | None = None, width: int = 640) -> np.ndarray:
    """(H, W, 3) uint8 RGB: the depth image false-coloured at ``width``, true gestures as white
    boxes, detected ones as green boxes with name and score, under the banner. ``fx``: the
    depth camera's focal length (px) to size the boxes (default: the image width, ~53 deg)."""
    h, w = depth_m.shape
    scale = width / w
    out = cv2.resize(colour_depth(depth_m), (width, int(round(h * scale))), interpolation=cv2.INTER_NEAREST)
    fx = fx or float(w)
    text_scale = max(0.4, width / 1100)
    thick = max(1, width // 320)
    for gestures_of, colour in ((truth, TRUTH_COLOUR), (gestures, GESTURE_COLOUR)):
        for g in gestures_of:
            depth = g.depth_m if g.depth_m > 0 else 1.5
            half = GESTURE_HALF_SIZE_M * fx / depth * scale
            u, v = (g.u + 0.5) * scale - 0.5, (g.v + 0.5) * scale - 0.5
            top_left = (int(round(u - half)), int(round(v - half)))
            bottom_right = (int(round(u + half)), int(round(v + half)))
            cv2.rectangle(out, top_left, bottom_right, colour, thick, cv2.LINE_AA)
            label = g.name if g.score is None else f"{g.name} {g.score:.2f}"
            y = v - half - 4 if g.score is not None else v + half + int(16 * text_scale / 0.4)
            _text(out, label, (u - half, max(12, y)), text_scale, colour)
    return np.vstack([_banner(out.shape[1], banner), out])
