"""Camera calibration from views of a printed board: what ``autopilot calibrate`` runs.

A camera's intrinsics (focal lengths, principal point) and lens distortion (OpenCV's
``k1 k2 p1 p2 k3``) are estimated from views of a flat chessboard or ChArUco board. The data
flow, all plain synchronous code:

1. a :class:`FrameSource` reads frames: an image folder, a video file, or a live stream
   (``udp://HOST:PORT``: RTP H.264 as PX4 cameras and ``autopilot sim`` send it; any other URL
   or ``/dev/videoN`` through OpenCV), live ones up to a number of frames or a duration;
2. a :class:`BoardDetector` finds the board's inner corners in each frame
   (:class:`BoardView`: pixels, corner ids, and how sharp the board's edges are);
3. :func:`select_views` drops blurry views and near-duplicates and, of the rest, keeps the
   most diverse ones (position in the image, size, tilt);
4. :func:`calibrate` fits the camera (``cv2.calibrateCamera``), drops views that do not fit
   the others (outliers) and fits again, and reports the reprojection error overall and per
   view and how well the views covered the image (:class:`CalibrationResult`).

:func:`calibrate_frames` chains 2-4; :func:`write_result` writes the OpenCV calibration YAML
and ROS's camera_info YAML (:mod:`drivers.calibration`). ``autopilot bench calibration`` runs
the same code on frames the simulator renders, against the true camera.

Board geometry follows OpenCV's ``CharucoBoard``: ``columns × rows`` *squares*; the inner
corners (``columns − 1`` × ``rows − 1``) have ids row by row from the top left, at
``((col + 1)·square, (row + 1)·square, 0)`` in the board frame (x right, y down, z into the
board). A chessboard uses the same ids, in the order OpenCV's detector reports its corners.
"""

from __future__ import annotations

import contextlib
import math
import os
import queue
import re
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import cv2
import numpy as np

from autopilot.config import InputError
from drivers.base import CameraIntrinsics
from drivers.camera_model import distortion_problem

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


def _no_log(message: str) -> None:
    pass


class CalibrationFailed(InputError):
    """The frames do not allow a calibration (no board in any, too few usable views); the
    message says what was found and what is needed."""


# --------------------------------------------------------------------------------------------
# The board
# --------------------------------------------------------------------------------------------


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
    size = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)).bytesList.shape[0]
    needed = columns * rows // 2
    if size < needed:
        raise bad(f"{name} has {size} markers; a {columns}x{rows} ChArUco board needs "
                  f"{needed}")
    return BoardSpec("charuco", columns, rows, square, marker, name)


# --------------------------------------------------------------------------------------------
# Detection
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class BoardView:
    """The board found in one frame."""

    name: str  # the image file's name, or "frame N" of a video
    image_points_px: np.ndarray  # (N, 2) float64, OpenCV's pixel convention
    corner_ids: np.ndarray  # (N,) int: which inner corners (BoardSpec ids)
    #: How sharp the board's square edges are: the width of the black-to-white step, in
    #: pixels (contrast over steepest gradient; about 1 for a focused, still image, 2.5σ for a
    #: Gaussian blur of σ px), the worse of the two grid directions (motion blurs one).
    edge_width_px: float


def _gray(image: np.ndarray) -> np.ndarray:
    if image.ndim == 2:
        return image
    if image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY)
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


class BoardDetector:
    """Finds a board's inner corners: ChArUco with ``cv2.aruco.CharucoDetector`` (any part of
    the board with at least ``min_corners`` corners, not all in one line); a chessboard with
    ``cv2.findChessboardCorners`` and ``cv2.cornerSubPix`` (window sized to the squares), or
    ``cv2.findChessboardCornersSB`` where that fails (the whole board, every corner)."""

    def __init__(self, board: BoardSpec, min_corners: int = 6) -> None:
        self.board = board
        self.min_corners = max(4, min_corners)
        self._charuco = None
        if board.pattern == "charuco":
            dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary))
            self._cv_board = cv2.aruco.CharucoBoard((board.columns, board.rows), board.square_m,
                                                    board.marker_m, dictionary)
            params = cv2.aruco.CharucoParameters()
            params.tryRefineMarkers = True
            self._charuco = cv2.aruco.CharucoDetector(self._cv_board, params)

    def detect(self, image: np.ndarray, name: str = "") -> BoardView | None:
        gray = _gray(image)
        if self._charuco is not None:
            found = self._detect_charuco(gray)
        else:
            found = self._detect_chessboard(gray)
        if found is None:
            return None
        points, ids = found
        keep = consistent_corners(points, ids, self.board.inner_corners[0])
        if keep.sum() < max(self.min_corners, 0.6 * len(ids)):
            return None  # much of it misread: not worth keeping
        points, ids = points[keep], ids[keep]
        width = edge_width_px(gray, points, ids, self.board)
        return BoardView(name, points, ids, width)

    def _detect_charuco(self, gray: np.ndarray):
        corners, ids, _, _ = self._charuco.detectBoard(gray)
        if ids is None or len(ids) < self.min_corners:
            return None
        ids = ids.reshape(-1).astype(int)
        if self._cv_board.checkCharucoCornersCollinear(ids.reshape(-1, 1)):
            return None
        order = np.argsort(ids)
        return corners.reshape(-1, 2)[order].astype(np.float64), ids[order]

    def _detect_chessboard(self, gray: np.ndarray):
        size = self.board.inner_corners
        flags = (cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
                 | cv2.CALIB_CB_FAST_CHECK)
        ok, corners = cv2.findChessboardCorners(gray, size, flags=flags)
        if ok:
            points = corners.reshape(-1, 2)
            half = int(np.clip(0.4 * _min_spacing_px(points, size[0]), 2, 10))
            corners = cv2.cornerSubPix(
                gray, corners, (half, half), (-1, -1),
                (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 60, 1e-3))
        elif cv2.checkChessboard(gray, size):  # a board is there: the slower, sturdier detector
            ok, corners = cv2.findChessboardCornersSB(
                gray, size, flags=cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE
                | cv2.CALIB_CB_ACCURACY)
        if not ok or corners is None or len(corners) != self.board.corner_count:
            return None
        return corners.reshape(-1, 2).astype(np.float64), np.arange(self.board.corner_count)


