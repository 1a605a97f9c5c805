"""Parameter dataclasses: described fields, groups, dotted names and ``KEY=VALUE`` overrides.

An algorithm's settings are one frozen dataclass. Each field is made by :func:`param` (a
default and a description: what the setting does, its unit and range) or by :func:`group`
(a nested frozen dataclass of related settings, handed down whole to the part that uses
them). The same class then serves every front end without importing any of them:

- a ROS node declares one parameter per leaf, named by its dotted path
  (``startup.min_views``), so a parameter file reads as groups
  (:mod:`hmocap_ros.nodes.common`);
- command-line tools take ``KEY=VALUE`` overrides with dotted keys (:func:`field_overrides`,
  :func:`replace_dotted`);
- reports store the settings as a flat ``{dotted name: value}`` record (:func:`flat_record`).
"""
from __future__ import annotations

import dataclasses
import typing
from collections.abc import Iterator
from dataclasses import MISSING, Field

__all__ = ["flat_fields", "flat_record", "from_flat", "field_overrides", "group", "param",
           "replace_dotted"]


def param(default, description: str, read_only: bool = False):
    """A dataclass field with a ``description`` (and ``read_only`` flag) in its metadata.

    A list default becomes a ``default_factory`` (a frozen dataclass turns it into a tuple in
    its ``__post_init__`` when it must stay immutable)."""
    metadata = {"description": description, "read_only": read_only}
    if isinstance(default, list):
        return dataclasses.field(default_factory=lambda: list(default), metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def group(cls, description: str = ""):
    """A field holding a nested parameter dataclass ``cls`` (its defaults by default)."""
    return dataclasses.field(default_factory=cls, metadata={"description": description,
                                                            "group": cls})


def _is_group(f: Field) -> bool:
    return "group" in f.metadata


def _default(f: Field):
    if f.default is not MISSING:
        return f.default
    if not callable(f.default_factory):
        raise TypeError(f"parameter field {f.name!r} has no default")
    return f.default_factory()


def flat_fields(cls, prefix: str = "") -> Iterator[tuple[str, Field, typing.Any, typing.Any]]:
    """Every leaf of ``cls`` as ``(dotted name, field, default, type)``, groups expanded in
    declaration order."""
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if _is_group(f):
            yield from flat_fields(f.metadata["group"], f"{prefix}{f.name}.")
        else:
            yield f"{prefix}{f.name}", f, _default(f), hints[f.name]


def flat_record(obj) -> dict:
    """``obj``'s settings as ``{dotted name: value}`` (what a report stores)."""
    out = {}
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if _is_group(f):
            out.update({f"{f.name}.{k}": v for k, v in flat_record(value).items()})
        else:
            out[f.name] = value
    return out


def from_flat(cls, values: dict):
    """An instance of ``cls`` from ``{dotted name: value}``; names not given keep their
    defaults. ValueError names an unknown key."""
    known = {name for name, *_ in flat_fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}")
    return _build(cls, values, "")


def _build(cls, values: dict, prefix: str):
    kwargs = {}
    for f in dataclasses.fields(cls):
        name = f"{prefix}{f.name}"
        if _is_group(f):
            if any(k.startswith(name + ".") for k in values):
                kwargs[f.name] = _build(f.metadata["group"], values, name + ".")
        elif name in values:
            kwargs[f.name] = values[name]
    return cls(**kwargs)


def replace_dotted(obj, values: dict):
    """A copy of ``obj`` with ``{dotted name: value}`` replaced (groups rebuilt)."""
    record = flat_record(obj)
    unknown = sorted(set(values) - set(record))
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}")
    record.update(values)
    return from_flat(type(obj), record)


def field_overrides(cls, items, what: str = "parameter") -> dict:
    """``{dotted name: typed value}`` of ``cls`` from ``KEY=VALUE`` strings.

    Each value is typed as the field's default (``true``/``yes``/``on``/``1`` for a bool); a
    list field takes comma-separated numbers. ValueError names a malformed item or an unknown
    key (``what``: how the message calls the fields)."""
    known = {name: default for name, _, default, _ in flat_fields(cls)}
    out: dict[str, typing.Any] = {}
    for item in items or []:
        if "=" not in item:
            raise ValueError(f"expected KEY=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        if key not in known:
            raise ValueError(f"unknown {what} {key!r}; known: {sorted(known)}")
        default = known[key]
        if isinstance(default, (list, tuple)):
            out[key] = [float(v) for v in value.split(",") if v.strip()]
        elif isinstance(default, bool):
            out[key] = value.lower() in ("1", "true", "yes", "on")
        else:
            out[key] = type(default)(value)
    return out
