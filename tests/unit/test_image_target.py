"""The image target's reference (the generated default, image files) and its errors."""

import cv2
import numpy as np
import pytest

from autopilot.perception.image_target import (
    DEFAULT_TARGET,
    ImageTargetDetector,
    ImageTargetError,
    ImageTargetSettings,
    default_target_image,
    load_target_image,
)


def test_the_default_target_is_generated_the_same_every_time():
    a = default_target_image(256)
    assert a.shape == (256, 256, 3)
    assert np.array_equal(a, default_target_image(256))
    assert not np.array_equal(a, default_target_image(256, seed=1))
    assert np.array_equal(load_target_image(DEFAULT_TARGET), default_target_image())


def test_its_features_are_spread_over_it_and_do_not_repeat():
    image = default_target_image()
    orb = cv2.ORB_create(nfeatures=2000)
    kps, desc = orb.detectAndCompute(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY), None)
    pts = np.array([k.pt for k in kps])
    # every cell of a 4×4 grid holds features
    cells = np.histogram2d(pts[:, 0], pts[:, 1], bins=4, range=[[0, 1024], [0, 1024]])[0]
    assert cells.min() >= 20
    # few features have a near twin elsewhere (a repeating pattern would; the same corner at
    # another of ORB's scales is not elsewhere)
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
    pairs = matcher.knnMatch(desc, desc, k=2)
    twins = sum(1 for p in pairs if len(p) == 2 and p[1].distance < 20
                and np.linalg.norm(pts[p[1].trainIdx] - pts[p[1].queryIdx]) > 20)
    assert twins / len(pairs) < 0.02


def test_image_files_and_their_errors(tmp_path):
    path = tmp_path / "target.png"
    cv2.imwrite(str(path), default_target_image(300))
    assert load_target_image(path).shape == (300, 300, 3)
    with pytest.raises(ImageTargetError, match="no such image file"):
        load_target_image(tmp_path / "missing.png")
    (tmp_path / "bad.png").write_text("not an image")
    with pytest.raises(ImageTargetError, match="not an image"):
        load_target_image(tmp_path / "bad.png")
    cv2.imwrite(str(tmp_path / "tiny.png"), np.zeros((20, 20, 3), np.uint8))
    with pytest.raises(ImageTargetError, match="too small"):
        load_target_image(tmp_path / "tiny.png")


def test_a_featureless_image_is_refused():
    with pytest.raises(ImageTargetError, match="too few features"):
        ImageTargetDetector(np.full((400, 400, 3), 128, np.uint8), ImageTargetSettings(1.0))