def consistent_corners(points_px: np.ndarray, ids: np.ndarray, columns: int,
                       tolerance_squares: float = 0.1) -> np.ndarray:
    """Which corners sit where their grid neighbours say they should (a mask): each corner
    against the homography of the corners up to two squares around it; the worst one further
    than ``tolerance_squares`` (of the local square size) is dropped, and so on. A detector
    occasionally places a corner of small, foreshortened squares a good part of a square
    off, and sub-pixel refinement cannot bring it back; the neighbourhood is small enough for
    lens distortion not to matter."""
    keep = np.ones(len(ids), bool)
    for _ in range(max(1, len(ids) // 3)):
        off = _local_residuals_squares(points_px, ids, columns, keep)
        worst = int(np.argmax(off))
        if off[worst] <= tolerance_squares:
            break
        keep[worst] = False
    return keep


_NEIGHBOURS = np.array([(dx, dy) for dy in range(-2, 3) for dx in range(-2, 3)
                        if (dx, dy) != (0, 0)], dtype=np.float64)


def _local_residuals_squares(points_px: np.ndarray, ids: np.ndarray, columns: int,
                             keep: np.ndarray) -> np.ndarray:
    """For each kept corner: how far (in local square sizes) it is from where the homography
    through its kept neighbours (up to 24, at least 6 needed; else 0) puts it."""
    n = len(ids)
    gx, gy = ids % columns, ids // columns
    where = np.full((int(gy.max()) + 5, columns + 4), -1)
    where[gy + 2, gx + 2] = np.where(keep, np.arange(n), -1)
    j = where[gy[:, None] + 2 + _NEIGHBOURS[None, :, 1].astype(int),
              gx[:, None] + 2 + _NEIGHBOURS[None, :, 0].astype(int)]  # (n, 24)
    valid = j >= 0
    d = np.where(valid[..., None], points_px[np.maximum(j, 0)] - points_px[:, None, :], 0.0)
    ratio = np.linalg.norm(d, axis=2) / np.linalg.norm(_NEIGHBOURS, axis=1)[None, :]
    ratio = np.where(valid, ratio, np.nan)
    enough = keep & (valid.sum(axis=1) >= 6)
    out = np.zeros(n)
    if not enough.any():
        return out
    with np.errstate(all="ignore"):
        step = np.nanmedian(ratio[enough], axis=1)
    d = d[enough] / np.maximum(step, 1e-9)[:, None, None]  # in squares, from the corner
    m = valid[enough][..., None].astype(np.float64)
    x, y = _NEIGHBOURS[None, :, 0], _NEIGHBOURS[None, :, 1]
    u, v = d[..., 0], d[..., 1]
    one, zero = np.ones_like(u), np.zeros_like(u)
    rows_u = np.stack([x * one, y * one, one, zero, zero, zero, -u * x, -u * y, -u], axis=2)
    rows_v = np.stack([zero, zero, zero, x * one, y * one, one, -v * x, -v * y, -v], axis=2)
    a = np.concatenate([rows_u * m, rows_v * m], axis=1)  # (k, 48, 9), absent rows zero
    h = np.linalg.svd(a)[2][:, -1, :]  # the homography, neighbour offsets → corner offsets
    with np.errstate(all="ignore"):
        predicted = h[:, [2, 5]] / h[:, [8]]  # where it maps the corner's own (0, 0)
    residual = np.linalg.norm(predicted, axis=1)
    out[enough] = np.where(np.isfinite(residual), residual, 0.0)
    return out


def _min_spacing_px(points: np.ndarray, columns: int) -> float:
    grid = points.reshape(-1, columns, 2)
    along = np.linalg.norm(np.diff(grid, axis=1), axis=2)
    across = np.linalg.norm(np.diff(grid, axis=0), axis=2)
    return float(min(along.min(initial=np.inf), across.min(initial=np.inf)))


def edge_width_px(gray: np.ndarray, points_px: np.ndarray, ids: np.ndarray,
                  board: BoardSpec) -> float:
    """How blurred the board's square edges are (see :attr:`BoardView.edge_width_px`).

    The edge between two neighbouring inner corners separates a black square from a white one;
    intensity is sampled across it at its middle (three parallel profiles, averaged), from
    deep in the black square to the white square's clear band (a ChArUco marker starts
    ``(square − marker) / 2`` into it). The step's width is its contrast over its steepest
    gradient. The median over edges is taken per grid direction; the worse direction is
    returned (motion blurs the edges across the motion only). NaN without two neighbours."""
    cols = board.columns - 1
    index = {int(i): k for k, i in enumerate(ids)}
    clear = 0.45 if board.pattern == "chessboard" else \
        max(0.05, 0.9 * (board.square_m - board.marker_m) / (2.0 * board.square_m))
    image = gray.astype(np.float32)
    widths = []
    for step in (1, cols):  # neighbours along a row, then along a column
        a, b = [], []
        for i, k in index.items():
            j = i + step
            if (step == 1 and i % cols == cols - 1) or j not in index:
                continue
            a.append(points_px[k])
            b.append(points_px[index[j]])
        if a:
            widths.append(_edge_widths(image, np.array(a), np.array(b), clear))
    medians = [float(np.median(w)) for w in widths if len(w)]
    return max(medians) if medians else math.nan


def _edge_widths(image: np.ndarray, a: np.ndarray, b: np.ndarray, clear: float) -> np.ndarray:
    step_px = 0.25
    mid = (a + b) / 2.0
    along = b - a
    length = np.linalg.norm(along, axis=1)
    keep = length > 4.0
    if not keep.any():
        return np.empty(0)
    mid, along, length = mid[keep], along[keep] / length[keep, None], length[keep]
    normal = np.column_stack([-along[:, 1], along[:, 0]])
    reach = 0.45 * length.max()
    s = np.arange(-reach, reach + step_px / 2, step_px)  # across the edge (px)
    shifts = np.array([-0.15, 0.0, 0.15])  # parallel profiles, in edge lengths
    # (edges, shifts, samples, 2)
    pts = (mid[:, None, None, :] + (shifts[None, :, None, None] * length[:, None, None, None])
           * along[:, None, None, :] + s[None, None, :, None] * normal[:, None, None, :])
    maps = pts.reshape(-1, len(s), 2).astype(np.float32)
    values = cv2.remap(image, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_REPLICATE)
    profile = values.reshape(len(mid), len(shifts), len(s)).mean(axis=1)
    out = []
    for k in range(len(mid)):
        inside = np.abs(s) <= 0.45 * length[k]
        p, sk = profile[k][inside], s[inside]
        if len(p) < 8:
            continue
        # which side is black: the darker half
        if p[sk < 0].mean() > p[sk > 0].mean():
            p, sk = p[::-1], -sk[::-1]
        white_end = clear * length[k]
        use = sk <= white_end
        p, sk = p[use], sk[use]
        black = float(np.percentile(p[sk < 0], 10))
        white = float(p[sk >= 0].max(initial=black))
        gradient = np.abs(np.gradient(p, step_px))
        steepest = float(gradient[np.abs(sk) <= max(2.0, 0.25 * length[k])].max(initial=0.0))
        if white - black > 10.0 and steepest > 0.0:
            out.append((white - black) / steepest)
    return np.array(out)


# --------------------------------------------------------------------------------------------
# Frame sources
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, eq=False)
class SourceFrame:
    name: str
    image: np.ndarray  # BGR or grey, uint8


class FrameSource:
    """Frames from an image folder (its images in name order), a video file, or a live
    stream: ``udp://`` / ``rtp://`` is RTP H.264 (:class:`drivers.video.VideoSource`, as PX4
    cameras and ``autopilot sim`` send it), anything else (``rtsp://``, ``http://``,
    ``/dev/video0``, a device number) goes to ``cv2.VideoCapture``.

    ``max_frames`` and ``duration_s`` bound what is read (a live source defaults to
    :data:`LIVE_DEFAULT_FRAMES` and :data:`LIVE_DEFAULT_DURATION_S`); ``every`` keeps every
    n-th frame. Ctrl-C while a live source is read ends the reading and
    :func:`calibrate_frames` uses the frames so far. :class:`InputError` for a source that
    does not exist or does not open."""

    def __init__(self, source: str, *, max_frames: int | None = None,
                 duration_s: float | None = None, every: int = 1,
                 open_timeout_s: float = 10.0, log: Log = _no_log) -> None:
        if every < 1:
            raise InputError(f"--every {every}: must be at least 1")
        if max_frames is not None and max_frames < 1:
            raise InputError(f"--frames {max_frames}: must be at least 1")
        if duration_s is not None and not duration_s > 0.0:
            raise InputError(f"--duration-s {duration_s}: must be positive")
        self.source = source
        self.kind: SourceKind = _source_kind(source)
        live = self.kind == "live"
        self.max_frames = max_frames if max_frames is not None or not live \
            else LIVE_DEFAULT_FRAMES
        self.duration_s = duration_s if duration_s is not None or not live \
            else LIVE_DEFAULT_DURATION_S
        self.every = every
        self.open_timeout_s = open_timeout_s
        self.log = log
        #: Files of a folder that could not be read as images.
        self.skipped: list[str] = []
        self._files: list[Path] = []
        if self.kind == "folder":
            folder = Path(source)
            self._files = sorted(p for p in folder.iterdir()
                                 if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
            if not self._files:
                raise InputError(f"{source}: no images in this folder (expected "
                                 f"{', '.join(IMAGE_SUFFIXES)} files)")

    @property
    def live(self) -> bool:
        """A live stream: Ctrl-C ends the reading, and the frames so far are used."""
        return self.kind == "live"

    def describe(self) -> str:
        if self.kind == "folder":
            return f"{self.source} (folder, {len(self._files)} images)"
        limits = [f"{self.max_frames} frames" if self.max_frames else None,
                  f"{self.duration_s:g} s" if self.duration_s else None]
        bound = " or ".join(x for x in limits if x)
        return f"{self.source} ({self.kind}{', up to ' + bound if bound else ''})"

    def __iter__(self) -> Iterator[SourceFrame]:
        if self.kind == "folder":
            yield from self._folder()
        elif self.kind == "live" and _is_rtp(self.source):
            yield from self._limited(self._rtp())
        else:
            yield from self._limited(self._capture())

    def _folder(self) -> Iterator[SourceFrame]:
        files = self._files[::self.every][:self.max_frames]
        read = 0
        for path in files:
            image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if image is None or image.dtype != np.uint8:
                self.skipped.append(path.name)
                self.log(f"{path}: not an 8-bit image OpenCV reads; skipped")
                continue
            read += 1
            yield SourceFrame(path.name, image)
        if read == 0:
            raise InputError(f"{self.source}: none of its {len(files)} image files could be "
                             "read (8-bit PNG, JPEG, ... expected)")

    def _limited(self, frames: Iterator[np.ndarray]) -> Iterator[SourceFrame]:
        started = time.monotonic()
        kept = 0
        try:
            for n, image in enumerate(frames):
                if self.duration_s is not None and time.monotonic() - started > self.duration_s:
                    break
                if n % self.every:
                    continue
                yield SourceFrame(f"frame {n}", image)
                kept += 1
                if self.max_frames is not None and kept >= self.max_frames:
                    break
        finally:
            close = getattr(frames, "close", None)
            if close is not None:
                close()

    def _capture(self) -> Iterator[np.ndarray]:
        target = int(self.source) if self.source.isdigit() else self.source
        capture = cv2.VideoCapture(target)
        try:
            if not capture.isOpened():
                raise InputError(f"{self.source}: OpenCV cannot open this as a video "
                                 f"{'stream' if self.kind == 'live' else 'file'}")
            got = False
            while True:
                ok, image = capture.read()
                if not ok:
                    break
                got = True
                yield image
            if not got:
                raise InputError(f"{self.source}: opened, but no frame could be read")
        finally:
            capture.release()

    def _rtp(self) -> Iterator[np.ndarray]:
        """RTP H.264 received and decoded by the project's video receiver (on an event loop
        of its own, on a thread); the newest frame is handed over, older ones dropped while
        the caller is busy detecting."""
        import asyncio

        from drivers.base import CameraInfo
        from drivers.camera_model import pinhole
        from drivers.video import VideoSource, check_video_url

        try:
            check_video_url(self.source)
        except ValueError as exc:
            raise InputError(str(exc)) from None
        # the receiver wants a camera to stamp frames for: the intrinsics are what we are
        # about to measure, so any will do
        info = CameraInfo("calibrate", pinhole(640, 480, 90.0), np.eye(3), np.zeros(3), 30.0)
        newest: queue.Queue[np.ndarray] = queue.Queue(maxsize=1)
        stop = threading.Event()
        failure: list[BaseException] = []

        async def pump() -> None:
            video = VideoSource(self.source, info)
            try:
                async with contextlib.aclosing(video.frames()) as frames:
                    pending = asyncio.ensure_future(anext(frames))
                    while not stop.is_set():
                        done, _ = await asyncio.wait({pending}, timeout=0.2)
                        if not done:
                            continue
                        image = pending.result()
                        pending = asyncio.ensure_future(anext(frames))
                        with contextlib.suppress(queue.Empty):
                            newest.get_nowait()
                        newest.put_nowait(image.image)
                    pending.cancel()
            finally:
                await video.close()

        def run() -> None:
            try:
                asyncio.run(pump())
            except BaseException as exc:  # handed to the reading thread
                failure.append(exc)

        thread = threading.Thread(target=run, name="calibrate-video", daemon=True)
        thread.start()
        try:
            got = 0
            while True:
                try:
                    image = newest.get(timeout=self.open_timeout_s if got == 0 else 5.0)
                except queue.Empty:
                    if failure:
                        raise InputError(f"{self.source}: {failure[0]}") from None
                    if got == 0:
                        raise InputError(
                            f"{self.source}: no frame within {self.open_timeout_s:g} s: is "
                            "the camera streaming RTP H.264 to this address and port?") from None
                    self.log(f"{self.source}: no frame for 5 s; the stream stopped")
                    return
                got += 1
                yield image
        finally:
            stop.set()
            thread.join(5.0)


def _is_rtp(source: str) -> bool:
    return source.split("://", 1)[0].lower() in ("udp", "rtp") and "://" in source


def _source_kind(source: str) -> SourceKind:
    path = Path(source)
    if "://" in source or source.isdigit() or source.startswith("/dev/"):
        return "live"
    if path.is_dir():
        return "folder"
    if path.is_file():
        return "video"
    raise InputError(f"{source}: no such file or folder (SOURCE is an image folder, a video "
                     "file, or a live video URL such as udp://127.0.0.1:5600)")


# --------------------------------------------------------------------------------------------
# View selection
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class CalibrationOptions:
    """How views are chosen and the camera is fitted."""

    #: At most this many views go into the fit (the most diverse of the usable ones).
    max_views: int = 40
    #: Fewer usable views than this: no calibration (:class:`CalibrationFailed`).
    min_views: int = 10
    #: Views whose edges are wider than this times the median view's are not used (see
    #: :attr:`BoardView.edge_width_px`; the limit is never below ``sharp_edge_width_px``:
    #: that sharp is sharp enough). Relative, as lenses, sensors and compression differ.
    blur_factor: float = 1.5
    sharp_edge_width_px: float = 1.8
    #: A view whose corners are, on average, within this share of the image diagonal of an
    #: already chosen view's (the same corners) adds nothing: a near-duplicate.
    duplicate_fraction: float = 0.02
    #: After a fit, views whose RMS error exceeds this times the median view's (and
    #: ``outlier_floor_px``) are dropped and the camera is fitted again (up to 3 times).
    outlier_factor: float = 3.0
    outlier_floor_px: float = 0.3
    #: Distortion model: OpenCV's k1 k2 p1 p2 k3 by default; without k3 (narrow lenses, few
    #: views); or the rational model (8 coefficients: wide-angle lenses).
    fix_k3: bool = False
    rational: bool = False


@dataclass(frozen=True, slots=True)
class Rejection:
    name: str
    reason: Literal["blurry", "duplicate", "not_needed", "outlier"]
    detail: str


@dataclass(frozen=True, slots=True, eq=False)
class Selection:
    views: tuple[BoardView, ...]
    rejected: tuple[Rejection, ...]


@dataclass(frozen=True, slots=True)
class _Pose:
    centre_px: tuple[float, float]  # of the corners seen
    scale: float  # the whole board's width over the image's (about; the rough camera)
    tilt_deg: float  # between the board's normal and the optical axis
    tilt_xy_deg: tuple[float, float]  # about the camera's x (top towards / away) and y axes


def _rough_camera(views: Sequence[BoardView], board: BoardSpec,
                  image_size: tuple[int, int]) -> np.ndarray:
    """A camera matrix from the views' homographies (principal point at the centre), good
    enough to tell views' tilts apart; a 60° lens if they do not determine it."""
    w, h = image_size
    fallback = np.array([[w * 0.866, 0.0, (w - 1) / 2.0], [0.0, w * 0.866, (h - 1) / 2.0],
                         [0.0, 0.0, 1.0]])
    obj = board.object_points_m()
    usable = [v for v in views if len(v.corner_ids) >= 6][:200]
    if len(usable) < 2:
        return fallback
    try:
        k = cv2.initCameraMatrix2D([obj[v.corner_ids] for v in usable],
                                   [v.image_points_px.astype(np.float32) for v in usable],
                                   (w, h))
    except cv2.error:
        return fallback
    f = 0.5 * (k[0, 0] + k[1, 1])
    if not (math.isfinite(f) and 0.2 * w < f < 20.0 * w):
        return fallback
    return np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])


