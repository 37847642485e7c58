"""What the calibration modules share: the board patterns, the log callback, the failure."""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal

from autopilot.config import InputError

Pattern = Literal["chessboard", "charuco"]
SourceKind = Literal["folder", "video", "live"]

BOARD_SPEC_FORM = ("chessboard:COLSxROWS:SQUARE_M or charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT "
                   "(COLS and ROWS count squares, not inner corners; sizes in metres; e.g. "
                   "chessboard:10x7:0.025 or charuco:11x8:0.03:0.022:DICT_5X5_100)")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")
#: A live source stops after this many frames or seconds, whichever comes first, unless told.
LIVE_DEFAULT_FRAMES = 900
LIVE_DEFAULT_DURATION_S = 60.0

Log = Callable[[str], None]


def no_log(message: str) -> None:
    pass


class CalibrationFailed(InputError):
    """The frames do not allow a calibration (no board in any, too few usable views); the
    message says what was found and what is needed."""
