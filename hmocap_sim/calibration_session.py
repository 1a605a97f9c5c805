"""``hmocap sim calibration``: a rig calibration session, a ChArUco board seen by every camera.

The board (:class:`hmocap_ros.calibration.board.BoardSpec`, printed on a white plate) lies on
the floor at the room origin for ``--floor-seconds`` (the pose that defines the room frame),
then is carried through the volume the cameras see, turning to face each camera in turn
(:mod:`hmocap_sim.calibration_path`). :mod:`hmocap_sim.calibration_render` warps the
board through each camera's intrinsics and lens distortion over a plain textured background,
with lighting that follows the board's tilt, lens blur and sensor noise. The rig is
:func:`hmocap_sim.mocap_rig.make_rig`'s unless ``--rig`` gives one. Same seed, same bytes.

Output, next to each other (``BAG`` = ``--out``, e.g. ``cal.mcap``): ``BAG`` with the latched
``/camera_rig`` and ``/<cam>/image_raw`` (rgb8) of every camera and frame (one stamp per
frame), and ``<stem>_rig.yaml``, the true rig, for checking a calibration against.
``--rig RIG.yaml`` renders the session in the cameras of a given rig (e.g. the true rig of a
mocap bag, to calibrate the cameras that recorded it).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hmocap_ros.calibration.board import BoardSpec

__all__ = ["CalibrationSimConfig", "generate"]

BASE_STAMP_NS = 1_700_000_000_000_000_000


@dataclass(frozen=True)
class CalibrationSimConfig:
    """Everything that defines a session (the CLI options)."""

    out: Path
    cameras: int = 4
    width: int = 640
    height: int = 480
    fps: float = 3.0
    seconds: float = 60.0
    floor_seconds: float = 1.0
    seed: int = 0
    board: BoardSpec = BoardSpec()
    rig: Path | None = None
    force: bool = False
    progress: bool = True


def generate(config: CalibrationSimConfig, log=print) -> tuple[Path, Path, int]:
    """Render and write one session (module docstring); returns the bag, the rig YAML and the
    number of frames."""
    from hmocap_ros.geometry.rig import load_rig
    from hmocap_ros.io import topics
    from hmocap_ros.io.bag_writer import LATCHED, whole_bag
    from hmocap_ros.io.conversions import numpy_to_image
    from hmocap_ros.io.msg_factory import RosbagsFactory
    from hmocap_ros.io.rig_messages import rig_to_msg
    from hmocap_ros.io.typestore import hmocap_typestore
    from hmocap_sim.calibration_path import board_poses
    from hmocap_sim.calibration_render import BoardRenderer
    from hmocap_sim.mocap_outputs import clear_outputs, output_paths, save_rig_yaml
    from hmocap_sim.mocap_rig import make_rig

    if config.fps <= 0 or config.seconds <= 0 or config.floor_seconds < 0:
        raise ValueError("--fps and --seconds must be positive, --floor-seconds not negative")
    out = Path(config.out)
    rig_path, _ = output_paths(out)
    clear_outputs((out, rig_path), config.force)
    rig = load_rig(config.rig) if config.rig is not None else make_rig(config.cameras, config.width,
                                                                         config.height)
    seeds = np.random.SeedSequence(int(config.seed)).spawn(3)
    rng_scene, rng_path, rng_light = (np.random.default_rng(s) for s in seeds)
    renderer = BoardRenderer(rig, config.board, rng_scene)
    n_frames = int(round((config.floor_seconds + config.seconds) * config.fps))
    t = np.arange(n_frames) / config.fps
    R, origin = board_poses(t, config.floor_seconds, config.board.size_m, rng_path)
    light = np.array([0.3, 1.0, 0.2]) + rng_light.normal(0.0, 0.1, 3)
    light /= np.linalg.norm(light)
    gains = 1.0 + 0.08 * rng_light.standard_normal((n_frames, len(rig)))
    stamps = BASE_STAMP_NS + np.round(t * 1e9).astype(np.int64)
    factory = RosbagsFactory(hmocap_typestore())
    t0 = time.perf_counter()
    with whole_bag(out) as bag:
        bag.add_topic(topics.CAMERA_RIG, "hmocap_interfaces/msg/CameraRig", LATCHED)
        bag.write(topics.CAMERA_RIG, rig_to_msg(rig, int(stamps[0]), factory), int(stamps[0]))
        for i in range(n_frames):
            for k, cam in enumerate(rig):
                noise = np.random.default_rng(np.random.SeedSequence(int(config.seed), spawn_key=(2, i, k)))
                image = renderer.render(k, R[i], origin[i], light, float(gains[i, k]), noise)
                bag.write(topics.camera_image(cam.name),
                          numpy_to_image(image, "rgb8", int(stamps[i]), cam.frame_id, factory),
                          int(stamps[i]))
            if config.progress and (i + 1) % max(1, int(config.fps * 10)) == 0:
                log(f"  {i + 1}/{n_frames} frames rendered ({time.perf_counter() - t0:.0f} s)")
    save_rig_yaml(rig, rig_path, out.name, config.seed)
    return out, rig_path, n_frames