def _pose(view: BoardView, board: BoardSpec, k: np.ndarray, dist: np.ndarray | None,
          image_size: tuple[int, int], rvec: np.ndarray | None = None,
          tvec: np.ndarray | None = None) -> _Pose:
    """Where a view has the board: its pose as given (a fit's), or else solved for with
    camera matrix ``k`` and distortion ``dist``."""
    obj = board.object_points_m()[view.corner_ids]
    if rvec is None:
        ok, rvec, tvec = cv2.solvePnP(obj, view.image_points_px, k, dist,
                                      flags=cv2.SOLVEPNP_IPPE)
        if not ok:
            rvec, tvec = np.zeros(3), np.array([0.0, 0.0, 1.0])
    r, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float))
    normal = r[:, 2] * (1.0 if r[2, 2] >= 0 else -1.0)
    tilt = math.degrees(math.acos(min(1.0, abs(float(normal[2])))))
    tilt_xy = (math.degrees(math.atan2(normal[1], normal[2])),
               math.degrees(math.atan2(normal[0], normal[2])))
    outline, _ = cv2.projectPoints(board.outline_m(), rvec, tvec, k, None)
    outline = outline.reshape(-1, 2)
    width = 0.5 * (np.linalg.norm(outline[1] - outline[0])
                   + np.linalg.norm(outline[2] - outline[3]))
    centre = view.image_points_px.mean(axis=0)
    return _Pose((float(centre[0]), float(centre[1])), float(width / image_size[0]), tilt,
                 (float(tilt_xy[0]), float(tilt_xy[1])))


