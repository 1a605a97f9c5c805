"""Images of a ChArUco board seen by a calibrated camera: the board texture warped through
the camera model (intrinsics and OpenCV distortion), over a plain textured background, with
sensor noise.

Every pixel is an inverse lookup: the pixel's ray (undistorted once per camera, at
``supersample`` x ``supersample`` sub-pixel positions) is intersected with the board plane and
the board texture is sampled there (bilinear); the sub-pixel samples are averaged, so edges
are anti-aliased and corners land where :func:`hmocap_ros.geometry.project_points` puts
them. Only the board's bounding box in the image is traced.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from hmocap_ros.calibration.board import BoardSpec

__all__ = ["BoardRenderer", "BoardLook"]

_PIXELS_PER_SQUARE = 120
_MARGIN_SQUARES = 0.3  # white plate around the printed squares


@dataclass(frozen=True)
class BoardLook:
    """Photometry: albedo of the white and black print, lighting, blur and noise (grey levels)."""

    white: float = 0.85
    black: float = 0.07
    back: float = 0.55  # the unprinted back of the plate
    ambient: float = 0.45
    diffuse: float = 0.55
    blur_sigma: float = 0.6
    noise_sigma: float = 2.0


class BoardRenderer:
    """Renders a board (``spec``) in the cameras of ``rig``; ``rng`` draws the backgrounds."""

    def __init__(self, rig, spec: BoardSpec, rng: np.random.Generator, supersample: int = 3,
                 look: BoardLook = BoardLook()):
        self.rig, self.spec, self.look, self.ss = rig, spec, look, int(supersample)
        pps = _PIXELS_PER_SQUARE
        margin = int(round(_MARGIN_SQUARES * pps))
        printed = spec.image(pps).astype(np.float32) / 255.0
        albedo = look.black + (look.white - look.black) * printed
        self.texture = cv2.copyMakeBorder(albedo, margin, margin, margin, margin,
                                          cv2.BORDER_CONSTANT, value=look.white)
        self.texels_per_metre = pps / spec.square
        self.texture_origin = margin  # texel of board coordinate 0
        w, h = spec.size_m
        m = _MARGIN_SQUARES * spec.square
        self.outline = _outline(-m, -m, w + m, h + m)
        self.rays = [self._pixel_rays(cam) for cam in rig]
        self.backgrounds = [self._background(cam, rng) for cam in rig]

    def _pixel_rays(self, cam) -> np.ndarray:
        """(H, W, ss*ss, 2) float32 undistorted normalized coordinates of the sub-pixel samples."""
        offsets = (np.arange(self.ss) + 0.5) / self.ss - 0.5
        ox, oy = np.meshgrid(offsets, offsets)
        u = np.arange(cam.width)[None, :, None] + ox.ravel()[None, None, :]
        v = np.arange(cam.height)[:, None, None] + oy.ravel()[None, None, :]
        u, v = np.broadcast_arrays(u, v)
        return cam.undistort_points(np.stack([u, v], axis=-1)).astype(np.float32)

    @staticmethod
    def _background(cam, rng) -> np.ndarray:
        """A fixed smooth random texture per camera (walls and floor stand-in), float32 grey 0-1."""
        coarse = rng.uniform(0.25, 0.7, (cam.height // 16 + 2, cam.width // 16 + 2)).astype(np.float32)
        fine = rng.uniform(-0.04, 0.04, (cam.height // 2 + 1, cam.width // 2 + 1)).astype(np.float32)
        return (cv2.resize(coarse, (cam.width, cam.height), interpolation=cv2.INTER_CUBIC)
                + cv2.resize(fine, (cam.width, cam.height), interpolation=cv2.INTER_LINEAR))

    def render(self, k: int, R_board: np.ndarray, t_board: np.ndarray, light: np.ndarray,
               gain: float, rng: np.random.Generator) -> np.ndarray:
        """(H, W, 3) uint8 image of camera ``k`` with the board at pose ``(R_board, t_board)``
        (board -> room), lit from direction ``light`` (unit, room), exposure ``gain``."""
        cam = self.rig[k]
        look = self.look
        image = self.backgrounds[k].copy()
        R_cb = cam.R @ R_board
        t_cb = cam.R @ t_board + cam.t
        normal_cam = R_cb[:, 2]
        facing = float(normal_cam @ t_cb) > 0.0  # camera on the printed side (board z points away)
        box = self._bounding_box(cam, R_board, t_board)
        if box is not None:
            x0, y0, x1, y1 = box
            rays = self.rays[k][y0:y1, x0:x1]
            d = np.concatenate([rays, np.ones(rays.shape[:-1] + (1,), np.float32)], axis=-1)
            denom = d @ normal_cam.astype(np.float32)
            with np.errstate(divide="ignore", invalid="ignore"):
                s = np.float32(normal_cam @ t_cb) / denom
                hit = d * s[..., None] - t_cb.astype(np.float32)
            bx = hit @ R_cb[:, 0].astype(np.float32)
            by = hit @ R_cb[:, 1].astype(np.float32)
            tu = (bx * self.texels_per_metre + self.texture_origin - 0.5).astype(np.float32)
            tv = (by * self.texels_per_metre + self.texture_origin - 0.5).astype(np.float32)
            tu[~(s > 0)] = -1e6
            shape = tu.shape
            th, tw = self.texture.shape
            inside = ((tu >= -0.5) & (tu <= tw - 0.5) & (tv >= -0.5) & (tv <= th - 0.5)).astype(np.float32)
            if facing:
                albedo = cv2.remap(self.texture, tu.reshape(shape[0], -1), tv.reshape(shape[0], -1),
                                   cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).reshape(shape)
            else:
                albedo = np.full(shape, look.back, np.float32)
            lit = look.ambient + look.diffuse * abs(float((R_board[:, 2]) @ light))
            crop = image[y0:y1, x0:x1]
            coverage = inside.mean(axis=-1)
            board = (albedo * inside).sum(axis=-1) / np.maximum(inside.sum(axis=-1), 1.0) * lit
            image[y0:y1, x0:x1] = crop * (1.0 - coverage) + board * coverage
        image = cv2.GaussianBlur(image * (255.0 * gain), (0, 0), look.blur_sigma)
        noisy = image[..., None] + rng.standard_normal((cam.height, cam.width, 3), np.float32) * look.noise_sigma
        return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)

    def _bounding_box(self, cam, R_board, t_board):
        """Pixel box ``(x0, y0, x1, y1)`` holding the board's image, or None when it is out of
        view or (partly) behind the camera."""
        points = self.outline @ R_board.T + t_board
        cam_pts = points @ cam.R.T + cam.t
        if np.any(cam_pts[:, 2] < 0.05):
            return None
        if np.any((cam_pts[:, :2] ** 2).sum(axis=1) / cam_pts[:, 2] ** 2 > cam.max_normalized_radius2):
            return 0, 0, cam.width, cam.height  # beyond the lens model's range: trace everything
        px, _ = cam.project(points)
        x0, y0 = np.floor(px.min(axis=0)).astype(int) - 2
        x1, y1 = np.ceil(px.max(axis=0)).astype(int) + 3
        x0, y0 = max(x0, 0), max(y0, 0)
        x1, y1 = min(x1, cam.width), min(y1, cam.height)
        if x1 <= x0 or y1 <= y0:
            return None
        return x0, y0, x1, y1


def _outline(x0: float, y0: float, x1: float, y1: float, n: int = 24) -> np.ndarray:
    """(4n, 3) points along the rectangle's edges in the board plane (distortion bends edges)."""
    s = np.linspace(0.0, 1.0, n, endpoint=False)
    xs, ys = x0 + (x1 - x0) * s, y0 + (y1 - y0) * s
    edges = [np.stack([xs, np.full(n, y0)], 1), np.stack([np.full(n, x1), ys], 1),
             np.stack([xs[::-1] + (x1 - x0) / n, np.full(n, y1)], 1),
             np.stack([np.full(n, x0), ys[::-1] + (y1 - y0) / n], 1)]
    return np.concatenate([np.concatenate(edges), np.zeros((4 * n, 1))], axis=1)
