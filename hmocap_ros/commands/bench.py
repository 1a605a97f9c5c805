"""``hmocap bench [NAME...] [-- ARGS]``: run the benchmark scripts of the source checkout
(``benchmarks/bench_NAME.py``) with this interpreter, all of them when no NAME is given; the
scripts print what they measure. Exit status 2 with one line when the checkout has no
``benchmarks/`` folder or a NAME is unknown, else the first failing script's."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

__all__ = ["BENCH_DIR", "add_arguments", "benchmarks", "main_from_args", "split_arguments"]

#: The source checkout's benchmark scripts (absent from an installed package).
BENCH_DIR = Path(__file__).resolve().parents[2] / "benchmarks"


def benchmarks() -> list[str]:
    """The NAMEs of ``benchmarks/bench_NAME.py``, sorted."""
    return sorted(p.stem[len("bench_"):] for p in BENCH_DIR.glob("bench_*.py"))


def split_arguments(own: list[str]) -> tuple[list[str], list[str]]:
    """Split ``bench NAME... [ARGS]`` into hmocap's part and the scripts': everything after
    ``--``, or after the leading benchmark names (``hmocap bench pipeline BAG --json OUT``)."""
    if "--" in own:
        i = own.index("--")
        return own[:i], own[i + 1:]
    available = set(benchmarks())
    n = 1
    while n < len(own) and own[n] in available:
        n += 1
    return (own[:n], own[n:]) if n > 1 else (own, [])


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("names", nargs="*", metavar="NAME",
                        help=f"benchmarks to run ({', '.join(benchmarks()) or 'none found'})")


def main_from_args(ns: argparse.Namespace) -> int:
    """Run the named scripts in turn with ``ns.extra`` (the arguments :func:`split_arguments`
    left to the scripts)."""
    available = benchmarks()
    if not available:
        print(f"hmocap bench: no benchmarks/ folder next to the package ({BENCH_DIR}): the benchmark "
              "scripts live in the source checkout", file=sys.stderr)
        return 2
    names = ns.names or available
    unknown = [n for n in names if n not in available]
    if unknown:
        print(f"hmocap bench: unknown {', '.join(unknown)}; available: {', '.join(available)}", file=sys.stderr)
        return 2
    for name in names:
        print(f"== benchmarks/bench_{name}.py", flush=True)
        rc = subprocess.call([sys.executable, str(BENCH_DIR / f"bench_{name}.py"), *getattr(ns, "extra", [])])
        if rc:
            return rc
    return 0
