"""Calibration boards (chessboard, ChArUco) for ``autopilot calibrate`` in the simulator."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import cv2
import mujoco
import numpy as np

from drivers.geometry import quat_to_matrix
from drivers.markers import aruco_dictionary
from drivers.sim.scenario.bodies import (
    BodyTruth,
    ScenarioObject,
    WorldFrame,
)
from drivers.sim.scenario.markers import (
    PLATE_M,
)

CalibrationPattern = Literal["chessboard", "charuco"]

#: The printed pattern's frame in a calibration board's body frame (columns: the pattern's axes
#: in the body's FRD). The pattern frame is OpenCV's object frame as a camera in front of the
#: board reads it: x right, y down, z into the face; the body's x is the face's normal, so the
#: pattern's x is the body's left (−y), its y the body's down (+z), its z the body's back (−x).
BOARD_FROM_PATTERN = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def calibration_texture(pattern: CalibrationPattern, squares: tuple[int, int], *,
                        marker_ratio: float = 0.75, dictionary: str = "DICT_5X5_100",
                        px_per_square: int = 64, margin_squares: int = 1,
                        blur_squares: float = 0.0) -> np.ndarray:
    """A calibration board's face as a grey-scale image: ``squares`` (columns, rows) squares of
    ``px_per_square`` texels, chessboard or ChArUco (OpenCV's layout, markers of
    ``marker_ratio`` of a square from ``dictionary``), in a white margin of ``margin_squares``
    squares; the top-left square is black. ``blur_squares``: the standard deviation of a
    Gaussian blur of the print, in squares (see :class:`CalibrationBoard`).

    Square edges fall on texel boundaries at every mipmap level up to
    log2(``px_per_square``) when ``px_per_square`` is a power of two, so that OpenGL's texture
    filtering blurs them symmetrically and leaves the corners where they are."""
    cols, rows = squares
    if cols < 2 or rows < 2:
        raise ValueError(f"a calibration board needs at least 2x2 squares, got {cols}x{rows}")
    if px_per_square < 8:
        raise ValueError("px_per_square must be at least 8")
    margin = margin_squares * px_per_square
    if pattern == "chessboard":
        cells = (np.indices((rows, cols)).sum(axis=0) % 2).astype(np.uint8) * 255
        face = np.kron(cells, np.ones((px_per_square, px_per_square), np.uint8))
        image = cv2.copyMakeBorder(face, margin, margin, margin, margin, cv2.BORDER_CONSTANT,
                                   value=255)
    elif pattern == "charuco":
        if not 0.0 < marker_ratio < 1.0:
            raise ValueError(f"marker_ratio must be in (0, 1), got {marker_ratio}")
        board = charuco_board(squares, 1.0, marker_ratio, dictionary)
        size = (cols * px_per_square + 2 * margin, rows * px_per_square + 2 * margin)
        image = board.generateImage(size, marginSize=margin, borderBits=1)
    else:
        raise ValueError(f"unknown calibration pattern {pattern!r} (chessboard, charuco)")
    if blur_squares > 0.0:
        image = cv2.GaussianBlur(image, (0, 0), blur_squares * px_per_square,
                                 borderType=cv2.BORDER_REPLICATE)
    return image


def charuco_board(squares: tuple[int, int], square_m: float, marker_m_or_ratio: float,
                  dictionary: str):
    """OpenCV's ChArUco board (``cv2.aruco.CharucoBoard``: columns × rows of squares)."""
    d = aruco_dictionary(dictionary)
    needed = squares[0] * squares[1] // 2
    if d.bytesList.shape[0] < needed:
        raise ValueError(f"{dictionary} has {d.bytesList.shape[0]} markers; a "
                         f"{squares[0]}x{squares[1]} ChArUco board needs {needed}")
    return cv2.aruco.CharucoBoard(tuple(squares), square_m, marker_m_or_ratio, d)


