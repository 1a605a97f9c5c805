"""Rig calibration against the truth on simulated sessions (hmocap sim calibration, then
hmocap calibrate): camera centre error (mm), orientation error (degrees) and reprojection RMS
(px), with no alignment (the room frame comes from the board on the floor).

    .venv/bin/python benchmarks/bench_calibration.py [--cameras 4 6] [--seconds 60] [--fps 3]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def rig_errors(estimated, truth) -> tuple[np.ndarray, np.ndarray]:
    """Per camera of ``estimated``: centre error (mm) and orientation error (degrees)."""
    from hmocap_ros.geometry.rotations import rotation_angle_deg

    centre = np.array([np.linalg.norm(c.position - truth[c.name].position) * 1000 for c in estimated])
    angle = np.array([float(rotation_angle_deg(c.R, truth[c.name].R)) for c in estimated])
    return centre, angle


def main() -> int:
    from hmocap_ros.geometry.rig import load_rig

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cameras", type=int, nargs="+", default=[4, 6])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--fps", type=float, default=3.0)
    parser.add_argument("--seed", type=int, default=0)
    ns = parser.parse_args()
    exe = [sys.executable, "-m", "hmocap_ros.cli"]
    with tempfile.TemporaryDirectory() as tmp:
        for n in ns.cameras:
            bag = Path(tmp) / f"cal{n}.mcap"
            t0 = time.perf_counter()
            subprocess.run([*exe, "sim", "calibration", "--cameras", str(n), "--seconds", str(ns.seconds),
                            "--fps", str(ns.fps), "--seed", str(ns.seed), "--out", str(bag), "--quiet"],
                           check=True, stdout=subprocess.DEVNULL)
            t1 = time.perf_counter()
            out = Path(tmp) / f"est{n}.yaml"
            run = subprocess.run([*exe, "calibrate", str(bag), "--out", str(out)], check=True,
                                 capture_output=True, text=True)
            t2 = time.perf_counter()
            rms = float(run.stdout.split("overall reprojection RMS ")[1].split()[0])
            centre, angle = rig_errors(load_rig(out), load_rig(Path(tmp) / f"cal{n}_rig.yaml"))
            print(f"{n} cameras, {ns.seconds:g} s at {ns.fps:g} fps 640x480: centre error mean "
                  f"{centre.mean():.2f} max {centre.max():.2f} mm; orientation mean {angle.mean():.3f} "
                  f"max {angle.max():.3f} deg; RMS {rms:.3f} px (render {t1 - t0:.0f} s, calibrate "
                  f"{t2 - t1:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
