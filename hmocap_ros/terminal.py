"""How the command-line front ends meet the terminal: Ctrl-C, a closed pipe, help in plain text.

``hmocap ... | head -1`` closes the pipe after one line; Ctrl-C raises ``KeyboardInterrupt``
wherever the program is. Neither is an error of the program: :class:`TerminalManners` ends
it without a traceback, with the shell's exit status (130 for Ctrl-C, 141 for a closed pipe,
as a program killed by SIGINT or SIGPIPE) and, for a closed pipe, standard output pointed at
``/dev/null`` so that the interpreter's last flush cannot fail in turn.
"""

from __future__ import annotations

import os
import re
import sys

__all__ = ["EXIT_CLOSED_PIPE", "EXIT_INTERRUPTED", "TerminalManners", "plain_text", "silence_stdout"]

#: Exit status after Ctrl-C (128 + SIGINT), as a shell reports a program that SIGINT ended.
EXIT_INTERRUPTED = 130
#: Exit status after the reader of standard output went away (128 + SIGPIPE).
EXIT_CLOSED_PIPE = 141


def silence_stdout() -> None:
    """Point standard output at /dev/null (its reader is gone): later writes and the final
    flush go nowhere instead of raising ``BrokenPipeError``."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (AttributeError, OSError, ValueError):  # a replaced sys.stdout (pytest's capture)
        pass
    finally:
        os.close(devnull)


class TerminalManners:
    """A context that ends Ctrl-C and a closed standard output quietly: ``status`` is then
    :data:`EXIT_INTERRUPTED` (a line ``interrupted`` on stderr) or :data:`EXIT_CLOSED_PIPE`;
    None while neither happened. Other exceptions pass."""

    def __init__(self, program: str = "hmocap"):
        self.program = program
        self.status: int | None = None

    def __enter__(self) -> TerminalManners:
        return self

    def __exit__(self, kind, err, _tb) -> bool:
        if kind is not None and issubclass(kind, KeyboardInterrupt):
            self.status = EXIT_INTERRUPTED
            try:
                print(f"{self.program}: interrupted", file=sys.stderr, flush=True)
            except OSError:
                pass
            return True
        if kind is not None and issubclass(kind, BrokenPipeError):
            self.status = EXIT_CLOSED_PIPE
            silence_stdout()
            return True
        return False


_ROLE = re.compile(r":[a-z]+(?::[a-z]+)?:`([^`]*)`")
_LITERAL = re.compile(r"``([^`]*)``")


def _role_text(match: re.Match) -> str:
    text = match.group(1)
    titled = re.fullmatch(r"(.*?)\s*<[^>]*>", text, re.S)
    if titled:
        return titled.group(1)
    return text.lstrip("~").rsplit(".", 1)[-1] if text.startswith("~") else text


def plain_text(doc: str) -> str:
    """A docstring's reStructuredText markup as a terminal shows it: ``code`` and
    :mod:`roles` as their text (``:class:`~a.b.C``` as ``C``, ``:meth:`title <target>``` as
    ``title``), ``::`` ending a paragraph as ``:``."""
    text = _ROLE.sub(_role_text, doc)
    text = _LITERAL.sub(r"\1", text)
    return re.sub(r"(\S)::$", r"\1:", text, flags=re.M)
