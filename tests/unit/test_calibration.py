"""Camera calibration files: OpenCV FileStorage and ROS camera_calibration YAML."""

import pytest

from drivers.base import CameraIntrinsics
from drivers.calibration import CalibrationError, load_calibration, write_calibration

ROS_YAML = """\
image_width: 640
image_height: 480
camera_name: front
camera_matrix:
  rows: 3
  cols: 3
  data: [320.5, 0.0, 319.5, 0.0, 321.0, 239.5, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.1, 0.01, 0.0, 0.0, 0.0]
"""


def test_opencv_file_round_trip(tmp_path):
    intr = CameraIntrinsics(640, 480, 319.5, 319.5, 319.5, 239.5, (0.1, -0.02, 0.0, 0.0, 0.0))
    path = tmp_path / "front.yaml"
    write_calibration(path, intr)
    assert path.read_text().startswith("%YAML")  # OpenCV FileStorage
    assert load_calibration(path) == intr


def test_ros_camera_calibration_yaml(tmp_path):
    path = tmp_path / "ost.yaml"
    path.write_text(ROS_YAML)
    got = load_calibration(path)
    assert (got.width_px, got.height_px, got.fx, got.fy, got.cx, got.cy) == \
        (640, 480, 320.5, 321.0, 319.5, 239.5)
    assert got.distortion == (-0.1, 0.01, 0.0, 0.0, 0.0)


@pytest.mark.parametrize(("text", "match"), [
    ("image_width: 640\nimage_height: 480\n", "missing key 'camera_matrix'"),
    ("image_width: 640\nimage_height: 480\ncamera_matrix: {data: [1, 2, 3]}\n",
     "expected 9 numbers"),
    ("image_width: 640\nimage_height: 480\ncamera_matrix: {data: [0,0,0,0,0,0,0,0,1]}\n",
     "positive fx"),
    ("- just\n- a list\n", "expected a mapping"),
])
def test_bad_files_say_what_is_wrong(tmp_path, text, match):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(CalibrationError, match=match):
        load_calibration(path)
    with pytest.raises(CalibrationError, match="no such calibration file"):
        load_calibration(tmp_path / "missing.yaml")
