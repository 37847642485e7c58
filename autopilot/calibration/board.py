"""The board a calibration views: its spec (``chessboard:…`` or ``charuco:…``), parsed and
checked."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import cv2
import numpy as np

from autopilot.calibration.common import BOARD_SPEC_FORM, Pattern
from autopilot.config import InputError
from drivers.markers import aruco_dictionary


@dataclass(frozen=True, slots=True)
class BoardSpec:
    """A calibration board: ``columns × rows`` squares of ``square_m``; a ChArUco board's
    markers are ``marker_m`` wide, from OpenCV's ``dictionary`` (e.g. ``DICT_5X5_100``)."""

    pattern: Pattern
    columns: int
    rows: int
    square_m: float
    marker_m: float | None = None
    dictionary: str | None = None

    @property
    def inner_corners(self) -> tuple[int, int]:
        """Inner corners per row and per column (OpenCV's chessboard ``patternSize``)."""
        return self.columns - 1, self.rows - 1

    @property
    def corner_count(self) -> int:
        return (self.columns - 1) * (self.rows - 1)

    @property
    def text(self) -> str:
        """The spec as ``--board`` takes it."""
        base = f"{self.pattern}:{self.columns}x{self.rows}:{self.square_m:g}"
        return base if self.pattern == "chessboard" else \
            f"{base}:{self.marker_m:g}:{self.dictionary}"

    def describe(self) -> str:
        cols, rows = self.inner_corners
        what = (f"ChArUco {self.columns}x{self.rows} squares of {self.square_m * 1e3:g} mm, "
                f"{self.marker_m * 1e3:g} mm {self.dictionary} markers"
                if self.pattern == "charuco" else
                f"chessboard {self.columns}x{self.rows} squares of {self.square_m * 1e3:g} mm")
        return f"{what} ({cols}x{rows} inner corners)"

    def object_points_m(self) -> np.ndarray:
        """Every inner corner in the board frame, by id, ``(N, 3)`` float32."""
        cols, rows = self.inner_corners
        ids = np.arange(cols * rows)
        return np.column_stack([(ids % cols + 1) * self.square_m,
                                (ids // cols + 1) * self.square_m,
                                np.zeros(len(ids))]).astype(np.float32)

    def outline_m(self) -> np.ndarray:
        """The pattern's outer corners in the board frame, ``(4, 3)``."""
        w, h = self.columns * self.square_m, self.rows * self.square_m
        return np.array([[0.0, 0.0, 0.0], [w, 0.0, 0.0], [w, h, 0.0], [0.0, h, 0.0]])

    def centre_m(self) -> np.ndarray:
        return np.array([self.columns * self.square_m / 2.0, self.rows * self.square_m / 2.0,
                         0.0])


def parse_board_spec(text: str) -> BoardSpec:
    """``chessboard:COLSxROWS:SQUARE_M`` or ``charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT``
    (:data:`BOARD_SPEC_FORM`); :class:`InputError` naming what is wrong otherwise."""

    def bad(why: str) -> InputError:
        return InputError(f"--board {text!r}: {why}; expected {BOARD_SPEC_FORM}")

    parts = [p.strip() for p in text.strip().split(":")]
    pattern = parts[0].lower()
    if pattern not in ("chessboard", "charuco"):
        raise bad(f"unknown pattern {parts[0]!r} (chessboard or charuco)")
    fields = 2 if pattern == "chessboard" else 4
    if len(parts) - 1 != fields:
        raise bad(f"a {pattern} takes {fields} fields after '{pattern}:', got "
                  f"{len(parts) - 1}")
    match = re.fullmatch(r"(\d+)\s*[xX×*]\s*(\d+)", parts[1])
    if match is None:
        raise bad(f"{parts[1]!r} is not COLSxROWS (two whole numbers of squares, e.g. 10x7)")
    columns, rows = int(match[1]), int(match[2])
    least = 4 if pattern == "chessboard" else 3  # OpenCV: more than 2 inner corners a side
    if min(columns, rows) < least:
        raise bad(f"a {pattern} needs at least {least}x{least} squares, got {columns}x{rows}")

    def length(name: str, value: str) -> float:
        try:
            number = float(value)
        except ValueError:
            raise bad(f"{name} {value!r} is not a number") from None
        if not (number > 0.0 and math.isfinite(number)):
            raise bad(f"{name} must be positive, got {value}")
        if number > 1.0:
            raise bad(f"{name} is in metres: {value} m is more than a metre (for "
                      f"{value} mm write {number / 1000:g})")
        return number

    square = length("SQUARE_M", parts[2])
    if pattern == "chessboard":
        return BoardSpec("chessboard", columns, rows, square)
    marker = length("MARKER_M", parts[3])
    if marker >= square:
        raise bad(f"MARKER_M ({marker:g}) must be smaller than SQUARE_M ({square:g})")
    name = parts[4].upper()
    name = name if name.startswith("DICT_") else f"DICT_{name}"
    if not hasattr(cv2.aruco, name):
        raise bad(f"no ArUco dictionary {parts[4]!r} (OpenCV's names: DICT_4X4_50, "
                  "DICT_5X5_100, DICT_6X6_250, DICT_ARUCO_ORIGINAL, DICT_APRILTAG_36h11, ...)")
    size = aruco_dictionary(name).bytesList.shape[0]
    needed = columns * rows // 2
    if size < needed:
        raise bad(f"{name} has {size} markers; a {columns}x{rows} ChArUco board needs "
                  f"{needed}")
    return BoardSpec("charuco", columns, rows, square, marker, name)