@dataclass
class CalibrationBoard(ScenarioObject):
    """A flat camera-calibration board (chessboard or ChArUco) standing still at a pose.

    The body's origin is the centre of the pattern on the printed face; its x axis is the face's
    normal (out of the face), y right and z down as seen from behind the board (FRD), as for a
    :class:`MarkerBoard`, but ``attitude_q`` (body → NED) may tilt it any way. The pattern frame
    (OpenCV's object frame) is ``R_ned_body @ BOARD_FROM_PATTERN``; :meth:`corners_ned` gives
    where the pattern's inner corners are, in the order OpenCV's detectors report them.

    The texture has ``px_per_square`` texels a square (a power of two: see
    :func:`calibration_texture`); choose it larger than a square will appear in the image, so
    that the texture is minified (mipmapped), not magnified.

    ``blur_squares`` softens the print: a Gaussian blur of that standard deviation, in squares
    (e.g. 0.02 for ink that bleeds a little), so it scales with the board's distance, unlike
    the camera's own blur (lens, motion: see the camera's configuration). The blur is
    symmetric, so the corners stay where they are. 0 (the default): a sharp print.
    """

    name: str
    position_ned_m: tuple[float, float, float]
    attitude_q: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    pattern: CalibrationPattern = "chessboard"
    squares: tuple[int, int] = (10, 7)  # columns × rows of squares
    square_m: float = 0.05
    marker_m: float | None = None  # ChArUco: the markers' side (default 0.75 of a square)
    dictionary: str = "DICT_5X5_100"
    px_per_square: int = 64
    margin_squares: int = 1  # the white margin around the pattern, in squares
    #: The print's blur (Gaussian standard deviation, in squares); see the class notes.
    blur_squares: float = 0.0
    thickness_m: float = 0.01
    board_rgba: tuple[float, float, float, float] = (0.85, 0.85, 0.85, 1.0)
    #: The face's brightness: the printed white under the scene's light (below 1 keeps the
    #: lit face from saturating).
    face_gain: float = 0.8
    moves = False
    _mocap_id: int = field(default=-1, init=False)
    _origin: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), init=False)

    def __post_init__(self) -> None:
        marker = 0.75 * self.square_m if self.marker_m is None else self.marker_m
        if not 0.0 < marker < self.square_m:
            raise ValueError(f"marker_m must be between 0 and square_m, got {marker}")
        self.marker_m = marker
        self.texture = calibration_texture(self.pattern, self.squares,
                                           marker_ratio=marker / self.square_m,
                                           dictionary=self.dictionary,
                                           px_per_square=self.px_per_square,
                                           margin_squares=self.margin_squares,
                                           blur_squares=self.blur_squares)
        cols, rows = self.squares
        self.face_size_m = ((cols + 2 * self.margin_squares) * self.square_m,
                            (rows + 2 * self.margin_squares) * self.square_m)

    def pattern_points_m(self) -> np.ndarray:
        """The inner corners in the pattern frame, origin at the pattern's centre, ``(N, 3)``:
        row by row from the top left for a chessboard, by id for ChArUco (OpenCV's order)."""
        cols, rows = self.squares
        ij = np.stack(np.meshgrid(np.arange(1, cols), np.arange(1, rows)), axis=-1)
        xy = ij.reshape(-1, 2) * self.square_m - np.array([cols, rows]) * self.square_m / 2
        return np.column_stack([xy, np.zeros(len(xy))])

    def rotation_ned_pattern(self) -> np.ndarray:
        """The pattern frame's axes in NED (columns)."""
        return quat_to_matrix(np.asarray(self.attitude_q, dtype=float)) @ BOARD_FROM_PATTERN

    def corners_ned(self) -> np.ndarray:
        """Where the inner corners are, local NED, ``(N, 3)`` (order of
        :meth:`pattern_points_m`)."""
        return (np.asarray(self.position_ned_m, dtype=float)
                + self.pattern_points_m() @ self.rotation_ned_pattern().T)

    def build(self, spec: mujoco.MjSpec, frame: WorldFrame) -> None:
        height, width = self.texture.shape
        texture = spec.add_texture(name=f"{self.name}/texture",
                                   type=mujoco.mjtTexture.mjTEXTURE_2D,
                                   width=width, height=height, nchannel=3)
        texture.data = np.repeat(self.texture[:, :, None], 3, axis=2).tobytes()
        gain = self.face_gain
        material = spec.add_material(name=f"{self.name}/face", specular=0.0, shininess=0.0,
                                     reflectance=0.0, rgba=[gain, gain, gain, 1.0])
        material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"{self.name}/texture"
        body = spec.worldbody.add_body(name=self.name, mocap=True,
                                       pos=frame.to_enu(np.asarray(self.position_ned_m)),
                                       quat=self._quat_enu())
        half_w, half_h = self.face_size_m[0] / 2.0, self.face_size_m[1] / 2.0
        # body FLU: the face's normal is +x, the face spans y (width) and z (height)
        body.add_geom(name=f"{self.name}/face", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[PLATE_M / 2.0, half_w, half_h], pos=[-PLATE_M / 2.0, 0.0, 0.0],
                      material=f"{self.name}/face", contype=0, conaffinity=0)
        body.add_geom(name=f"{self.name}/board", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[self.thickness_m / 2.0, half_w, half_h],
                      pos=[-PLATE_M - self.thickness_m / 2.0, 0.0, 0.0],
                      rgba=list(self.board_rgba), contype=0, conaffinity=0)

    def _quat_enu(self) -> np.ndarray:
        from drivers.sim.frames import quat_ned_frd_to_enu_flu

        return quat_ned_frd_to_enu_flu(np.asarray(self.attitude_q, dtype=float))

    def bind(self, model: mujoco.MjModel, data: mujoco.MjData, frame: WorldFrame) -> None:
        self._mocap_id = int(model.body_mocapid[model.body(self.name).id])
        self._origin = tuple(frame.origin_enu_m.tolist())

    def truth(self, time_s: float, data: mujoco.MjData) -> BodyTruth:
        return BodyTruth(np.asarray(self.position_ned_m, dtype=float), np.zeros(3),
                         np.asarray(self.attitude_q, dtype=float))


# --------------------------------------------------------------------------------------------
# Images on the ground (seed 000's hover target) and a ground with features
# --------------------------------------------------------------------------------------------
