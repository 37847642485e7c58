"""The ball's edge measure on a candidate whose fitted centre lies off the image (a sliver of
ball at the border): no measure, never an error (OpenCV's remap refused the empty crop, and the
detector's error failed a follow step in flight)."""

import numpy as np

from autopilot.perception.ball import EDGE_MIN_RADIUS_PX, BallCandidate, _at_edge, _edge_offset


def test_a_centre_off_the_image_gives_no_edge_measure():
    image = np.zeros((480, 640, 3), np.uint8)
    image[:, 630:] = (0, 128, 255)  # an orange sliver at the right border
    radius = max(EDGE_MIN_RADIUS_PX, 20.0)
    # outline points along the border, the fitted centre well beyond it
    outline = np.array([[639.0, 200.0 + 4 * i] for i in range(16)])
    c = BallCandidate(u_px=640.0 + radius + 40.0, v_px=230.0, radius_px=radius,
                      circularity=0.5, fill_ratio=0.5, cut_by_border=True, outline=outline)
    assert _edge_offset(image, c) is None
    assert _at_edge(image, c) == c
