"""Camera calibration files: the intrinsics of a camera whose frames arrive as video.

Reads the two formats calibration tools write:

* OpenCV ``FileStorage`` YAML or XML (``%YAML:1.0``; ``camera_matrix`` / ``distortion_coefficients``
  as ``!!opencv-matrix``, ``image_width`` / ``image_height``), as OpenCV's calibration sample
  writes it;
* ROS ``camera_calibration`` YAML (``camera_matrix: {rows, cols, data}``,
  ``distortion_coefficients: {data}``, ``image_width``, ``image_height``).

Writes both: the OpenCV format (:func:`write_calibration`; what ``autopilot sim --out`` leaves
for its camera, and ``autopilot calibrate``'s main file) and ROS's camera_info YAML
(:func:`write_ros_calibration`, as ROS's ``camera_calibration`` saves it). Either loads back
with :func:`load_calibration`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import yaml

from drivers.base import CameraIntrinsics


class CalibrationError(ValueError):
    pass


def load_calibration(path: str | Path) -> CameraIntrinsics:
    path = Path(path)
    if not path.is_file():
        raise CalibrationError(f"{path}: no such calibration file")
    text = path.read_text(errors="replace")
    if text.startswith("%YAML") or path.suffix.lower() == ".xml":
        size, matrix, dist = _read_opencv(path)
    else:
        size, matrix, dist = _read_ros(path, text)
    width, height = size
    k = np.asarray(matrix, dtype=float).reshape(3, 3)
    if not (k[0, 0] > 0 and k[1, 1] > 0 and width > 0 and height > 0):
        raise CalibrationError(f"{path}: camera_matrix needs positive fx, fy and the image size "
                               f"positive; got fx={k[0, 0]}, fy={k[1, 1]}, {width}x{height}")
    d = [float(v) for v in np.asarray(dist, dtype=float).ravel()]
    d = (d + [0.0] * 5)[:5] if len(d) <= 5 else d
    return CameraIntrinsics(int(width), int(height), float(k[0, 0]), float(k[1, 1]),
                            float(k[0, 2]), float(k[1, 2]), tuple(d))


def write_calibration(path: str | Path, intrinsics: CameraIntrinsics,
                      metadata: Mapping[str, int | float | str] | None = None) -> None:
    """OpenCV FileStorage YAML (whatever the file's suffix): ``image_width``,
    ``image_height``, ``camera_matrix``, ``distortion_coefficients``, then ``metadata``'s
    entries (e.g. ``reprojection_rms_px``; names must be valid FileStorage keys)."""
    import cv2

    if not Path(path).parent.is_dir():
        raise CalibrationError(f"{path}: cannot write: no such folder")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_FORMAT_YAML)
    except cv2.error:
        fs = None
    if fs is None or not fs.isOpened():
        raise CalibrationError(f"{path}: cannot write (no such folder, or not permitted)")
    try:
        fs.write("image_width", intrinsics.width_px)
        fs.write("image_height", intrinsics.height_px)
        fs.write("camera_matrix", intrinsics.matrix)
        # a column (OpenCV's calibration sample writes 5x1): a 1-D array would be written as an
        # n-d matrix, which readers expecting rows and cols do not take
        fs.write("distortion_coefficients",
                 np.asarray(intrinsics.distortion, dtype=float).reshape(-1, 1))
        for key, value in (metadata or {}).items():
            fs.write(key, value)
    finally:
        fs.release()


def write_ros_calibration(path: str | Path, intrinsics: CameraIntrinsics,
                          camera_name: str = "camera") -> None:
    """ROS camera_info YAML (``camera_calibration_parsers``' format) for a monocular camera:
    ``plumb_bob`` distortion (``rational_polynomial`` with 8 coefficients), identity
    rectification and the projection matrix of the undistorted image as ROS's calibrator
    makes it (``cv2.getOptimalNewCameraMatrix``, alpha 0: only valid pixels)."""
    import cv2

    k = intrinsics.matrix
    dist = [float(v) for v in intrinsics.distortion]
    size = (intrinsics.width_px, intrinsics.height_px)
    if any(dist):
        new_k, _ = cv2.getOptimalNewCameraMatrix(k, np.asarray(dist), size, 0.0, size)
    else:
        new_k = k
    projection = np.hstack([np.asarray(new_k, dtype=float), np.zeros((3, 1))])

    def matrix(rows: int, cols: int, values) -> str:
        data = ", ".join(repr(float(v)) for v in np.asarray(values, dtype=float).ravel())
        return f"\n  rows: {rows}\n  cols: {cols}\n  data: [{data}]"

    model = "plumb_bob" if len(dist) <= 5 else "rational_polynomial"
    text = (f"image_width: {size[0]}\nimage_height: {size[1]}\ncamera_name: {camera_name}\n"
            f"camera_matrix:{matrix(3, 3, k)}\n"
            f"distortion_model: {model}\n"
            f"distortion_coefficients:{matrix(1, len(dist), dist)}\n"
            f"rectification_matrix:{matrix(3, 3, np.eye(3))}\n"
            f"projection_matrix:{matrix(3, 4, projection)}\n")
    if not Path(path).parent.is_dir():
        raise CalibrationError(f"{path}: cannot write: no such folder")
    try:
        Path(path).write_text(text)
    except OSError as exc:
        raise CalibrationError(f"{path}: cannot write: {exc.strerror}") from None


def _read_opencv(path: Path):
    import cv2

    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        if not fs.isOpened():
            raise CalibrationError(f"{path}: not an OpenCV FileStorage file")
        matrix = fs.getNode("camera_matrix").mat()
        dist = fs.getNode("distortion_coefficients").mat()
        width = fs.getNode("image_width").real()
        height = fs.getNode("image_height").real()
    finally:
        fs.release()
    if matrix is None or matrix.size != 9:
        raise CalibrationError(f"{path}: camera_matrix: expected a 3x3 matrix")
    return (width, height), matrix, np.zeros(5) if dist is None else dist


def _read_ros(path: Path, text: str):
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise CalibrationError(f"{path}: not YAML: {exc}") from None
    if not isinstance(data, dict):
        raise CalibrationError(f"{path}: expected a mapping with camera_matrix")
    try:
        matrix = data["camera_matrix"]["data"]
        width, height = data["image_width"], data["image_height"]
    except (KeyError, TypeError) as exc:
        raise CalibrationError(f"{path}: missing key {exc} (expected image_width, image_height, "
                               "camera_matrix.data)") from None
    if len(matrix) != 9:
        raise CalibrationError(f"{path}: camera_matrix.data: expected 9 numbers, got "
                               f"{len(matrix)}")
    dist = (data.get("distortion_coefficients") or {}).get("data", [0.0] * 5)
    return (width, height), matrix, dist
