"""Corner observations of a calibration session as flat arrays (one row per corner seen)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Observations"]


@dataclass(frozen=True, eq=False)
class Observations:
    """Corner ``corner[i]`` of board pose ``pose[i]`` seen by camera ``camera[i]`` at
    ``pixels[i]``. A board pose is one frame of the carried board, or all the frames of the
    board lying still on the floor."""

    camera: np.ndarray  # (N,) int
    pose: np.ndarray  # (N,) int
    corner: np.ndarray  # (N,) int
    pixels: np.ndarray  # (N, 2) float
    n_cameras: int
    n_poses: int

    @classmethod
    def from_views(cls, views: dict, n_cameras: int, n_poses: int) -> "Observations":
        """From ``{(camera, pose): [(ids, pixels), ...]}``."""
        cam, pose, corner, pixels = [], [], [], []
        for (c, p), items in sorted(views.items()):
            for ids, px in items:
                cam.append(np.full(len(ids), c))
                pose.append(np.full(len(ids), p))
                corner.append(np.asarray(ids, int))
                pixels.append(np.asarray(px, float).reshape(-1, 2))
        if not cam:
            return cls(np.zeros(0, int), np.zeros(0, int), np.zeros(0, int), np.zeros((0, 2)),
                       n_cameras, n_poses)
        return cls(np.concatenate(cam).astype(int), np.concatenate(pose).astype(int),
                   np.concatenate(corner).astype(int), np.concatenate(pixels), n_cameras, n_poses)

    def subset(self, keep: np.ndarray) -> "Observations":
        return Observations(self.camera[keep], self.pose[keep], self.corner[keep],
                            self.pixels[keep], self.n_cameras, self.n_poses)

    def views(self) -> dict:
        """``{(camera, pose): row indices}``."""
        key = self.camera * self.n_poses + self.pose
        order = np.argsort(key, kind="stable")
        uniq, starts = np.unique(key[order], return_index=True)
        groups = np.split(order, starts[1:])
        return {(int(k // self.n_poses), int(k % self.n_poses)): g for k, g in zip(uniq, groups)}
