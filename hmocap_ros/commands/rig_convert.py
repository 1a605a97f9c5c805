"""``hmocap rig convert IN OUT``: a camera calibration from one format into another.

Formats (:mod:`hmocap_ros.calibration.formats`): ``rig`` (this package's rig YAML), ``toml``
(Pose2Sim / Anipose), ``qca`` (Qualisys), ``opencv`` (EasyMocap's ``intri.yml`` + ``extri.yml``,
a folder), ``ros`` (a folder of camera_info YAML files with poses). ``IN``'s format is read from
its content (``--from`` to say it); ``OUT``'s from its name: ``.yaml``/``.yml`` a rig file,
``.toml``, ``.qca``/``.qca.txt``, ``intri.yml``/``intri.xml`` or a folder (``--to`` to say it;
a folder needs it).

The calibration passes through the room frame (+Y up, metres, floor at y = 0): ``--up``,
``--units`` and ``--floor`` say what ``IN``'s world is where its format does not; ``--to-up``
and ``--to-units`` choose ``OUT``'s world (default: the format's, Z-up for every format but the
rig). Errors (a file in none of the formats, a field missing, an up axis or unit that cannot be
told) are one line on stderr and exit status 2; nothing is written then.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_arguments", "main_from_args", "output_format", "parse_size"]

PROG = "hmocap rig convert"


def output_format(path: Path) -> str | None:
    """The format an output path names (module docstring), or None."""
    name = path.name.lower()
    if name.endswith((".qca", ".qca.txt")):
        return "qca"
    if name.endswith(".toml"):
        return "toml"
    if name.startswith("intri.") and path.suffix in (".yml", ".yaml", ".xml"):
        return "opencv"
    if path.suffix in (".yaml", ".yml"):
        return "rig"
    return None


def parse_size(text: str) -> tuple[int, int]:
    """``"1920x1080"`` -> (1920, 1080); ValueError otherwise."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"a size is WIDTHxHEIGHT, got {text!r}") from None
    if width <= 0 or height <= 0:
        raise ValueError(f"a size must be positive, got {text!r}")
    return width, height


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from hmocap_ros.calibration.formats import AXES, FORMATS, UNITS

    parser.add_argument("input", metavar="IN", help="calibration file or folder")
    parser.add_argument("output", metavar="OUT", help="file or folder to write")
    parser.add_argument("--from", dest="source_format", choices=tuple(FORMATS), default=None,
                        help="IN's format (default: from its content)")
    parser.add_argument("--to", dest="target_format", choices=tuple(FORMATS), default=None,
                        help="OUT's format (default: from its name)")
    parser.add_argument("--up", default=None, metavar="AXIS",
                        help=f"IN's up axis ({', '.join(AXES)}; default: what the format says, "
                             f"else the cameras' image-up direction)")
    parser.add_argument("--units", choices=tuple(UNITS), default=None,
                        help="IN's length unit (default: what the format says, else from the "
                             "cameras' spread)")
    parser.add_argument("--floor", type=float, default=0.0,
                        help="height of the floor along IN's up axis, in IN's unit (default 0: "
                             "the origin is on the floor)")
    parser.add_argument("--size", default=None, metavar="WxH",
                        help="image size of cameras whose file gives none")
    parser.add_argument("--to-up", default=None, metavar="AXIS",
                        help="OUT's up axis (default: the format's: +Y for a rig, else +Z)")
    parser.add_argument("--to-units", choices=tuple(UNITS), default=None,
                        help="OUT's length unit (default: the format's: mm for qca, else m)")
    parser.add_argument("--force", action="store_true", help="overwrite OUT")


def main_from_args(ns: argparse.Namespace) -> int:
    from hmocap_ros.calibration.formats import (
        CalibrationFormatError,
        detect_format,
        load_calibration_rig,
        read_calibration,
        save_calibration_rig,
    )

    output = Path(ns.output)
    target = ns.target_format or output_format(output)
    try:
        if target is None:
            raise ValueError(f"cannot tell OUT's format from {output.name!r}: give --to")
        if output.exists() and not ns.force:
            raise ValueError(f"{output} exists already (--force to overwrite it)")
        sizes = None
        if ns.size:
            size = parse_size(ns.size)
            names = read_calibration(ns.input, ns.source_format).names
            sizes = {name: size for name in names}
        rig, notes = load_calibration_rig(ns.input, format=ns.source_format, up=ns.up,
                                          units=ns.units, floor=ns.floor, sizes=sizes)
        source = ns.source_format or detect_format(ns.input)
        written = save_calibration_rig(rig, output, target, up=ns.to_up, units=ns.to_units)
    except (CalibrationFormatError, ValueError) as error:
        print(f"{PROG}: {error}", file=sys.stderr)
        return 2
    for note in notes:
        print(f"{PROG}: note: {note}", file=sys.stderr)
    print(f"{ns.input} ({source}) -> {', '.join(map(str, written))} ({target}): "
          f"{len(rig)} cameras ({', '.join(rig.names)})")
    return 0