def select_views(views: Sequence[BoardView], board: BoardSpec, image_size: tuple[int, int],
                 options: CalibrationOptions = CalibrationOptions()) -> Selection:
    """The views to calibrate with: sharp ones (see :class:`CalibrationOptions`), no two
    nearly the same (the sharper, fuller one kept), and of those, if more than
    ``max_views``, up to half of them for coverage (one by one, the view reaching most of the
    image not yet reached), the rest for diversity (one by one, the view farthest from those
    already chosen in position in the image, board size and tilt)."""
    rejected: list[Rejection] = []
    finite = [v.edge_width_px for v in views if math.isfinite(v.edge_width_px)]
    median = float(np.median(finite)) if finite else math.nan
    limit = max(options.sharp_edge_width_px, options.blur_factor * median) \
        if math.isfinite(median) else math.inf
    sharp = []
    for v in views:
        if math.isfinite(v.edge_width_px) and v.edge_width_px > limit:
            rejected.append(Rejection(v.name, "blurry", f"edges {v.edge_width_px:.1f} px wide "
                                      f"(limit {limit:.1f} px)"))
        else:
            sharp.append(v)

    # near-duplicates: best first (most corners, then sharpest)
    diagonal = math.hypot(*image_size)
    order = sorted(sharp, key=lambda v: (-len(v.corner_ids),
                                         v.edge_width_px if math.isfinite(v.edge_width_px)
                                         else math.inf))
    distinct: list[BoardView] = []
    lookup: list[dict[int, int]] = []
    for v in order:
        ids = {int(i): k for k, i in enumerate(v.corner_ids)}
        duplicate = None
        for other, other_ids in zip(distinct, lookup, strict=True):
            common = [i for i in ids if i in other_ids]
            if len(common) < max(4, 0.5 * min(len(ids), len(other_ids))):
                continue
            a = v.image_points_px[[ids[i] for i in common]]
            b = other.image_points_px[[other_ids[i] for i in common]]
            if float(np.linalg.norm(a - b, axis=1).mean()) < options.duplicate_fraction * diagonal:
                duplicate = other
                break
        if duplicate is not None:
            rejected.append(Rejection(v.name, "duplicate", f"nearly the same as "
                                      f"{duplicate.name}"))
        else:
            distinct.append(v)
            lookup.append(ids)

    if len(distinct) <= options.max_views:
        return Selection(tuple(distinct), tuple(rejected))
    # first, coverage: one by one, the view whose corners fall in most cells of a fine grid
    # that no chosen view reaches yet (the image's edges and corners are where the lens model
    # is otherwise extrapolated), for up to half the views
    w, h = image_size
    gx, gy = 16, 12
    cells = np.zeros((len(distinct), gx * gy), bool)
    for i, v in enumerate(distinct):
        p = v.image_points_px
        ix = np.clip((p[:, 0] + 0.5) * gx / w, 0, gx - 1).astype(int)
        iy = np.clip((p[:, 1] + 0.5) * gy / h, 0, gy - 1).astype(int)
        cells[i, iy * gx + ix] = True
    chosen: list[int] = []
    covered = np.zeros(gx * gy, bool)
    while len(chosen) < options.max_views // 2:
        gain = (cells & ~covered).sum(axis=1)
        best = int(np.argmax(gain))  # ties: the earlier, fuller view
        if gain[best] == 0:
            break
        chosen.append(best)
        covered |= cells[best]
    # then diversity of pose: each next view the farthest from those chosen in position in
    # the image, board size and tilt (farthest-point sampling)
    k = _rough_camera(distinct, board, image_size)
    poses = [_pose(v, board, k, None, image_size) for v in distinct]
    features = np.array([[p.centre_px[0] / w, p.centre_px[1] / h, p.scale,
                          p.tilt_xy_deg[0] / 60.0, p.tilt_xy_deg[1] / 60.0] for p in poses])
    chosen = chosen or [0]  # (no coverage pick: the fullest view; the list is sorted so)
    nearest = np.min(np.linalg.norm(features[:, None, :] - features[None, chosen, :], axis=2),
                     axis=1)
    while len(chosen) < options.max_views:
        nxt = int(np.argmax(nearest))
        chosen.append(nxt)
        nearest = np.minimum(nearest, np.linalg.norm(features - features[nxt], axis=1))
    keep = set(chosen)
    for i, v in enumerate(distinct):
        if i not in keep:
            rejected.append(Rejection(v.name, "not_needed", f"{options.max_views} more "
                                      "diverse views were enough"))
    return Selection(tuple(distinct[i] for i in sorted(keep)), tuple(rejected))


