#!/usr/bin/env python3
"""Reaction times of the example apps (target: under 200 ms of the output they depend on).

Each run writes the two scenes (hmocap_examples.scenes) and drives them as test_example_apps
does, every node and app its own process over DDS on loopback: the depth bag through
gesture_detection into light_switch, the walk's body_tracker messages into presence. A
reaction time is the DDS publication time of the app's output minus that of the room's output
it answered (``/gestures``; ``/skeleton`` or ``/humans/bodies/tracked`` of the same stamp), both
on this machine's clock: the hop to the app and its work, not the pipeline before it.

    .venv/bin/python benchmarks/bench_apps.py [--runs 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
from pathlib import Path

import numpy as np

from hmocap_examples import scenes
from hmocap_examples.drive import drive_light_switch, drive_presence, light_reactions, reaction_ms
from hmocap_ros.processes import loopback_dds_env


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="drives of each app")
    ns = ap.parse_args(argv)
    env = loopback_dds_env(domain_id=int(os.environ.get("ROS_DOMAIN_ID", "42")))
    light, presence = [], []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        gesture_bag, walk_bag = scenes.gesture_scene(out), scenes.walk_scene(out)
        for run in range(ns.runs):
            ms = [m for _, m in light_reactions(drive_light_switch(gesture_bag, out / f"light{run}", env))]
            print(f"light_switch run {run}: toggles {len(ms)}, reaction ms {', '.join(f'{m:.1f}' for m in ms)}")
            light += ms
            drive = drive_presence(walk_bag, out / f"presence{run}", env, changes=6)
            inputs = drive.messages["/skeleton"] + drive.messages["/humans/bodies/tracked"]
            ms = [m for _, m in reaction_ms(inputs, drive.messages["/presence"][1:])]
            print(f"presence run {run}: changes {len(ms)}, reaction ms {', '.join(f'{m:.1f}' for m in ms)}")
            presence += ms
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs; "
          "times: DDS source timestamps (system clock)")
    for name, ms in (("light_switch", light), ("presence", presence)):
        if ms:
            print(f"{name}: {len(ms)} reactions, median {np.median(ms):.1f} ms, max {max(ms):.1f} ms "
                  f"(target < 200 ms: {'met' if max(ms) < 200 else 'missed'})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
