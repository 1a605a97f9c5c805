"""The foreground each body of several is fitted to: the other bodies in front of it taken out.

With several people in a room every tracker's silhouette term (the XOR of eq. 2.8) sees the
whole foreground, so a limb of one body is pulled onto another person standing next to it or
in front of it. :func:`masks_without_others` gives each tracked body the cameras' masks with
the silhouettes of the other tracked bodies removed where those bodies stand nearer to the
camera than it does (the depth of each body's pelvis in that camera): the pixels of a person in
front are theirs, and a body behind them cannot be seen there anyway. Where the body stands in
front, the other body's pixels stay: its own silhouette covers them. A slot that follows nobody
sees the foreground without every tracked body, so it starts on a person no body explains.

The other bodies are rendered at their last estimate (before this frame set's update, the same
for every slot, so the result does not depend on the slots' order), each once per frame set
and camera, at the resolution of that camera's mask (:func:`~hmocap_ros.render.render_silhouettes`).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from hmocap_ros.geometry import project_points
from hmocap_ros.render import render_silhouettes

__all__ = ["BodySilhouettes", "masks_without_others", "render_bodies"]


class BodySilhouettes:
    """One body's rendered silhouettes: per camera a bool mask at that camera's mask
    resolution (None where the body is not in front of the camera or the mask is missing),
    and the depth of its pelvis in each camera (NaN: behind it)."""

    def __init__(self, silhouettes: list, depths: np.ndarray):
        self.silhouettes = silhouettes
        self.depths = depths


def render_bodies(cameras: Sequence, masks: Sequence[np.ndarray | None],
                  bodies: Sequence[tuple[np.ndarray, np.ndarray] | None],
                  faces: np.ndarray) -> list[BodySilhouettes | None]:
    """Per body ``(vertices (V, 3), pelvis (3,))`` (None: not tracked), its silhouettes in
    every camera with a mask (module docstring)."""
    out: list[BodySilhouettes | None] = []
    for body in bodies:
        if body is None:
            out.append(None)
            continue
        vertices, pelvis = body[0], body[1]
        mesh = project_points(cameras, vertices, distort=True)
        centre = project_points(cameras, np.asarray(pelvis, float)[None]).depth[:, 0]
        silhouettes: list[np.ndarray | None] = []
        for v, (camera, mask) in enumerate(zip(cameras, masks)):
            if mask is None or not np.all(mesh.depth[v] > 0):
                silhouettes.append(None)
                continue
            h, w = np.shape(mask)[:2]
            pixels = (mesh.pixels[v] + 0.5) * np.array([w / camera.width, h / camera.height]) - 0.5
            silhouettes.append(render_silhouettes(pixels, faces, h, w).astype(bool))
        out.append(BodySilhouettes(silhouettes, np.where(centre > 0, centre, np.nan)))
    return out


def masks_without_others(masks: Sequence[np.ndarray | None], rendered: Sequence[BodySilhouettes | None],
                         k: int) -> list[np.ndarray | None]:
    """The masks body ``k`` is fitted to (module docstring): each camera's mask without the
    silhouettes of the other rendered bodies that stand nearer that camera than body ``k``
    (all of them when body ``k`` is not rendered)."""
    mine = rendered[k]
    out = list(masks)
    for j, other in enumerate(rendered):
        if j == k or other is None:
            continue
        for v, silhouette in enumerate(other.silhouettes):
            mask = out[v]
            if silhouette is None or mask is None:
                continue
            if mine is not None and not (other.depths[v] < mine.depths[v]):
                continue  # body k stands in front (or the order is unknown): its pixels stay
            out[v] = np.where(silhouette, np.zeros_like(mask), mask)
    return out