# --------------------------------------------------------------------------------------------
# Calibration
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ViewError:
    name: str
    rms_px: float
    corners: int
    tilt_deg: float
    board_width_fraction: float  # the whole board's width over the image's


@dataclass(frozen=True, slots=True)
class Coverage:
    """How much of the image and of the possible poses the views used covered."""

    #: Of the image divided into ``grid`` cells: the share with a corner in any view.
    cells_fraction: float
    #: Of the cells on the image's border (where the lens distorts most): the share covered.
    border_cells_fraction: float
    #: Of the image's area: the share inside some view's detected corners' outline.
    area_fraction: float
    grid: tuple[int, int]
    tilt_deg_min: float
    tilt_deg_max: float
    #: The range of tilt about the camera's x axis (board top towards or away) and y axis.
    tilt_x_deg_range: tuple[float, float]
    tilt_y_deg_range: tuple[float, float]
    board_width_fraction_range: tuple[float, float]


@dataclass(frozen=True, slots=True, eq=False)
class CalibrationResult:
    board: BoardSpec
    intrinsics: CameraIntrinsics
    #: Over every corner of every view used: sqrt(mean squared reprojection error), px.
    reprojection_rms_px: float
    #: The views used, with their own RMS error.
    views: tuple[ViewError, ...]
    #: Views found but not used, and why.
    rejected: tuple[Rejection, ...]
    coverage: Coverage
    #: One standard deviation of fx, fy, cx, cy (px) as the fit estimates it.
    std_px: tuple[float, float, float, float]
    frames_read: int
    frames_with_board: int
    warnings: tuple[str, ...] = ()
    #: Files of a folder that could not be read.
    skipped: tuple[str, ...] = field(default=())

    def rejected_counts(self) -> dict[str, int]:
        counts = {"blurry": 0, "duplicate": 0, "not_needed": 0, "outlier": 0}
        for r in self.rejected:
            counts[r.reason] += 1
        return counts

    def as_dict(self) -> dict:
        intr = self.intrinsics
        c = self.coverage
        return {
            "board": self.board.text,
            "image_width_px": intr.width_px, "image_height_px": intr.height_px,
            "fx_px": intr.fx, "fy_px": intr.fy, "cx_px": intr.cx, "cy_px": intr.cy,
            "distortion": list(intr.distortion),
            "std_px": dict(zip(("fx", "fy", "cx", "cy"), self.std_px, strict=True)),
            "reprojection_rms_px": self.reprojection_rms_px,
            "frames_read": self.frames_read,
            "frames_with_board": self.frames_with_board,
            "views_used": len(self.views),
            "rejected": self.rejected_counts(),
            "coverage": {
                "cells_fraction": c.cells_fraction, "grid": list(c.grid),
                "border_cells_fraction": c.border_cells_fraction,
                "area_fraction": c.area_fraction,
                "tilt_deg_min": c.tilt_deg_min, "tilt_deg_max": c.tilt_deg_max,
                "tilt_x_deg_range": list(c.tilt_x_deg_range),
                "tilt_y_deg_range": list(c.tilt_y_deg_range),
                "board_width_fraction_range": list(c.board_width_fraction_range)},
            "views": [{"name": v.name, "rms_px": v.rms_px, "corners": v.corners,
                       "tilt_deg": v.tilt_deg,
                       "board_width_fraction": v.board_width_fraction} for v in self.views],
            "rejected_views": [{"name": r.name, "reason": r.reason, "detail": r.detail}
                               for r in self.rejected],
            "skipped_files": list(self.skipped),
            "warnings": list(self.warnings),
        }


