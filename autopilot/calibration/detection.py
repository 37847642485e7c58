"""The board found in a frame: its corners (chessboard or ChArUco), checked for consistency,
with how sharp the frame is."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from autopilot.calibration.board import BoardSpec
from drivers.markers import aruco_dictionary


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


def to_gray(image: np.ndarray) -> np.ndarray:
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
            dictionary = aruco_dictionary(board.dictionary)
            self._cv_board = cv2.aruco.CharucoBoard((board.columns, board.rows), board.square_m,
                                                    board.marker_m, dictionary)
            params = cv2.aruco.CharucoParameters()
            params.tryRefineMarkers = True
            self._charuco = cv2.aruco.CharucoDetector(self._cv_board, params)

    def detect(self, image: np.ndarray, name: str = "") -> BoardView | None:
        gray = to_gray(image)
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
            half = int(np.clip(0.4 * min_spacing_px(points, size[0]), 2, 10))
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
        off = local_residuals_squares(points_px, ids, columns, keep)
        worst = int(np.argmax(off))
        if off[worst] <= tolerance_squares:
            break
        keep[worst] = False
    return keep


NEIGHBOURS = np.array([(dx, dy) for dy in range(-2, 3) for dx in range(-2, 3)
                        if (dx, dy) != (0, 0)], dtype=np.float64)


def local_residuals_squares(points_px: np.ndarray, ids: np.ndarray, columns: int,
                             keep: np.ndarray) -> np.ndarray:
    """For each kept corner: how far (in local square sizes) it is from where the homography
    through its kept neighbours (up to 24, at least 6 needed; else 0) puts it."""
    n = len(ids)
    gx, gy = ids % columns, ids // columns
    where = np.full((int(gy.max()) + 5, columns + 4), -1)
    where[gy + 2, gx + 2] = np.where(keep, np.arange(n), -1)
    j = where[gy[:, None] + 2 + NEIGHBOURS[None, :, 1].astype(int),
              gx[:, None] + 2 + NEIGHBOURS[None, :, 0].astype(int)]  # (n, 24)
    valid = j >= 0
    d = np.where(valid[..., None], points_px[np.maximum(j, 0)] - points_px[:, None, :], 0.0)
    ratio = np.linalg.norm(d, axis=2) / np.linalg.norm(NEIGHBOURS, axis=1)[None, :]
    ratio = np.where(valid, ratio, np.nan)
    enough = keep & (valid.sum(axis=1) >= 6)
    out = np.zeros(n)
    if not enough.any():
        return out
    with np.errstate(all="ignore"):
        step = np.nanmedian(ratio[enough], axis=1)
    d = d[enough] / np.maximum(step, 1e-9)[:, None, None]  # in squares, from the corner
    m = valid[enough][..., None].astype(np.float64)
    x, y = NEIGHBOURS[None, :, 0], NEIGHBOURS[None, :, 1]
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


def min_spacing_px(points: np.ndarray, columns: int) -> float:
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
            widths.append(edge_widths(image, np.array(a), np.array(b), clear))
    medians = [float(np.median(w)) for w in widths if len(w)]
    return max(medians) if medians else math.nan


def edge_widths(image: np.ndarray, a: np.ndarray, b: np.ndarray, clear: float) -> np.ndarray:
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
