"""Docstrings, comments and parameter descriptions say what the code does, never its results.

A measured figure (an error in mm, an AP, a timing, a before -> after pair, a speed-up) belongs
in the docs beside the command that makes it (docs/tracking.md, docs/gestures.md,
docs/development.md, "Costs the code is shaped by"); the code states the choice and points
there. This test reads every module of ``hmocap_ros/`` with ``ast`` and ``tokenize`` and scans
its docstrings, its comments and the descriptions given to ``param(...)``, ``group(...)`` and
argparse's ``help=`` for :data:`PATTERNS`. Units that describe a value without a figure
("in mm", "uint16 mm", "1/8 mm") pass. Fails with file:line of every hit.
"""
from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "hmocap_ros"

# A number as written in prose: 3, 0.82, 3,500, 1.5-2 (not a digit inside a word: 16UC1, uint16).
_NUMBER = r"(?<![\w/.,])\d[\d,]*(?:\.\d+)?"
_TIME_UNIT = r"(?:ns|us|µs|ms|s|seconds?)\b"

PATTERNS = {
    # an error or a size found by a run: "1.5 mm", "56.9-60 mm"
    "millimetres": re.compile(_NUMBER + r"\s*mm\b"),
    # an average precision with its value: "AP 0.82", "AP of 0.36", "AP on held-out ... 0.81"
    "AP figure": re.compile(r"\bAP\b[^.;:\n]{0,40}?\b[01]\.\d\d?\b"),
    # a timing: "about 3 ms", "~60 ms", "161-175 ms"
    "timing": re.compile(r"(?:\babout|~|≈)\s*" + _NUMBER + r"\s*" + _TIME_UNIT
                         + r"|" + _NUMBER + r"\s*-\s*\d[\d.]*\s*" + _TIME_UNIT),
    # the machine a figure was measured on
    "machine": re.compile(r"\b\d+-core\b|\bon \d+ cores\b"),
    # a before -> after pair with a unit
    "before -> after": re.compile(r"\d\s*(?:mm|ms|s|%)?\s*->\s*\d[\d.]*\s*(?:mm|ms|s\b|%)"),
    # a speed-up: "2.5-3 times faster", "6x slower"
    "speed-up": re.compile(_NUMBER + r"(?:\s*-\s*\d[\d.]*)?\s*(?:x|times)\s+(?:faster|slower)\b"),
}

# Units named for what a value is, not a figure: the depth units of REP 118 and of raw
# SR300/SR305 images; a sensor model's value at a distance ("1.5 mm at 1 m").
ALLOWED = re.compile(r"\b0\.1 mm\b|~?\d[\d.]*\s*(?:mm|cm) at \d[\d.]*\s*m\b")

# Figures still to move into the docs, as (file, matched text): each entry must still match
# (the test fails on a stale one), so the list only shrinks.
KNOWN_HITS: set[tuple[str, str]] = set()

_DESCRIBING_CALLS = {"param": 1, "group": 1}


def _string_of(node: ast.AST) -> str | None:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return "".join(v.value for v in node.values
                       if isinstance(v, ast.Constant) and isinstance(v.value, str))
    return None


def described_texts(source: str) -> list[tuple[int, str]]:
    """(first line, text) of every docstring, comment, ``param``/``group`` description and
    ``help=`` string of a module's ``source``."""
    tree = ast.parse(source)
    texts: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc is not None:
                texts.append((node.body[0].lineno, doc))
        elif isinstance(node, ast.Call):
            func = node.func
            name = func.id if isinstance(func, ast.Name) else getattr(func, "attr", "")
            candidates = []
            position = _DESCRIBING_CALLS.get(name)
            if position is not None and len(node.args) > position:
                candidates.append(node.args[position])
            candidates += [k.value for k in node.keywords if k.arg in ("description", "help")]
            for candidate in candidates:
                text = _string_of(candidate)
                if text is not None:
                    texts.append((candidate.lineno, text))
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            texts.append((token.start[0], token.string))
    return texts


def figure_hits(text: str) -> list[tuple[int, str, str]]:
    """(line offset, pattern name, matched text) of every measured figure in ``text``."""
    hits = []
    for offset, line in enumerate(text.splitlines()):
        line = ALLOWED.sub("", line)
        for name, pattern in PATTERNS.items():
            hits += [(offset, name, m.group(0)) for m in pattern.finditer(line)]
    return hits


def module_hits(source: str) -> list[tuple[int, str, str]]:
    """(line, pattern name, matched text) of every figure in a module's described texts."""
    return [(first + offset, name, found)
            for first, text in described_texts(source)
            for offset, name, found in figure_hits(text)]


@pytest.mark.parametrize("text", [
    "a tighter 1.15 gained 1.5 mm over the 12 limb joints",
    "the shape is 20 mm per entity off",
    "``tee``'s AP on held-out subjects went from 0.81 to 0.79",
    "gave a mean AP of 0.36 against 0.65 without",
    "AP 0.82 / 0.82 with 100",
    "building the Jazzy typestore takes ~60 ms",
    "forward kinematics only, about 3 ms for 256 particles",
    "4 views in 161-175 ms per frame set",
    "1.5-2 s on that frame",
    "measured on the 2-core machine",
    "56.9 -> 49.2 mm",
    "it ran the model 2.5-3 times faster than OpenCV's dnn module",
    "a shared helper makes it 6x slower",
])
def test_the_patterns_catch_measured_figures(text):
    assert figure_hits(text), text


@pytest.mark.parametrize("text", [
    "depth in mm (REP 118)", "raw 1/8 mm values of an SR300", "16UC1 mm", "uint16 mm",
    "Units offered: mm, 1/8 mm, 0.1 mm, metres", "stamps within 10 ms",
    "25 holds one second at 25 fps",
    "640x480 -> 160x120", "the AP of each class", "3,500 weight evaluations per frame",
    "every 25 frames", "a 5 cm margin", "2 LiteRT threads", "exp(-spread / 5 cm)",
    "(default 1.5 mm at 1 m, 13.5 mm at 3 m)", "depth steps of ~3 mm at 1 m",
])
def test_the_patterns_pass_unit_descriptions(text):
    assert not figure_hits(text), text


def test_described_texts_reads_docstrings_comments_and_descriptions():
    source = '''"""Module: 1.5 mm."""
x = param(1, "a description, ~60 ms")  # a comment, 6x slower
def f():
    """Function: AP 0.82."""
p.add_argument("--n", help="help text 2-core")
'''
    assert sorted((line, name) for line, name, _ in module_hits(source)) == [
        (1, "millimetres"), (2, "speed-up"), (2, "timing"), (4, "AP figure"), (5, "machine"),
    ]


def test_no_measured_figures_in_the_package():
    hits, known = [], set()
    for path in sorted(PACKAGE.rglob("*.py")):
        name = path.relative_to(ROOT).as_posix()
        for line, kind, found in module_hits(path.read_text(encoding="utf-8")):
            if (name, found) in KNOWN_HITS:
                known.add((name, found))
            else:
                hits.append(f"{name}:{line}: {found!r} ({kind})")
    assert known == KNOWN_HITS, f"entries of KNOWN_HITS that no longer match: {KNOWN_HITS - known}"
    assert not hits, (
        f"{len(hits)} measured figure(s) in docstrings, comments or parameter descriptions: "
        "state the choice and point to the doc that holds the figure and its command\n"
        + "\n".join(hits)
    )