@dataclass(frozen=True, slots=True, eq=False)
class _Fit:
    rms_px: float
    k: np.ndarray
    dist: np.ndarray
    rvecs: tuple
    tvecs: tuple
    per_view_px: np.ndarray
    std: np.ndarray


def _fit(views: Sequence[BoardView], board: BoardSpec, image_size: tuple[int, int],
         options: CalibrationOptions) -> _Fit:
    obj = board.object_points_m()
    object_points = [obj[v.corner_ids].reshape(-1, 1, 3) for v in views]
    image_points = [v.image_points_px.astype(np.float32).reshape(-1, 1, 2) for v in views]
    flags = (cv2.CALIB_FIX_K3 if options.fix_k3 else 0) | \
        (cv2.CALIB_RATIONAL_MODEL if options.rational else 0)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    try:
        rms, k, dist, rvecs, tvecs, std, _, per_view = cv2.calibrateCameraExtended(
            object_points, image_points, image_size, None, None, flags=flags,
            criteria=criteria)
    except cv2.error as exc:
        raise CalibrationFailed(f"OpenCV cannot fit a camera to these {len(views)} views "
                                f"({(exc.err or str(exc)).strip()}): show the board at more "
                                "distances and tilts") from None
    return _Fit(float(rms), k, dist.ravel(), tuple(rvecs), tuple(tvecs),
                np.asarray(per_view, dtype=float).ravel(), np.asarray(std, dtype=float).ravel())


def calibrate(views: Sequence[BoardView], board: BoardSpec, image_size: tuple[int, int],
              options: CalibrationOptions = CalibrationOptions(), *,
              rejected: Sequence[Rejection] = (), frames_read: int | None = None,
              frames_with_board: int | None = None,
              skipped: Sequence[str] = ()) -> CalibrationResult:
    """Fit the camera to ``views`` (already selected: see :func:`select_views`), drop the
    views that fit much worse than the others and fit again (see
    :class:`CalibrationOptions`). :class:`CalibrationFailed` with fewer than
    ``options.min_views`` views."""
    if len(views) < options.min_views:
        raise CalibrationFailed(f"{len(views)} usable views of the board; need at least "
                                f"{options.min_views}")
    used = list(views)
    dropped: list[Rejection] = []
    fit = _fit(used, board, image_size, options)
    for _ in range(3):
        median = float(np.median(fit.per_view_px))
        limit = max(options.outlier_factor * median, options.outlier_floor_px)
        bad = [i for i, e in enumerate(fit.per_view_px) if e > limit]
        if not bad or len(used) - len(bad) < options.min_views:
            break
        dropped += [Rejection(used[i].name, "outlier", f"RMS {fit.per_view_px[i]:.2f} px "
                              f"(limit {limit:.2f} px)") for i in bad]
        used = [v for i, v in enumerate(used) if i not in set(bad)]
        fit = _fit(used, board, image_size, options)

    w, h = image_size
    dist = [float(d) for d in fit.dist]
    if len(dist) > 5 and not options.rational:
        dist = dist[:5]
    intr = CameraIntrinsics(int(w), int(h), float(fit.k[0, 0]), float(fit.k[1, 1]),
                            float(fit.k[0, 2]), float(fit.k[1, 2]), tuple(dist))
    poses = [_pose(v, board, fit.k, fit.dist, image_size, r, t)
             for v, r, t in zip(used, fit.rvecs, fit.tvecs, strict=True)]
    errors = [ViewError(v.name, float(e), len(v.corner_ids), p.tilt_deg, p.scale)
              for v, e, p in zip(used, fit.per_view_px, poses, strict=True)]
    coverage = _coverage(used, poses, image_size)
    std = tuple(float(s) for s in fit.std[:4])
    widths = [v.edge_width_px for v in used if math.isfinite(v.edge_width_px)]
    result_warnings = _warnings(intr, fit.rms_px, coverage, len(used), options,
                                float(np.median(widths)) if widths else math.nan)
    found = len(views) + len(rejected) if frames_with_board is None else frames_with_board
    return CalibrationResult(
        board=board, intrinsics=intr, reprojection_rms_px=fit.rms_px, views=tuple(errors),
        rejected=tuple(rejected) + tuple(dropped), coverage=coverage, std_px=std,
        frames_read=found if frames_read is None else frames_read,
        frames_with_board=found, warnings=result_warnings, skipped=tuple(skipped))


