"""Toy depth scenes with planted "gestures" and known ground truth, for tests and benchmarks.

Not the simulator (``hmocap_ros.sim``, a posed body rendered by a Kinect-like sensor): flat
cut-out shapes at known depths, fast to draw (OpenCV), enough to check that the forest,
the clipping and the localization do what the thesis says. A scene is a back wall, random
clutter boxes and discs, a "person" (torso and head) and, in front of the torso, a hand
shape: class 1 "palm" (a disc with four fingers up), class 2 "tee" (a T of two bars), or a
distractor "fist" (a plain disc) for negative frames. Sizes are metric, drawn with a pinhole
of focal ``focal_px``; the annotated point is the palm centre / the T's crossing point.
Depth comes out as uint16 millimetres with 0 = invalid (REP 118 16UC1), with Kinect-like
noise (sigma 1.5 mm at 1 m, growing with the square of depth) and random dropouts.
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from hmocap_ros.gestures.forest import train_forest
from hmocap_ros.gestures.params import DetectorParams, ForestParams, TrainParams

__all__ = ["TOY_CLASSES", "add_sensor_noise", "draw_hand", "toy_detector_params", "toy_forest", "toy_frame",
           "toy_sequence", "toy_train_params"]

TOY_CLASSES = ("background", "palm", "tee")


def _fill(z: np.ndarray, mask: np.ndarray, depth: float) -> None:
    np.minimum(z, np.where(mask > 0, np.float32(depth), np.float32(np.inf)), out=z)


def _rect(z, cx, cy, w, h, depth, f, angle=0.0):
    """Rectangle of w x h metres centred at pixel (cx, cy), at ``depth``."""
    s = f / depth
    box = cv2.boxPoints(((float(cx), float(cy)), (max(w * s, 1.0), max(h * s, 1.0)), float(angle)))
    mask = np.zeros(z.shape, np.uint8)
    cv2.fillConvexPoly(mask, np.rint(box).astype(np.int32), 1)
    _fill(z, mask, depth)


def _disc(z, cx, cy, r, depth, f, aspect=1.0):
    s = f / depth
    mask = np.zeros(z.shape, np.uint8)
    axes = (max(int(round(r * s)), 1), max(int(round(r * s * aspect)), 1))
    cv2.ellipse(mask, (int(round(cx)), int(round(cy))), axes, 0, 0, 360, 1, -1)
    _fill(z, mask, depth)


def draw_hand(z: np.ndarray, kind: str, u: float, v: float, depth: float, f: float) -> None:
    """Draw hand shape ``kind`` ('palm', 'tee', 'fist') with its annotated point at pixel (u, v)."""
    s = f / depth
    if kind == "palm":
        _disc(z, u, v, 0.045, depth, f)
        for i, dx in enumerate((-0.03, -0.01, 0.01, 0.03)):
            length = 0.07 if i in (1, 2) else 0.06
            _rect(z, u + dx * s, v - (0.04 + length / 2) * s, 0.016, length, depth, f)
    elif kind == "tee":
        _rect(z, u, v - 0.0175 * s, 0.20, 0.035, depth, f)
        _rect(z, u, v + 0.08 * s, 0.035, 0.16, depth + 0.02, f)
    elif kind == "fist":
        _disc(z, u, v, 0.05, depth, f, aspect=0.9)
    else:
        raise ValueError(f"unknown toy hand {kind!r}")


def toy_frame(rng: np.random.Generator, shape=(480, 640), class_id: int = 0, uv=None, depth_m=None,
              focal_px: float | None = None, n_clutter: int = 6, noise: bool = True, person: bool = True):
    """One toy depth frame (uint16 mm, 0 invalid) and its label ``(class_id, u, v)``.

    ``class_id`` 0 gives a person with a distractor fist (or no hand); 1 palm, 2 tee. ``uv`` and
    ``depth_m`` (the hand's) default to random values that keep the hand in the image.
    ``person=False`` leaves out person and hand (class 0 only): wall and clutter.
    """
    h, w = shape
    f = float(focal_px if focal_px is not None else 525.0 * w / 640.0)
    z = np.full(shape, np.float32(rng.uniform(3.5, 5.0)), np.float32)
    z += np.linspace(-0.3, 0.3, w, dtype=np.float32)[None, :] * np.float32(rng.uniform(-1, 1))
    hand_depth = float(depth_m if depth_m is not None else rng.uniform(1.4, 3.0))
    s = f / hand_depth
    margin = 0.15 * s
    if uv is None:
        uv = (rng.uniform(margin, w - margin), rng.uniform(margin, h - margin))
    u, v = float(uv[0]), float(uv[1])
    for _ in range(n_clutter):  # furniture, other people: at any depth, but never hiding the hand
        cd = rng.uniform(1.0, 4.5)
        cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        size = rng.uniform(0.2, 0.8)
        if cd < hand_depth + 0.6 and np.hypot(cx - u, cy - v) < (0.6 * size + 0.3) * f / cd:
            cd = rng.uniform(hand_depth + 0.6, 5.0)
        if rng.random() < 0.5:
            _rect(z, cx, cy, size, rng.uniform(0.2, 0.8), cd, f, rng.uniform(0, 90))
        else:
            _disc(z, cx, cy, 0.4 * size, cd, f)
    if not person:
        class_id = 0
    body_depth = hand_depth + rng.uniform(0.2, 0.35)
    sb = f / body_depth
    bx = u + rng.uniform(-0.15, 0.15) * sb
    by = v + rng.uniform(0.05, 0.25) * sb
    if person:
        _rect(z, bx, by + 0.1 * sb, 0.38, 0.65, body_depth, f)
        _disc(z, bx, by - 0.35 * sb, 0.1, body_depth, f, aspect=1.25)
        if class_id > 0:
            draw_hand(z, TOY_CLASSES[class_id], u, v, hand_depth, f)
        elif rng.random() < 0.7:
            draw_hand(z, "fist", u, v, hand_depth, f)
    depth_mm = add_sensor_noise(rng, z) if noise else np.clip(np.rint(z * 1000.0), 0, 65535).astype(np.uint16)
    return depth_mm, (int(class_id), int(round(u)), int(round(v)))


def add_sensor_noise(rng: np.random.Generator, depth_m: np.ndarray, dropout: float = 0.01) -> np.ndarray:
    """Kinect-like noise on a metres image (sigma 1.5 mm x depth^2, ``dropout`` pixels lost) -> uint16 mm."""
    z = np.asarray(depth_m, np.float32)
    z = z + (rng.standard_normal(z.shape, dtype=np.float32) * np.float32(0.0015)) * z * z
    z[rng.random(z.shape) < dropout] = 0.0
    return np.clip(np.rint(z * 1000.0), 0, 65535).astype(np.uint16)


def toy_sequence(rng: np.random.Generator, n_frames: int, shape=(480, 640), negative_fraction: float = 0.34,
                 n_classes: int = 3, empty_fraction: float = 0.3, **kw):
    """``n_frames`` toy frames with random classes (a ``negative_fraction`` of class 0, of which an
    ``empty_fraction`` show no person at all) and their labels."""
    frames, labels = [], []
    for _ in range(n_frames):
        c = 0 if rng.random() < negative_fraction else int(rng.integers(1, n_classes))
        person = c > 0 or rng.random() >= empty_fraction
        d, lab = toy_frame(rng, shape, c, person=person, **kw)
        frames.append(d)
        labels.append(lab)
    return frames, labels


def focal_scale(shape) -> float:
    """The toy camera's focal length relative to 525 px at 640x480: the factor by which the
    pixel*metre defaults (tuned for a Kinect-like 640x480 camera) scale to this image size."""
    return shape[1] / 640.0


def toy_train_params(shape=(240, 320), n_trees: int = 8, max_depth: int = 18,
                     samples_per_class: int = 5000, mining_rounds: int = 0) -> TrainParams:
    """Training defaults with the pixel*metre sizes scaled to the toy image size (no hard
    negative mining unless asked: the toy tests stay fast)."""
    forest = ForestParams(n_trees=n_trees, max_depth=max_depth, samples_per_class=samples_per_class,
                          mining_rounds=mining_rounds)
    return TrainParams(forest=forest).for_focal(525.0 * focal_scale(shape))


def toy_detector_params(shape=(240, 320), **overrides) -> DetectorParams:
    """Detector defaults with the pixel sizes scaled to the toy image size."""
    s = focal_scale(shape)
    base = dict(stride=max(1, round(4 * s)), parzen_sigma_px=6.0 * s, volume_radius_px_m=20.0 * s,
                suppression_radius_px_m=60.0 * s)
    base.update(overrides)
    return DetectorParams(**base)


@lru_cache(maxsize=4)
def toy_forest(n_frames: int = 300, seed: int = 0, shape=(240, 320), n_trees: int = 8, max_depth: int = 18):
    """A forest trained on ``n_frames`` toy frames (cached per process: tests share it; do not modify)."""
    rng = np.random.default_rng(seed)
    frames, labels = toy_sequence(rng, n_frames, shape)
    return train_forest(frames, labels, toy_train_params(shape, n_trees, max_depth), rng, class_names=TOY_CLASSES)
