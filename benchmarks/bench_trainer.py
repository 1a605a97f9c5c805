#!/usr/bin/env python
"""Cost per frame of the interactive trainer (``Trainer.on_frame``) in a closed loop with the simulated user.

    .venv/bin/python benchmarks/bench_trainer.py [--width 640 --height 480]

One short session (one round: 0.5 s do gesture, 2 s update positive, 0.3 s release, 2 s do
negatives, 0.5 s testing) of the default forest (15 trees, depth 20, 32 x 4 candidate tests per
leaf) at 30 fps; prints the mean wall and process (CPU) time per frame for each state, to
compare with the 33 ms of a 30 fps stream. Rendering the frames is not counted.
"""

import argparse
import time

import numpy as np

from hmocap_ros.gestures.trainer import Trainer, TrainerParams
from hmocap_sim.gesture_teacher import GestureTeacher


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ns = ap.parse_args(argv)
    p = TrainerParams(rounds=1, do_gesture_s=0.5, update_positive_s=2.0, release_s=0.3, do_negatives_s=2.0,
                      testing_s=0.5)
    teacher = GestureTeacher(seed=1, width=ns.width, height=ns.height)
    trainer = Trainer(None, p, np.random.default_rng(0), focal_px=teacher.focal_px)
    trainer.start("tee", teacher.next_stamp)
    status = trainer.status(teacher.next_stamp, ns.width, ns.height)
    cost = {}
    for _ in range(int(round(p.session_s() * teacher.fps))):
        depth, stamp = teacher.next_frame(status)
        w0, c0 = time.perf_counter(), time.process_time()
        status = trainer.on_frame(depth, stamp)
        cost.setdefault(status.state, []).append((time.perf_counter() - w0, time.process_time() - c0))
    print(f"{ns.width}x{ns.height}, {trainer.online.n_nodes} nodes at the end")
    for state, v in cost.items():
        a = 1e3 * np.array(v)
        print(f"{state:16s} {len(a):3d} frames: wall {a[:, 0].mean():6.1f} ms, cpu {a[:, 1].mean():6.1f} ms per frame")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
