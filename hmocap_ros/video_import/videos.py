"""Video files read frame by frame with OpenCV, several at once (no rclpy).

:func:`probe_video` opens a file and decodes its first frame (the size a player shows, after any
rotation the container asks for); :class:`FrameSetReader` decodes each video in its own thread
(OpenCV's decoder releases the GIL) a few frames ahead of the caller and hands out frame sets:
frame ``first[k] + i`` of every video ``k`` for ``i = 0, 1, ...`` (synchronisation by frame
index, with a per-video offset in ``first``), each frame passed through the video's ``convert``
function in its decoder thread (turning, resizing and colour conversion run on all cores while
the caller writes). Frames are skipped with ``grab()`` (demuxed and
decoded, not converted), which lands on the exact frame where a seek may not.
"""
from __future__ import annotations

import queue
import threading
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

__all__ = ["FrameSetReader", "VideoError", "VideoInfo", "probe_video"]

#: Frame sets decoded ahead of the caller, per video.
PREFETCH = 4


class VideoError(ValueError):
    """A video that cannot be opened or decoded (one line for the user)."""


@dataclass(frozen=True)
class VideoInfo:
    """A video file: decoded frame size (width, height), frame rate and frame count (as its
    container states them; 0 when it does not)."""

    path: Path
    width: int
    height: int
    fps: float
    frames: int


def probe_video(path: str | Path) -> VideoInfo:
    """Open ``path`` and decode its first frame; :class:`VideoError` for a file that is missing,
    not a video, or has no decodable frame."""
    path = Path(path)
    if not path.is_file():
        raise VideoError(f"{path}: no such video file")
    capture = cv2.VideoCapture(str(path))
    try:
        if not capture.isOpened():
            raise VideoError(f"{path}: not a video OpenCV can open")
        ok, frame = capture.read()
        if not ok or frame is None or frame.ndim != 3:
            raise VideoError(f"{path}: no decodable frame")
        fps = float(capture.get(cv2.CAP_PROP_FPS) or 0.0)
        frames = int(capture.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
    finally:
        capture.release()
    if not np.isfinite(fps) or fps <= 0:
        raise VideoError(f"{path}: the file states no frame rate")
    return VideoInfo(path, int(frame.shape[1]), int(frame.shape[0]), fps, max(frames, 0))


class _Decoder(threading.Thread):
    """Decodes one video from frame ``first`` into a bounded queue; ``None`` ends it."""

    def __init__(self, path: Path, first: int, count: int, convert=None):
        super().__init__(daemon=True)
        self.path, self.first, self.count, self.convert = path, first, count, convert
        self.frames: queue.Queue = queue.Queue(maxsize=PREFETCH)
        self.error: str | None = None
        self._halt = threading.Event()

    def run(self) -> None:
        capture = cv2.VideoCapture(str(self.path))
        try:
            for _ in range(self.first):
                if self._halt.is_set() or not capture.grab():
                    self.error = f"{self.path}: ends before frame {self.first}"
                    return
            for _ in range(self.count):
                ok, frame = capture.read()
                if not ok or self._halt.is_set():
                    return
                if self.convert is not None:
                    frame = self.convert(frame)
                while not self._halt.is_set():
                    try:
                        self.frames.put(frame, timeout=0.1)
                        break
                    except queue.Full:
                        continue
        finally:
            capture.release()
            self._put_end()

    def _put_end(self) -> None:
        while True:
            try:
                self.frames.put(None, timeout=0.1)
                return
            except queue.Full:
                if self._halt.is_set():
                    return

    def stop(self) -> None:
        self._halt.set()


class FrameSetReader:
    """Frame sets of several videos (module docstring): iterate for lists of frames, one per
    video (BGR uint8 as decoded, or what ``convert[k]`` makes of them), at most ``count``;
    iteration ends at the first video that ends. Use as a context manager (the threads stop on
    exit). ``ended_early``: the videos that ended before ``count`` sets, after iteration."""

    def __init__(self, paths, first: list[int], count: int, convert=None):
        convert = convert or [None] * len(paths)
        self._decoders = [_Decoder(Path(p), int(f), int(count), c)
                          for p, f, c in zip(paths, first, convert)]
        self.ended_early: list[Path] = []

    def __enter__(self) -> "FrameSetReader":
        for decoder in self._decoders:
            decoder.start()
        return self

    def __exit__(self, *exc) -> None:
        for decoder in self._decoders:
            decoder.stop()
        for decoder in self._decoders:
            while decoder.is_alive():
                try:
                    decoder.frames.get_nowait()
                except queue.Empty:
                    decoder.join(timeout=0.05)

    def __iter__(self):
        yielded = 0
        while True:
            frames = [decoder.frames.get() for decoder in self._decoders]
            if any(frame is None for frame in frames):
                if yielded < self._decoders[0].count:
                    self.ended_early = [d.path for d, f in zip(self._decoders, frames) if f is None]
                errors = [d.error for d in self._decoders if d.error]
                if errors:
                    raise VideoError(errors[0])
                return
            yielded += 1
            yield frames