def _coverage(views: Sequence[BoardView], poses: Sequence[_Pose],
              image_size: tuple[int, int]) -> Coverage:
    w, h = image_size
    gx, gy = (8, 6) if w >= h else (6, 8)
    cells = np.zeros((gy, gx), bool)
    scale = 4  # the area mask at a quarter of the resolution
    mask = np.zeros((max(1, h // scale), max(1, w // scale)), np.uint8)
    for v in views:
        p = v.image_points_px
        ix = np.clip((p[:, 0] + 0.5) * gx / w, 0, gx - 1).astype(int)
        iy = np.clip((p[:, 1] + 0.5) * gy / h, 0, gy - 1).astype(int)
        cells[iy, ix] = True
        hull = cv2.convexHull((p / scale).astype(np.float32)).astype(np.int32)
        cv2.fillConvexPoly(mask, hull, 1)
    border = np.ones_like(cells)
    border[1:-1, 1:-1] = False
    tilts = [p.tilt_deg for p in poses]
    tx = [p.tilt_xy_deg[0] for p in poses]
    ty = [p.tilt_xy_deg[1] for p in poses]
    widths = [p.scale for p in poses]
    return Coverage(
        cells_fraction=float(cells.mean()),
        border_cells_fraction=float(cells[border].mean()),
        area_fraction=float(mask.mean()), grid=(gx, gy),
        tilt_deg_min=float(min(tilts)), tilt_deg_max=float(max(tilts)),
        tilt_x_deg_range=(float(min(tx)), float(max(tx))),
        tilt_y_deg_range=(float(min(ty)), float(max(ty))),
        board_width_fraction_range=(float(min(widths)), float(max(widths))))


def _warnings(intr: CameraIntrinsics, rms_px: float, coverage: Coverage, used: int,
              options: CalibrationOptions, edge_width_px: float) -> tuple[str, ...]:
    out = []
    if edge_width_px > 3.0:
        out.append(f"the views are blurred (edges {edge_width_px:.1f} px wide; a focused, "
                   "still camera gives 1-2 px): focus the lens, light the board better "
                   "(shorter exposure), move it slower")
    if rms_px > 1.0:
        out.append(f"reprojection RMS {rms_px:.2f} px is high (below 0.5 px is usual): is the "
                   "board flat, are --board's sizes right, was the camera in focus?")
    if coverage.border_cells_fraction < 0.5:
        out.append(f"the board reached only {coverage.border_cells_fraction:.0%} of the "
                   "image's border cells: the distortion near the edges and corners is "
                   "extrapolated; hold the board there too")
    elif coverage.cells_fraction < 0.6:
        out.append(f"the board covered only {coverage.cells_fraction:.0%} of the image: "
                   "move it all over the image, into the corners")
    if coverage.tilt_deg_max < 25.0:
        out.append(f"no view tilted more than {coverage.tilt_deg_max:.0f}°: tilt the board "
                   "30-50° in different directions; the focal length is poorly determined "
                   "from views facing the camera")
    if used < max(15, options.min_views):
        out.append(f"only {used} views: 20-40 varied ones give a steadier calibration")
    problem = distortion_problem(intr)
    if problem is not None:
        out.append(f"the distortion fitted is not a plausible lens: {problem}")
    return tuple(out)


# --------------------------------------------------------------------------------------------
# The whole run
# --------------------------------------------------------------------------------------------


def calibrate_frames(frames: Iterable[SourceFrame], board: BoardSpec,
                     options: CalibrationOptions = CalibrationOptions(),
                     log: Log = _no_log) -> CalibrationResult:
    """Detect the board in every frame, select the views, calibrate. :class:`InputError`
    for frames of different sizes, :class:`CalibrationFailed` for no board in any frame or
    too few usable views (the message says how many were found and are needed)."""
    detector = BoardDetector(board)
    found: list[BoardView] = []
    size: tuple[int, int] | None = None
    first = ""
    read = 0
    started = time.monotonic()
    last_report = started
    reading = iter(frames)
    try:
        for frame in reading:
            read += 1
            h, w = frame.image.shape[:2]
            if size is None:
                size, first = (w, h), frame.name
            elif (w, h) != size:
                raise InputError(f"{frame.name}: {w}x{h} pixels, but {first} is {size[0]}x"
                                 f"{size[1]}: calibrate one camera at one resolution at a time")
            view = detector.detect(frame.image, frame.name)
            if view is not None:
                found.append(view)
            now = time.monotonic()
            if now - last_report >= 2.0:
                last_report = now
                log(f"{read} frames, board in {len(found)}")
    except KeyboardInterrupt:
        if not getattr(frames, "live", False):
            raise
        log(f"Ctrl-C: stopped reading after {read} frames; calibrating with those")
    finally:
        close = getattr(reading, "close", None)
        if close is not None:
            close()  # a live source's receiver stops here
    skipped = tuple(getattr(frames, "skipped", ()))
    if read == 0 or size is None:
        raise InputError("no frames to calibrate with")
    log(f"{read} frames read in {time.monotonic() - started:.1f} s; board in {len(found)}")
    if not found:
        cols, rows = board.inner_corners
        raise CalibrationFailed(
            f"no {board.pattern} {board.columns}x{board.rows} found in any of the {read} "
            f"frames. COLSxROWS counts squares: this board has {cols}x{rows} inner corners"
            + (" and must be seen whole" if board.pattern == "chessboard" else
               f", {board.dictionary} markers")
            + "; check --board against the printed board, and the focus and lighting")
    selection = select_views(found, board, size, options)
    if len(selection.views) < options.min_views:
        counts = {r: sum(1 for x in selection.rejected if x.reason == r)
                  for r in ("blurry", "duplicate")}
        raise CalibrationFailed(
            f"the board was found in {len(found)} of {read} frames, {len(selection.views)} "
            f"of them usable ({counts['blurry']} blurry, {counts['duplicate']} "
            f"near-duplicates); need at least {options.min_views} views: show the board "
            "still and sharp at more places, distances and tilts"
            + ("" if options.min_views <= 3 else " (or lower --min-views)"))
    return calibrate(selection.views, board, size, options, rejected=selection.rejected,
                     frames_read=read, frames_with_board=len(found), skipped=skipped)


def ros_path_for(out: Path) -> Path:
    """Where the ROS camera_info YAML goes by default: next to ``out``, ``NAME_ros.yaml``."""
    return out.with_name(f"{out.stem}_ros.yaml")


def write_result(result: CalibrationResult, out: Path, ros_out: Path | None = None,
                 camera_name: str = "camera", source: str = "") -> tuple[Path, Path]:
    """The OpenCV calibration YAML at ``out`` (with the fit's figures as metadata) and ROS's
    camera_info YAML at ``ros_out`` (default :func:`ros_path_for`). :class:`InputError` if
    either cannot be written."""
    from datetime import UTC, datetime

    from drivers.calibration import CalibrationError, write_calibration, write_ros_calibration

    ros = ros_out if ros_out is not None else ros_path_for(out)
    if ros.resolve() == out.resolve():
        raise InputError(f"--ros-out {ros}: the same file as --out")
    c = result.coverage
    metadata: dict[str, int | float | str] = {
        "calibration_time": datetime.now(UTC).isoformat(timespec="seconds"),
        "board": result.board.text,
        "reprojection_rms_px": result.reprojection_rms_px,
        "views": len(result.views),
        "frames_with_board": result.frames_with_board,
        "frames_read": result.frames_read,
        "coverage_cells_fraction": c.cells_fraction,
        "coverage_border_cells_fraction": c.border_cells_fraction,
        "tilt_deg_max": c.tilt_deg_max,
    }
    if source:
        metadata["source"] = source
    try:
        write_calibration(out, result.intrinsics, metadata)
        write_ros_calibration(ros, result.intrinsics, camera_name)
    except CalibrationError as exc:
        raise InputError(str(exc)) from None
    return out, ros


def format_summary(result: CalibrationResult) -> str:
    """What ``autopilot calibrate`` prints."""
    intr = result.intrinsics
    c = result.coverage
    counts = result.rejected_counts()
    names = {"blurry": "blurry", "duplicate": "near-duplicates", "outlier": "outliers",
             "not_needed": "not needed"}
    why = ", ".join(f"{n} {names[r]}" for r, n in counts.items() if n)
    errors = [v.rms_px for v in result.views]
    worst = sorted(result.views, key=lambda v: -v.rms_px)[:3]
    d = intr.distortion
    labels = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
    lines = [
        f"board: {result.board.describe()}",
        f"views: {len(result.views)} used of {result.frames_with_board} with the board "
        f"({result.frames_read} frames read)" + (f"; not used: {why}" if why else ""),
        f"coverage: {c.cells_fraction:.0%} of the image's {c.grid[0]}x{c.grid[1]} cells, "
        f"{c.border_cells_fraction:.0%} of its border cells, {c.area_fraction:.0%} of its "
        f"area; tilted {c.tilt_deg_min:.0f}-{c.tilt_deg_max:.0f}° off the optical axis; board "
        f"{c.board_width_fraction_range[0]:.0%}-{c.board_width_fraction_range[1]:.0%} of the "
        "image's width",
        f"reprojection RMS {result.reprojection_rms_px:.3f} px (views {min(errors):.3f}-"
        f"{max(errors):.3f} px; worst: "
        + ", ".join(f"{v.name} {v.rms_px:.3f}" for v in worst) + ")",
        f"image {intr.width_px}x{intr.height_px}: fx {intr.fx:.2f} ± {result.std_px[0]:.2f}, "
        f"fy {intr.fy:.2f} ± {result.std_px[1]:.2f}, cx {intr.cx:.2f} ± {result.std_px[2]:.2f}"
        f", cy {intr.cy:.2f} ± {result.std_px[3]:.2f} px (hfov "
        f"{math.degrees(intr.hfov_rad):.1f}° as a pinhole)",
        "distortion: " + " ".join(f"{labels[i] if i < len(labels) else f'c{i}'} {v:+.5f}"
                                  for i, v in enumerate(d)),
    ]
    if result.skipped:
        lines.append(f"skipped {len(result.skipped)} unreadable files: "
                     + ", ".join(result.skipped[:5]) + (" ..." if len(result.skipped) > 5
                                                       else ""))
    lines += [f"warning: {w}" for w in result.warnings]
    return "\n".join(lines)


def run(source: str, board_spec: str, out: str | os.PathLike, *,
        ros_out: str | os.PathLike | None = None, camera_name: str = "camera",
        max_frames: int | None = None, duration_s: float | None = None, every: int = 1,
        options: CalibrationOptions = CalibrationOptions(),
        log: Log = _no_log) -> tuple[CalibrationResult, Path, Path]:
    """``autopilot calibrate``: parse the board, read the source, calibrate, write both
    files. Returns the result and the two paths written."""
    board = parse_board_spec(board_spec)
    out_path = Path(out)
    if not out_path.parent.is_dir():
        raise InputError(f"--out {out}: no such folder {out_path.parent}")
    ros_path = Path(ros_out) if ros_out is not None else None
    if ros_path is not None and not ros_path.parent.is_dir():
        raise InputError(f"--ros-out {ros_out}: no such folder {ros_path.parent}")
    frames = FrameSource(source, max_frames=max_frames, duration_s=duration_s, every=every,
                         log=log)
    log(f"reading {frames.describe()}; board: {board.describe()}")
    result = calibrate_frames(frames, board, options, log)
    written = write_result(result, out_path, ros_path, camera_name, source)
    return result, *written
