#!/usr/bin/env python
"""Write test/data/rosdep_keys_jazzy.txt: the rosdep keys that resolve for ROS 2 Jazzy on Ubuntu 24.04.

From a checkout of the rosdistro index (github.com/ros/rosdistro) at one commit:

- every key of ``rosdep/base.yaml`` and ``rosdep/python.yaml`` with a rule for Ubuntu noble
  (a package list, a ``noble`` or ``*`` entry, or a pip rule), and
- every package released in ``jazzy/distribution.yaml`` (its name is its key),

one key a line, sorted, after a header naming the commit. ``test/test_workspace.py`` checks every
key of both package.xml files against it, as ``rosdep install`` would resolve them.

    .venv/bin/python tools/rosdep_keys.py /path/to/rosdistro COMMIT
"""
from __future__ import annotations

import argparse
from pathlib import Path

import yaml

OUT = Path(__file__).resolve().parents[1] / "test" / "data" / "rosdep_keys_jazzy.txt"
UBUNTU = "noble"


def resolves_on_noble(rule) -> bool:
    """Whether a rosdep rule of one key has something to install on Ubuntu noble."""
    if not isinstance(rule, dict):
        return False
    if "pip" in rule:
        return True
    ubuntu = rule.get("ubuntu")
    if isinstance(ubuntu, list):
        return bool(ubuntu)
    if isinstance(ubuntu, dict):
        if "pip" in ubuntu or "packages" in ubuntu:
            return True
        release = ubuntu.get(UBUNTU, ubuntu.get("*"))
        return bool(release)
    return False


def released_packages(distribution: dict) -> set[str]:
    out = set()
    for name, repo in (distribution.get("repositories") or {}).items():
        release = repo.get("release") or {}
        if not release.get("version"):
            continue
        out.update(release.get("packages") or [name])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rosdistro", type=Path, help="checkout of github.com/ros/rosdistro")
    parser.add_argument("commit", help="its commit (written in the header)")
    ns = parser.parse_args()
    keys = set()
    for name in ("base.yaml", "python.yaml"):
        rules = yaml.safe_load((ns.rosdistro / "rosdep" / name).read_text())
        keys |= {key for key, rule in rules.items() if resolves_on_noble(rule)}
    keys |= released_packages(yaml.safe_load((ns.rosdistro / "jazzy" / "distribution.yaml").read_text()))
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(f"# rosdep keys resolving for ROS 2 Jazzy on Ubuntu {UBUNTU}: rosdep/base.yaml, rosdep/python.yaml\n"
                   f"# and the packages of jazzy/distribution.yaml of github.com/ros/rosdistro at {ns.commit}\n"
                   f"# (tools/rosdep_keys.py writes this file)\n" + "\n".join(sorted(keys)) + "\n")
    print(f"wrote {len(keys)} keys to {OUT}")


if __name__ == "__main__":
    main()
