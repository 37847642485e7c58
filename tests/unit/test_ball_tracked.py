"""The ball as realistic frames show it: its lit top overexposed (a clipped red channel turns
orange towards yellow), and passing in front of something of its own colour, which hides the
part of its edge that lies against the other's face."""

import cv2
import numpy as np
import pytest

from autopilot.perception.ball import BallDetector, BallDetectorSettings
from autopilot.perception.colors import COLORS, ORANGEISH_RGBA

ORANGE_RGBA, ORANGE_HSV = COLORS["orange"]
CENTRE, RADIUS = (320.0, 240.0), 16.0
GROUND = (90, 120, 100)
K = 8  # drawn this much finer, then averaged: antialiased edges


def _bgr(hue: int, value: int = 255) -> tuple[int, int, int]:
    pixel = np.array([[[hue, 250, value]]], np.uint8)
    return tuple(int(c) for c in cv2.cvtColor(pixel, cv2.COLOR_HSV2BGR)[0, 0])


def _draw(shapes) -> np.ndarray:
    big = np.full((480 * K, 640 * K, 3), GROUND, np.uint8)
    for draw in shapes:
        draw(big)
    return cv2.resize(big, (640, 480), interpolation=cv2.INTER_AREA)


def _ball(big, colour=None, top_colour=None, centre=CENTRE, radius=RADIUS):
    c = (int(centre[0] * K + K / 2), int(centre[1] * K + K / 2))
    cv2.circle(big, c, int(radius * K), colour or _bgr(13), -1)
    if top_colour is not None:  # the lit cap: the disc's upper 40 %
        cap = np.zeros(big.shape[:2], np.uint8)
        cv2.circle(cap, c, int(radius * K), 255, -1)
        cap[int((centre[1] - 0.2 * radius) * K):] = 0
        big[cap > 0] = top_colour


def _box(big, x0, y0, x1, y1, colour=None):
    cv2.rectangle(big, (int(x0 * K), int(y0 * K)), (int(x1 * K), int(y1 * K)),
                  colour or _bgr(14, 230), -1)


def _settings() -> BallDetectorSettings:
    return BallDetectorSettings(hsv_ranges=ORANGE_HSV, diameter_m=0.2)


def test_an_overexposed_top_is_still_the_ball_s_colour():
    """Hue 19–20 where the red channel clips (measured on realistic frames: the ball's top at
    19–20 with auto-exposure up); amber, the nearest decoy colour, renders at 21 and above."""
    frame = _draw([lambda b: _ball(b, top_colour=_bgr(20))])
    found = BallDetector(_settings()).candidates(frame)
    assert len(found) == 1
    assert found[0].radius_px == pytest.approx(RADIUS, abs=0.6)
    assert found[0].v_px == pytest.approx(CENTRE[1], abs=0.8)
    amber = _draw([lambda b: _ball(b, colour=_bgr(22)), ])
    assert BallDetector(_settings()).candidates(amber) == []
    # the rendered colours the detector must tell apart stay on their sides of the range
    (lo, hi), = ((r[0][0], r[1][0]) for r in ORANGE_HSV)
    hue = [cv2.cvtColor(np.uint8([[[int(255 * c) for c in rgba[2::-1]]]]),
                        cv2.COLOR_BGR2HSV)[0, 0, 0] for rgba in (ORANGE_RGBA, ORANGEISH_RGBA[2])]
    assert lo < hue[0] < hi < hue[1]


def _in_front_of_a_box() -> np.ndarray:
    # a box of the ball's colour behind its left 40 %: the outline follows the circle on the
    # right only (about 60 % of it)
    x0 = CENTRE[0] - 2.6 * RADIUS
    return _draw([lambda b: _box(b, x0, CENTRE[1] - 1.1 * RADIUS, CENTRE[0] - 0.2 * RADIUS,
                                 CENTRE[1] + 1.2 * RADIUS),
                  lambda b: _ball(b)])


def test_a_ball_in_front_of_its_colour_is_found_where_the_tracker_expects_it():
    detector = BallDetector(_settings())
    frame = _in_front_of_a_box()
    camera_free = detector.candidates(frame)
    assert not any(abs(c.radius_px - RADIUS) < 2 and abs(c.u_px - CENTRE[0]) < 3
                   for c in camera_free)  # too little of its edge for an unexpected ball
    window = detector._window(frame, (CENTRE[0] + 3, CENTRE[1] - 2), RADIUS * 1.1)
    found = detector._tracked(frame, window, (CENTRE[0] + 3, CENTRE[1] - 2), RADIUS * 1.1)
    assert len(found) == 1
    ball = found[0]
    assert ball.merged
    assert ball.u_px == pytest.approx(CENTRE[0], abs=1.0)
    assert ball.v_px == pytest.approx(CENTRE[1], abs=1.0)
    assert ball.radius_px == pytest.approx(RADIUS, rel=0.05)


@pytest.mark.parametrize(("expected_uv", "expected_radius"), [
    ((CENTRE[0], CENTRE[1]), RADIUS * 1.6),  # a ball of another size
    ((CENTRE[0] + 1.5 * RADIUS, CENTRE[1]), RADIUS),  # somewhere else
])
def test_only_the_expected_ball_is_taken_from_a_merged_blob(expected_uv, expected_radius):
    detector = BallDetector(_settings())
    frame = _in_front_of_a_box()
    window = detector._window(frame, expected_uv, expected_radius)
    assert detector._tracked(frame, window, expected_uv, expected_radius) == []


def test_a_box_alone_is_no_ball_even_where_one_is_expected():
    detector = BallDetector(_settings())
    frame = _draw([lambda b: _box(b, CENTRE[0] - RADIUS, CENTRE[1] - RADIUS,
                                  CENTRE[0] + RADIUS, CENTRE[1] + RADIUS)])
    window = detector._window(frame, CENTRE, RADIUS)
    assert detector._tracked(frame, window, CENTRE, RADIUS) == []
    assert detector.candidates(frame) == []


@pytest.mark.parametrize("radius", [8.0, 16.0, 40.0])
@pytest.mark.parametrize("blur_px", [0.0, 1.0])
def test_the_radius_is_the_ball_s_edge_not_its_mask_s(radius, blur_px):
    """The mask keeps blended edge pixels down to about a third ball, so its outline lies
    outside the edge (more so with blur): the range would come out 1–3 % short. The radius is
    moved to where the colour is halfway between the ball's and the ground's."""
    frame = _draw([lambda b: _ball(b, radius=radius)])
    if blur_px:
        frame = cv2.GaussianBlur(frame, (0, 0), blur_px)
    found = BallDetector(_settings()).candidates(frame)
    assert len(found) == 1
    ball = found[0]
    assert ball.edge_offset_px < -0.05  # the mask's outline was outside the edge
    assert ball.radius_px == pytest.approx(radius, rel=0.01, abs=0.08)
    assert ball.radius_px - ball.edge_offset_px > radius + 0.1  # … by more than this allows
