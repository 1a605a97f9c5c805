"""Notice that a model file was written again, so a node reloads it without a restart.

``gesture_trainer`` writes its forest file atomically (a temporary file renamed into place,
:func:`~hmocap_ros.gestures.forest_file.save_forest`): a reader never sees half a file, and the
path then names a new inode. :class:`FileWatch` keeps the file's signature (inode, size,
modification time in ns) and :meth:`FileWatch.changed` says when it differs from the one last
seen (a file that appears counts; one that disappears does not: the node keeps what it has).
A node polls it on a timer (``gesture_detection``'s ``watch_period_s``); polling a ``stat``
once a second costs nothing and needs no inotify, and works on any file system.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["FileWatch", "file_signature"]


def file_signature(path) -> tuple | None:
    """(inode, size, mtime ns) of ``path``, None when it cannot be read."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_ino, st.st_size, st.st_mtime_ns


class FileWatch:
    """The signature of ``path`` as last seen (module docstring)."""

    def __init__(self, path):
        self.path = Path(path)
        self.signature = file_signature(self.path)

    def changed(self) -> bool:
        """True once per change of the file since the last call (or since construction) when
        the file is there now."""
        signature = file_signature(self.path)
        if signature == self.signature:
            return False
        self.signature = signature
        return signature is not None
