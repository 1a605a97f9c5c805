"""Write a file whole or not at all."""

from __future__ import annotations

import os
import secrets
from pathlib import Path

__all__ = ["write_text_atomically"]


def write_text_atomically(path: str | Path, text: str) -> Path:
    """Write ``text`` to a hidden file beside ``path`` and rename it onto ``path``: a reader,
    or a run that is interrupted, never sees a half-written file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    staging = path.with_name(f".{path.name}.{secrets.token_hex(4)}.partial")
    try:
        with open(staging, "x", encoding="utf-8", newline="\n") as f:
            f.write(text)
        os.replace(staging, path)
    finally:
        staging.unlink(missing_ok=True)
    return path
