#!/usr/bin/env python
"""Make the small shipped demo bag: 4 calibrated views of a simple moving scene.

A tiled floor and a walking upright cylinder (a stand-in for a person) seen by the cameras of
``config/rig_example.yaml`` at a reduced resolution, 25 fps, written as rgb8 images with the
rig (latched ``/camera_rig``). Deterministic. The full synthetic smart room (``hmocap sim``)
replaces the scene content; the layout of the bag stays the same.

    .venv/bin/python tools/make_demo_bag.py [--scale 0.25] [--seconds 2]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from hmocap_ros.config_files import find_config_file
from hmocap_ros.io.bag_writer import LATCHED, BagWriter
from hmocap_ros.io.conversions import numpy_to_image
from hmocap_ros.io.msg_factory import RosbagsFactory
from hmocap_ros.rig import Rig, load_rig, rig_to_msg, save_rig

OUT_DIR = Path(__file__).resolve().parents[1] / "hmocap_ros" / "data" / "demo"


def draw_view(camera, t: float) -> np.ndarray:
    """Render one view at time t (seconds): floor tiles, then the cylinder, painter's order."""
    h, w = camera.height, camera.width
    img = np.full((h, w, 3), (170, 180, 190), np.uint8)
    tile = 0.5
    for i in range(-6, 6):
        for j in range(-5, 5):
            corners = np.array([[i, 0, j], [i + 1, 0, j], [i + 1, 0, j + 1], [i, 0, j + 1]], float) * tile
            px, depth = camera.project(corners)
            if np.any(depth <= 0.1):
                continue
            colour = (120, 90, 60) if (i + j) % 2 else (150, 120, 80)
            cv2.fillConvexPoly(img, np.round(px * 16).astype(np.int32), colour, cv2.LINE_AA, shift=4)
    centre = np.array([1.2 * np.cos(0.8 * t), 0.0, 0.9 * np.sin(0.8 * t)])
    ang = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    ring = np.stack([0.2 * np.cos(ang), np.zeros_like(ang), 0.2 * np.sin(ang)], 1)
    pts = np.concatenate([centre + ring, centre + ring + [0, 1.7, 0]])
    px, depth = camera.project(pts)
    if np.all(depth > 0.1):
        hull = cv2.convexHull(np.round(px * 16).astype(np.int32))
        cv2.fillConvexPoly(img, hull, (200, 40, 40), cv2.LINE_AA, shift=4)
    return img


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scale", type=float, default=0.25, help="resolution factor of the example rig")
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--fps", type=float, default=25.0)
    parser.add_argument("--out", type=Path, default=OUT_DIR)
    ns = parser.parse_args()
    full = load_rig(find_config_file("rig_example.yaml"))
    rig = Rig(frame_id=full.frame_id, cameras=tuple(c.scaled(ns.scale) for c in full.cameras))
    ns.out.mkdir(parents=True, exist_ok=True)
    save_rig(rig, ns.out / "room_4cam_rig.yaml")
    bag_path = ns.out / "room_4cam.mcap"
    if bag_path.exists():
        bag_path.unlink()
    factory = RosbagsFactory()
    t0_ns = 1_700_000_000_000_000_000
    with BagWriter(bag_path) as bag:
        bag.add_topic("/camera_rig", "hmocap_interfaces/msg/CameraRig", LATCHED)
        bag.write("/camera_rig", rig_to_msg(rig, t0_ns, factory), t0_ns)
        for k in range(int(round(ns.seconds * ns.fps))):
            stamp = t0_ns + int(round(k * 1e9 / ns.fps))
            for cam in rig.cameras:
                img = draw_view(cam, k / ns.fps)
                bag.write(f"/{cam.name}/image_raw",
                          numpy_to_image(img, "rgb8", stamp, cam.frame_id, factory), stamp)
    print(f"wrote {bag_path} ({bag_path.stat().st_size / 1e3:.0f} kB) and {ns.out / 'room_4cam_rig.yaml'}")


if __name__ == "__main__":
    main()
