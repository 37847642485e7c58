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

from autopilot.calibration.board import (
    BoardSpec,
    parse_board_spec,
)
from autopilot.calibration.common import (
    BOARD_SPEC_FORM,
    IMAGE_SUFFIXES,
    LIVE_DEFAULT_DURATION_S,
    LIVE_DEFAULT_FRAMES,
    CalibrationFailed,
    Log,
    Pattern,
    SourceKind,
    no_log,
)
from autopilot.calibration.detection import (
    NEIGHBOURS,
    BoardDetector,
    BoardView,
    consistent_corners,
    edge_width_px,
    edge_widths,
    local_residuals_squares,
    min_spacing_px,
    to_gray,
)
from autopilot.calibration.fit import (
    CalibrationResult,
    Coverage,
    Fit,
    ViewError,
    calibrate,
    coverage_of,
    fit_views,
    warnings_of,
)
from autopilot.calibration.runner import (
    calibrate_frames,
    format_summary,
    ros_path_for,
    run,
    write_result,
)
from autopilot.calibration.selection import (
    BoardPose,
    CalibrationOptions,
    Rejection,
    Selection,
    board_pose,
    rough_camera,
    select_views,
)
from autopilot.calibration.sources import (
    FrameSource,
    SourceFrame,
    is_rtp,
    source_kind,
)

__all__ = [
    "BOARD_SPEC_FORM",
    "IMAGE_SUFFIXES",
    "LIVE_DEFAULT_DURATION_S",
    "LIVE_DEFAULT_FRAMES",
    "NEIGHBOURS",
    "BoardDetector",
    "BoardPose",
    "BoardSpec",
    "BoardView",
    "CalibrationFailed",
    "CalibrationOptions",
    "CalibrationResult",
    "Coverage",
    "Fit",
    "FrameSource",
    "Log",
    "Pattern",
    "Rejection",
    "Selection",
    "SourceFrame",
    "SourceKind",
    "ViewError",
    "board_pose",
    "calibrate",
    "calibrate_frames",
    "consistent_corners",
    "coverage_of",
    "edge_width_px",
    "edge_widths",
    "fit_views",
    "format_summary",
    "is_rtp",
    "local_residuals_squares",
    "min_spacing_px",
    "no_log",
    "parse_board_spec",
    "ros_path_for",
    "rough_camera",
    "run",
    "select_views",
    "source_kind",
    "to_gray",
    "warnings_of",
    "write_result",
]
