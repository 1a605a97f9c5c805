"""The ChArUco board: its layout (:class:`BoardSpec`), the OpenCV board and its corners.

Board frame (OpenCV's): the origin is the outer corner of the board next to the first square,
x along the ``columns`` squares, y along the ``rows`` squares, both in the board plane, z = x
cross y pointing away from the printed face. Inner chessboard corner ``id`` sits at
``((id % (columns - 1) + 1) * square, (id // (columns - 1) + 1) * square, 0)``.
"""

from __future__ import annotations

import argparse
import re
from dataclasses import dataclass

import numpy as np

__all__ = ["BoardSpec", "add_board_arguments", "board_from_args", "parse_board_size"]


def parse_board_size(text: str) -> tuple[int, int]:
    """``"7x5"`` -> ``(7, 5)``: squares along x, then along y."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", str(text))
    if not match:
        raise ValueError(f"board size must look like 7x5 (squares along x, then y), got {text!r}")
    cols, rows = int(match.group(1)), int(match.group(2))
    if cols < 3 or rows < 3:
        raise ValueError(f"a ChArUco board needs at least 3x3 squares, got {cols}x{rows}")
    return cols, rows


@dataclass(frozen=True)
class BoardSpec:
    """A ChArUco board: ``columns`` x ``rows`` squares of ``square`` metres, ArUco markers of
    ``marker`` metres from the OpenCV dictionary ``dictionary`` (e.g. ``DICT_4X4_50``)."""

    columns: int = 7
    rows: int = 5
    square: float = 0.16
    marker: float = 0.12
    dictionary: str = "DICT_4X4_50"

    def __post_init__(self) -> None:
        import cv2

        if self.columns < 3 or self.rows < 3:
            raise ValueError(f"a ChArUco board needs at least 3x3 squares, got {self.columns}x{self.rows}")
        if not 0 < self.marker < self.square:
            raise ValueError(f"marker size {self.marker} m must be positive and below the square size {self.square} m")
        if not self.dictionary.startswith("DICT_") or not hasattr(cv2.aruco, self.dictionary):
            raise ValueError(f"unknown ArUco dictionary {self.dictionary!r} (e.g. DICT_4X4_50, DICT_5X5_100)")
        n_markers = self.n_markers
        size = int(self.dictionary.split("_")[-1]) if self.dictionary.split("_")[-1].isdigit() else n_markers
        if size < n_markers:
            raise ValueError(f"a {self.columns}x{self.rows} board has {n_markers} markers, "
                             f"more than {self.dictionary} holds ({size})")

    @property
    def n_markers(self) -> int:
        return (self.columns * self.rows) // 2

    @property
    def n_corners(self) -> int:
        return (self.columns - 1) * (self.rows - 1)

    @property
    def size_m(self) -> tuple[float, float]:
        """Width (x) and height (y) of the board in metres."""
        return self.columns * self.square, self.rows * self.square

    def describe(self) -> str:
        return (f"{self.columns}x{self.rows} squares of {self.square * 100:g} cm, markers of "
                f"{self.marker * 100:g} cm, {self.dictionary}")

    def cv_board(self):
        """The ``cv2.aruco.CharucoBoard`` (OpenCV >= 4.7), or the board of the older aruco API
        (``CharucoBoard_create``: OpenCV 4.6 with the contrib modules, Ubuntu 24.04's); both lay
        the markers out alike."""
        import cv2

        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        if hasattr(cv2.aruco, "CharucoDetector"):
            return cv2.aruco.CharucoBoard((self.columns, self.rows), self.square, self.marker, dictionary)
        return cv2.aruco.CharucoBoard_create(self.columns, self.rows, self.square, self.marker, dictionary)

    def corner_points(self) -> np.ndarray:
        """(n_corners, 3) inner-corner positions in the board frame (metres), by corner id."""
        i = np.arange(self.n_corners)
        cols = self.columns - 1
        return np.stack([(i % cols + 1) * self.square, (i // cols + 1) * self.square,
                         np.zeros(self.n_corners)], axis=1)

    def image(self, pixels_per_square: int) -> np.ndarray:
        """The printed face as a uint8 grey image, ``pixels_per_square`` per square, no margin:
        pixel (col, row) covers board x in [col, col + 1) / pixels_per_square * square."""
        w, h = self.columns * pixels_per_square, self.rows * pixels_per_square
        board = self.cv_board()
        draw = board.generateImage if hasattr(board, "generateImage") else board.draw  # OpenCV 4.6: draw
        return draw((w, h), marginSize=0, borderBits=1)


def add_board_arguments(parser: argparse.ArgumentParser) -> None:
    """``--board --square --marker --dict`` (``hmocap calibrate``, ``hmocap sim calibration``)."""
    default = BoardSpec()
    parser.add_argument("--board", default=f"{default.columns}x{default.rows}",
                        help=f"squares along x, then y (default {default.columns}x{default.rows})")
    parser.add_argument("--square", type=float, default=default.square,
                        help=f"square side in metres (default {default.square})")
    parser.add_argument("--marker", type=float, default=default.marker,
                        help=f"ArUco marker side in metres (default {default.marker})")
    parser.add_argument("--dict", default=default.dictionary,
                        help=f"OpenCV ArUco dictionary (default {default.dictionary})")


def board_from_args(ns: argparse.Namespace) -> BoardSpec:
    """The board of :func:`add_board_arguments`' options."""
    cols, rows = parse_board_size(ns.board)
    return BoardSpec(cols, rows, float(ns.square), float(ns.marker), str(ns.dict))
