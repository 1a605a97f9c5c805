"""The product states what is, never how it came to be (STYLE.md, habit 13).

Scans every text file that git tracks for the vocabulary of work rounds and of the rules
settings were chosen by (:data:`PATTERNS`; the phrases each must and must not match are in
the tests below): that history belongs in commit messages, not in code, docs, config or
parameter descriptions. Fails with file:line of every hit.
"""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
THIS_FILE = Path(__file__).resolve().relative_to(ROOT).as_posix()

# Binary and data files: recordings, arrays, images, motion clips, meshes, generated tables.
SKIPPED_SUFFIXES = (
    ".mcap", ".db3", ".npz", ".npy", ".png", ".jpg", ".jpeg", ".gif", ".svg", ".pdf",
    ".bvh", ".obj", ".ply", ".stl", ".json", ".csv", ".pkl", ".bin", ".zip", ".tar.gz", ".gz",
)

# A number after the word that is a quantity (frames, seconds, a unit) is plain English.
_NOT_A_QUANTITY = r"(?!\d)(?![.,]?\d*\s*(?:%|mm|cm|m\b|ms|s\b|px|fps|frames?|seconds?|minutes?|times|degrees))"

PATTERNS = {
    # the word followed by a round's number; not the verb, not "non-stop"
    "work round (stop N)": re.compile(r"(?<![-\w])stops?\s+\d+" + _NOT_A_QUANTITY, re.IGNORECASE),
    # the hyphenated form of the same
    "work round (stop-N)": re.compile(r"(?<![-\w])stop-\d+", re.IGNORECASE),
    # a round named as a point in time, with or without its number
    "work round (until/since stop)": re.compile(r"\b(?:until|since)\s+stops?\b", re.IGNORECASE),
    # a lettered rule: the letter is a capital, so "as a rule a filter ..." passes
    "tuning rule (rule X)": re.compile(r"\b(?i:rules?)\s+[A-F]\b"),
    "tuning rule": re.compile(r"\btuning\s+rules?\b", re.IGNORECASE),
    # a numbered round; not "rounded", "round(x, 2)", "one mining round" or an option such as
    # "--mining-rounds 1"
    "work round (round N)": re.compile(r"(?<![-\w])rounds?\s+\d+", re.IGNORECASE),
    "work round": re.compile(r"\bwork\s+rounds?\b", re.IGNORECASE),
}


def _tracked_files() -> list[str]:
    if shutil.which("git") is None:
        pytest.skip("git is not available: cannot list the tracked files")
    try:
        result = subprocess.run(
            ["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=False, timeout=60
        )
    except (OSError, subprocess.SubprocessError) as exc:
        pytest.skip(f"git ls-files failed: {exc}")
    if result.returncode != 0:
        pytest.skip(f"not a git checkout ({result.stderr.decode(errors='replace').strip()})")
    return [name for name in result.stdout.decode("utf-8", errors="replace").split("\0") if name]


def _text_of(path: Path) -> str | None:
    """The file's text, or None for a binary, unreadable or missing file."""
    try:
        data = path.read_bytes()
    except OSError:  # listed by git but deleted in the working tree
        return None
    if b"\0" in data[:8192]:
        return None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return None


def history_hits(text: str) -> list[tuple[int, str, str]]:
    """(line number, pattern name, matched text) of every work-round phrase in ``text``."""
    hits = []
    for number, line in enumerate(text.splitlines(), start=1):
        for name, pattern in PATTERNS.items():
            for match in pattern.finditer(line):
                hits.append((number, name, match.group(0)))
    return hits


@pytest.mark.parametrize(
    "text",
    [
        "stop 27", "Stop 14's machine", "stops 11-13", "(stop 26: 48.5)", "since stop 15",
        "until stop", "the stop-12 row", "rule F", "tuning rules B and D", "a tuning rule",
        "round 3", "Rounds 2-4", "work rounds",
    ],
)
def test_the_patterns_catch_work_round_vocabulary(text):
    assert history_hits(text), text


@pytest.mark.parametrize(
    "text",
    [
        "the filter stops", "non-stop", "it stops 3 frames later", "growth stops at depth 20",
        "as a rule a filter weighs", "round(x, 2)", "rounded to 0.1", "one mining round",
        "rule-based", "a stop sign", "--mining-rounds 1", "stop_event.set()", "the run stopped",
    ],
)
def test_the_patterns_pass_ordinary_english(text):
    assert not history_hits(text), text


def test_no_work_round_vocabulary_in_tracked_files():
    hits = []
    for name in _tracked_files():
        if name == THIS_FILE or name.lower().endswith(SKIPPED_SUFFIXES):
            continue
        text = _text_of(ROOT / name)
        if text is None:
            continue
        hits += [f"{name}:{line}: {found!r} ({kind})" for line, kind, found in history_hits(text)]
    assert not hits, (
        f"{len(hits)} work-round phrase(s): the product says what is; history goes in commit "
        "messages (STYLE.md 13)\n" + "\n".join(hits)
    )
