"""MCAP files without a summary: the trailer that seals them and a view that reads them.

A recording is written as chunks appended to the file, each followed by :data:`MCAP_TRAILER`
(a DataEnd record, a Footer that points to no summary, the closing magic), so the file is a
valid summary-less MCAP between writes. A file cut anywhere (process killed during a write,
power cut, disk full) is read through :class:`SealedMcap`: the file up to its last complete
record, followed by the same trailer. ``hmocap repair`` rewrites such a file with its summary.
"""

from __future__ import annotations

import io
import struct
from dataclasses import dataclass
from pathlib import Path

MCAP_MAGIC = b"\x89MCAP0\r\n"
_OP_FOOTER = 0x02
_OP_CHUNK = 0x06
_OP_DATA_END = 0x0F
_RECORD_HEAD = struct.Struct("<BQ")
# DataEnd (no data section CRC), Footer (summary start 0: no summary), closing magic.
MCAP_TRAILER = (
    _RECORD_HEAD.pack(_OP_DATA_END, 4) + struct.pack("<I", 0)
    + _RECORD_HEAD.pack(_OP_FOOTER, 20) + struct.pack("<QQI", 0, 0, 0)
    + MCAP_MAGIC
)


def has_summary(path: Path) -> bool:
    """Whether ``path`` ends with an MCAP footer that points to a summary section."""
    size = path.stat().st_size
    if size < len(MCAP_MAGIC) * 2 + 29:
        return False
    with path.open("rb") as f:
        f.seek(size - 37)
        tail = f.read(37)
    if tail[-8:] != MCAP_MAGIC or tail[0] != _OP_FOOTER:
        return False
    (summary_start,) = struct.unpack_from("<Q", tail, 9)
    return summary_start != 0


@dataclass(frozen=True)
class DataSection:
    """Where the data section of an MCAP file ends: ``end`` just past its last complete record
    (0 when the file does not start with the MCAP magic), ``chunks`` complete chunk records
    before it, and ``closed`` when a DataEnd record follows, as in a file that was closed."""

    end: int
    chunks: int
    closed: bool


def data_section(path: Path) -> DataSection:
    """Walk the records of an MCAP file by opcode and length only, up to a DataEnd or Footer
    record, a record that runs past the end of the file, or an opcode of 0 (the zero-filled
    tail a power cut can leave)."""
    size = path.stat().st_size
    with path.open("rb") as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            return DataSection(0, 0, False)
        end, chunks, closed = len(MCAP_MAGIC), 0, False
        while end + _RECORD_HEAD.size <= size:
            f.seek(end)
            opcode, length = _RECORD_HEAD.unpack(f.read(_RECORD_HEAD.size))
            if opcode in (0, _OP_DATA_END, _OP_FOOTER) or end + _RECORD_HEAD.size + length > size:
                closed = opcode == _OP_DATA_END and end + _RECORD_HEAD.size + length <= size
                break
            end += _RECORD_HEAD.size + length
            chunks += opcode == _OP_CHUNK
    return DataSection(end, chunks, closed)


class _SealedStream(io.RawIOBase):
    """Read-only bytes of ``path`` up to ``end``, followed by :data:`MCAP_TRAILER`."""

    def __init__(self, path: Path, end: int):
        super().__init__()
        self._file = path.open("rb")
        self._end = end
        self._size = end + len(MCAP_TRAILER)
        self._pos = 0

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def tell(self) -> int:
        return self._pos

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        base = {io.SEEK_SET: 0, io.SEEK_CUR: self._pos, io.SEEK_END: self._size}[whence]
        self._pos = max(0, base + offset)
        return self._pos

    def readinto(self, buffer) -> int:
        n = max(0, min(len(buffer), self._size - self._pos))
        view = memoryview(buffer)
        done = 0
        if self._pos < self._end:
            self._file.seek(self._pos)
            done = self._file.readinto(view[: min(n, self._end - self._pos)]) or 0
        if done < n:
            start = self._pos + done - self._end
            view[done:n] = MCAP_TRAILER[start : start + n - done]
            done = n
        self._pos += done
        return done

    def close(self) -> None:
        self._file.close()
        super().close()


@dataclass(frozen=True)
class SealedMcap:
    """A path-like stand-in for an MCAP file without summary that ``open()`` gives the file
    up to byte ``end`` (its last complete record) sealed with :data:`MCAP_TRAILER`; rosbags'
    reader and the ``mcap`` package read it as a complete summary-less MCAP."""

    path: Path
    end: int

    @property
    def name(self) -> str:
        return self.path.name

    @property
    def suffix(self) -> str:
        return self.path.suffix

    @property
    def dropped_bytes(self) -> int:
        """Bytes of the file past the last complete record (a record cut short)."""
        return max(0, self.path.stat().st_size - self.end - len(MCAP_TRAILER))

    def exists(self) -> bool:
        return self.path.exists()

    def is_dir(self) -> bool:
        return False

    def open(self, mode: str = "rb"):
        if mode != "rb":
            raise ValueError(f"{self.path} is opened for reading only")
        return io.BufferedReader(_SealedStream(self.path, self.end))

    def __str__(self) -> str:
        return str(self.path)


def recording_file(path: Path) -> Path:
    """The MCAP file of a bag: ``path`` itself, or the one ``.mcap`` of a rosbag2 directory."""
    if path.is_dir():
        files = sorted(path.glob("*.mcap"))
        if len(files) == 1:
            return files[0]
    return path


def summaryless_view(path: str | Path, salvage: bool = False) -> SealedMcap | None:
    """For a bag whose MCAP file is a recording that did not close, the :class:`SealedMcap`
    view of that file: no summary, and either sealed by :data:`MCAP_TRAILER` or cut after at
    least one complete chunk. None for a bag that is whole, or not MCAP, or damaged otherwise: a
    closed file cut inside its summary, a file cut inside its first chunk. With ``salvage``, any
    file with a complete header gets a view (what repair reads)."""
    path = Path(path)
    if path.is_dir() and (path / "metadata.yaml").exists():
        return None
    mcap_file = recording_file(path)
    if mcap_file.suffix != ".mcap" or not mcap_file.is_file() or has_summary(mcap_file):
        return None
    section = data_section(mcap_file)
    if section.end <= len(MCAP_MAGIC):
        return None
    view = SealedMcap(mcap_file, section.end)
    if salvage:
        return view
    if section.closed:
        sealed = mcap_file.stat().st_size == section.end + len(MCAP_TRAILER)
        return view if sealed else None
    return view if section.chunks else None
