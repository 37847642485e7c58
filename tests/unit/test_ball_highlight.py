"""A ball whose specular highlight falls outside the colour range: the blob has a bite out of
its edge (seen on realistic follow_ball frames, lit from above), yet it is the ball."""

import dataclasses

import cv2
import numpy as np

from autopilot.perception.ball import BallDetector, BallDetectorSettings
from autopilot.perception.colors import COLORS

_, ORANGE_HSV = COLORS["orange"]
CENTRE, RADIUS = (320.0, 200.0), 17.0


def _frame(bite: bool) -> np.ndarray:
    """An orange disc on grey-green ground (drawn 8× finer, then averaged: antialiased), with a
    pale, unsaturated highlight cutting into its top edge."""
    k = 8
    big = np.full((480 * k, 640 * k, 3), (90, 120, 100), np.uint8)
    centre = (int(CENTRE[0] * k + k / 2), int(CENTRE[1] * k + k / 2))
    cv2.circle(big, centre, int(RADIUS * k), (0, 110, 255), -1)
    if bite:
        cv2.ellipse(big, (centre[0], centre[1] - int(RADIUS * k)), (9 * k, 8 * k), 0, 0, 360,
                    (170, 215, 250), -1)
        # ... inside the disc only: outside it the ground shows
        outside = np.zeros(big.shape[:2], np.uint8)
        cv2.circle(outside, centre, int(RADIUS * k), 255, -1)
        big[outside == 0] = (90, 120, 100)
    return cv2.resize(big, (640, 480), interpolation=cv2.INTER_AREA)


def test_a_ball_bitten_by_its_highlight_is_found_and_fitted_to_its_outline():
    settings = BallDetectorSettings(hsv_ranges=ORANGE_HSV, diameter_m=0.2)
    whole = BallDetector(settings).candidates(_frame(bite=False))
    assert len(whole) == 1
    bitten = _frame(bite=True)
    strict = BallDetector(dataclasses.replace(settings, min_solidity=1.0))
    judged_by_outline = strict.candidates(bitten)  # barely a ball, and mis-fitted if one
    assert not judged_by_outline or abs(judged_by_outline[0].radius_px - RADIUS) > 1.0
    found = BallDetector(settings).candidates(bitten)
    assert len(found) == 1
    ball = found[0]
    assert abs(ball.u_px - whole[0].u_px) < 0.5
    assert abs(ball.v_px - whole[0].v_px) < 1.0
    assert abs(ball.radius_px - whole[0].radius_px) < 0.3
    assert abs(whole[0].radius_px - RADIUS) < 0.5


def test_a_round_edge_s_pixel_staircase_is_not_a_bite_but_a_highlight_s_dent_is():
    from autopilot.perception.ball import _off_bites

    rng = np.random.default_rng(0)
    for radius in (4, 8, 17, 40, 150):
        k = 8
        big = np.zeros((400 * k, 400 * k), np.uint8)
        centre = (int((200 + rng.uniform(-0.5, 0.5)) * k), int((200 + rng.uniform(-0.5, 0.5)) * k))
        cv2.circle(big, centre, radius * k, 255, -1)
        disc = (cv2.resize(big, (400, 400), interpolation=cv2.INTER_AREA) > 127).astype(np.uint8)
        contours, _ = cv2.findContours(disc, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        assert _off_bites(contours[0]) is None, radius
    detector = BallDetector(BallDetectorSettings(hsv_ranges=ORANGE_HSV, diameter_m=0.2))
    contours, _ = cv2.findContours(detector.mask(_frame(bite=True)), cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_NONE)
    on_hull = _off_bites(max(contours, key=cv2.contourArea))
    assert on_hull is not None
    assert 0.5 < on_hull.mean() < 0.95
