#!/usr/bin/env python
"""Write config/<node>.yaml from a node's parameter dataclasses (defaults and descriptions).

    .venv/bin/python tools/write_node_config.py foreground_segmentation \
        hmocap_ros.nodes.foreground_segmentation:ForegroundNodeConfig hmocap_ros.segmentation:ForegroundParams
"""

import dataclasses
import importlib
import sys
import textwrap
from pathlib import Path


def _yaml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list):
        return "[" + ", ".join(f'"{x}"' if isinstance(x, str) else repr(x) for x in value) + "]"
    if isinstance(value, str):
        return f'"{value}"'
    return repr(value)


def main() -> None:
    node, *specs = sys.argv[1:]
    lines = [f"# Parameters of {node} (see `{node} --help`).", f"{node}:", "  ros__parameters:"]
    for spec in specs:
        module, name = spec.split(":")
        cls = getattr(importlib.import_module(module), name)
        for field in dataclasses.fields(cls):
            default = field.default if field.default is not dataclasses.MISSING else field.default_factory()
            lines += ["    # " + line for line in textwrap.wrap(field.metadata.get("description", ""), 95)]
            if isinstance(default, list) and not default:
                lines.append(f"    # {field.name}: []   (left out: an empty list has no type in ROS YAML)")
            else:
                lines.append(f"    {field.name}: {_yaml_value(default)}")
    path = Path(__file__).resolve().parents[1] / "config" / f"{node}.yaml"
    path.write_text("\n".join(lines) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
