"""A calibrated camera fitted to the frames of its video: turned, scaled or cropped (no rclpy).

A calibration describes the image the calibrating tool saw; a video may hold that image turned
by quarter turns (a phone or a camera mounted on its side, a player that applied the file's
rotation), resized (recorded binned or at a lower resolution) or with a few rows or columns cut
(an encoder's crop to a size its codec prefers). :func:`fit_camera` finds which from the two
sizes and returns the camera of the video's frames:

* same size: the camera as it is;
* turned (``turns`` quarter turns clockwise, from ``--rotate``): :func:`rotate_camera`;
* the same aspect ratio: :meth:`~hmocap_ros.geometry.pinhole_camera.PinholeCamera.scaled`;
* at most :data:`MAX_CROP_PX` pixels fewer along either axis, none more: cut at the right and
  bottom edges (the principal point stays; the Pose2Sim demo's two 1080-wide videos of its
  1088-wide calibration reproject best so, see ``docs/real_recordings.md``);
* anything else: :class:`CameraFitError`.

:func:`upright_turns` says how many quarter turns bring the room's up direction to the image's
up, so that the keypoint network, trained on upright people, sees them upright.
"""
from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["MAX_CROP_PX", "CameraFitError", "common_size", "crop_camera", "fit_camera",
           "rotate_camera", "upright_turns"]

#: Most pixels a video may lack along an axis (at the right or bottom) for a cut, not a mismatch.
MAX_CROP_PX = 16
#: Smallest share of the room's up direction that must lie in the image plane for
#: :func:`upright_turns` to turn a camera (a camera looking straight down is left as it is).
MIN_UP_IN_IMAGE = 0.5
#: Largest difference (pixels) between the two axes' scale factors of a resized video.
_SCALE_TOLERANCE_PX = 1.0


class CameraFitError(ValueError):
    """A video's frames do not fit its camera's calibration (one line for the user)."""


def rotate_camera(camera, turns: int):
    """The camera of its image turned by ``turns`` quarter turns clockwise
    (``cv2.ROTATE_90_CLOCKWISE`` applied ``turns`` times).

    One turn maps pixel ``(u, v)`` of a ``W x H`` image to ``(H - 1 - v, u)``: the optical
    frame turns about its z axis (``x' = -y``, ``y' = x``), so ``R' = Rz R``, ``t' = Rz t``;
    ``fx' = fy``, ``fy' = fx``, ``cx' = H - 1 - cy``, ``cy' = cx``; the radial terms stay and
    the tangential ones become ``p1' = p2``, ``p2' = -p1`` (Brown-Conrady with ``x = y'``,
    ``y = -x'``).
    """
    turns = int(turns) % 4
    Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    for _ in range(turns):
        K, D = np.array(camera.K), np.array(camera.D)
        K_new = np.array([[K[1, 1], 0.0, camera.height - 1 - K[1, 2]],
                          [0.0, K[0, 0], K[0, 2]], [0.0, 0.0, 1.0]])
        if D.size >= 4:
            D[2], D[3] = camera.D[3], -camera.D[2]
        camera = dataclasses.replace(
            camera, width=camera.height, height=camera.width, K=K_new, D=D, R=Rz @ camera.R,
            t=Rz @ camera.t, rectification=None, projection=None)
    return camera


def crop_camera(camera, width: int, height: int):
    """The camera of its image cut to ``width x height`` at the right and bottom edges: the
    intrinsics stay."""
    P = np.hstack([np.asarray(camera.K), np.zeros((3, 1))])
    return dataclasses.replace(camera, width=width, height=height, projection=P)


def fit_camera(camera, size: tuple[int, int], turns: int = 0):
    """The camera of a video whose frames are ``size`` (width, height), and a note on what was
    done (empty when nothing); ``turns``: quarter turns clockwise from the calibration's image
    to the video's (module docstring). :class:`CameraFitError` when the sizes do not fit."""
    width, height = (int(v) for v in size)
    notes = []
    if turns % 4:
        camera = rotate_camera(camera, turns)
        notes.append(f"turned {90 * (turns % 4)} deg clockwise")
    cw, ch = camera.width, camera.height
    where = f"camera {camera.name!r}: the video is {width}x{height}, the calibration {cw}x{ch}"
    if (width, height) == (cw, ch):
        return camera, ", ".join(notes)
    if (width, height) == (ch, cw):
        raise CameraFitError(f"{where} (turned): give --rotate {camera.name}=90 or "
                             f"{camera.name}=270, the clockwise turn from the calibration's image "
                             f"to the video's")
    sx, sy = width / cw, height / ch
    if abs(sx - sy) * max(cw, ch) <= _SCALE_TOLERANCE_PX:
        notes.append(f"scaled by {sx:.4g}")
        return camera.scaled(sx), ", ".join(notes)
    if 0 <= cw - width <= MAX_CROP_PX and 0 <= ch - height <= MAX_CROP_PX:
        notes.append(f"cut to {width}x{height} at the right and bottom")
        return crop_camera(camera, width, height), ", ".join(notes)
    raise CameraFitError(where)


def common_size(cameras) -> tuple[int, int] | None:
    """``(width, height)`` every camera is cut to when their image sizes differ by at most
    :data:`MAX_CROP_PX` pixels along each axis (the smallest of each), so that all views of a
    frame set share one size as the tracker's silhouette stack needs; None when they are equal
    or differ by more."""
    sizes = np.array([(c.width, c.height) for c in cameras])
    if len(sizes) == 0 or (sizes == sizes[0]).all():
        return None
    smallest = sizes.min(axis=0)
    if (sizes - smallest).max() > MAX_CROP_PX:
        return None
    return int(smallest[0]), int(smallest[1])


def upright_turns(camera) -> int:
    """Quarter turns clockwise (0-3) that bring the room's up direction (+Y) nearest to the
    image's up (its -v axis); 0 when up lies mostly along the optical axis (module
    docstring)."""
    up = np.asarray(camera.R) @ np.array([0.0, 1.0, 0.0])  # room up in the optical frame
    in_image = up[:2]
    if np.linalg.norm(in_image) < MIN_UP_IN_IMAGE:
        return 0
    # one clockwise turn maps an image direction (x, y) to (-y, x): take the k whose result
    # lies nearest to the image's up, (0, -1)
    scores, direction = [], in_image
    for _ in range(4):
        scores.append(-direction[1])
        direction = np.array([-direction[1], direction[0]])
    return int(np.argmax(scores))
