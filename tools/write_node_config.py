#!/usr/bin/env python
"""Write config/<node>.yaml from a node's parameter dataclasses (defaults and descriptions).

The parameters sit under ``/**`` (every node name and namespace), so the file serves a node
started in a namespace or under another name as well as the plain one.

    .venv/bin/python tools/write_node_config.py foreground_segmentation \
        hmocap_ros.nodes.foreground_segmentation:ForegroundNodeConfig hmocap_ros.segmentation:ForegroundParams
"""

import argparse
import dataclasses
import importlib
import textwrap
from pathlib import Path


def _yaml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(f'"{x}"' if isinstance(x, str) else repr(x) for x in value) + "]"
    if isinstance(value, str):
        return f'"{value}"'
    return repr(value)


def _yaml_lines(cls, indent: str) -> list[str]:
    """A parameter dataclass as YAML: a comment and a value per leaf, groups nested."""
    lines = []
    for field in dataclasses.fields(cls):
        description = field.metadata.get("description", "")
        if "group" in field.metadata:
            lines += [f"{indent}# {line}" for line in textwrap.wrap(description, 95)]
            lines.append(f"{indent}{field.name}:")
            lines += _yaml_lines(field.metadata["group"], indent + "  ")
            continue
        default = field.default if field.default is not dataclasses.MISSING else field.default_factory()
        lines += [f"{indent}# {line}" for line in textwrap.wrap(description, 99 - len(indent))]
        if isinstance(default, (list, tuple)) and not default:
            lines.append(f"{indent}# {field.name}: []   (left out: an empty list has no type in ROS YAML)")
        else:
            lines.append(f"{indent}{field.name}: {_yaml_value(default)}")
    return lines


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("node", help="node name: writes config/<node>.yaml")
    ap.add_argument("specs", nargs="+", metavar="module:Class",
                    help="parameter dataclasses, in the file's order")
    ns = ap.parse_args(argv)
    node, specs = ns.node, ns.specs
    if not node.isidentifier():
        ap.error(f"node must be a node name such as body_tracker, got {node!r}")
    bad = [s for s in specs if s.count(":") != 1]
    if bad:
        ap.error(f"expected module:Class, got {bad}")
    # Under the wildcard /**, not the node's name: a node started in a namespace or under another
    # name (launch files, several instances) reads the file all the same.
    lines = [f"# Parameters of {node} (see `{node} --help`), for any node name and namespace.",
             "/**:", "  ros__parameters:"]
    for spec in specs:
        module, name = spec.split(":")
        cls = getattr(importlib.import_module(module), name)
        lines += _yaml_lines(cls, "    ")
    path = Path(__file__).resolve().parents[1] / "config" / f"{node}.yaml"
    path.write_text("\n".join(lines) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
