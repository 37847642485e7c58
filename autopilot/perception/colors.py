"""Named colours: how the simulator paints an object, and the HSV ranges that find it.

OpenCV's HSV: hue 0–180 (half degrees), saturation and value 0–255. Red wraps around hue 0, so
it needs two ranges. The ranges are wide in value (shaded sides of a lit sphere are dark) and
narrow in hue.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

HsvRange = tuple[tuple[int, int, int], tuple[int, int, int]]

#: name → (RGBA used to render it, HSV ranges that detect it)
COLORS: dict[str, tuple[tuple[float, float, float, float], tuple[HsvRange, ...]]] = {
    "orange": ((1.0, 0.42, 0.0, 1.0), (((9, 150, 50), (20, 255, 255)),)),
    "red": ((0.9, 0.05, 0.05, 1.0), (((0, 150, 50), (5, 255, 255)),
                                      ((172, 150, 50), (180, 255, 255)))),
    "yellow": ((0.95, 0.85, 0.05, 1.0), (((24, 150, 60), (34, 255, 255)),)),
    "green": ((0.1, 0.75, 0.15, 1.0), (((50, 150, 40), (70, 255, 255)),)),
    "blue": ((0.1, 0.25, 0.95, 1.0), (((105, 150, 40), (125, 255, 255)),)),
}

#: Colours close to orange but not orange, for distractors (rendered only).
ORANGEISH_RGBA = (
    (1.0, 0.42, 0.0, 1.0),  # the ball's own orange (shape and tracking must reject these)
    (1.0, 0.17, 0.0, 1.0),  # red-orange
    (1.0, 0.75, 0.05, 1.0),  # amber
)


def color_mask(image_bgr: np.ndarray, hsv_ranges: Sequence[HsvRange], opening: np.ndarray,
               closing: np.ndarray) -> np.ndarray:
    """The pixels within any of ``hsv_ranges`` (255), opened then closed by the structuring
    elements ``opening`` and ``closing`` (specks removed, holes filled)."""
    hsv = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2HSV)
    mask = np.zeros(hsv.shape[:2], np.uint8)
    for lo, hi in hsv_ranges:
        mask |= cv2.inRange(hsv, np.array(lo, np.uint8), np.array(hi, np.uint8))
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, opening)
    return cv2.morphologyEx(mask, cv2.MORPH_CLOSE, closing)


def inner_outline(contour: np.ndarray, width_px: int, height_px: int, border_px: int,
                  max_points: int) -> tuple[np.ndarray, bool]:
    """A contour's points (float, N×2) without those within ``border_px`` of the frame's
    edge (where the frame cuts a blob, its outline is the border's, not its own), thinned
    evenly to at most ``max_points``; and whether the frame's edge cut any off."""
    pts = contour.reshape(-1, 2).astype(np.float64)
    b = border_px
    inner = (pts[:, 0] > b) & (pts[:, 0] < width_px - 1 - b) & (pts[:, 1] > b) \
        & (pts[:, 1] < height_px - 1 - b)
    arc = pts[inner]
    if len(arc) > max_points:
        arc = arc[np.linspace(0, len(arc) - 1, max_points).astype(int)]
    return arc, not bool(inner.all())
