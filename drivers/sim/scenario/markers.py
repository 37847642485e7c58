"""Marker boards: a square fiducial (ArUco or AprilTag) generated from OpenCV's
dictionaries, facing the drone, its travel, or a fixed heading."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Literal

import cv2
import mujoco
import numpy as np

from drivers.base import CameraInfo
from drivers.geometry import quat_to_matrix
from drivers.markers import aruco_dictionary
from drivers.sim.frames import quat_enu_flu_to_ned_frd
from drivers.sim.scenario.bodies import (
    BodyTruth,
    ScenarioObject,
    WorldFrame,
    yaw_quat_enu,
)
from drivers.sim.scenario.paths import (
    ClosedPath,
    PathName,
    Static,
    Trajectory,
    named_path,
)

Facing = Literal["drone", "travel", "trail", "fixed"]

#: AprilTag families by their OpenCV dictionary names (the same codes and ids).
#: The printed marker's frame in a board's body frame (columns: the marker's axes in FRD). The
#: marker frame is OpenCV's: x right and y up as the marker is read, z out of its face; the
#: board's body x is the face's normal, so the marker's x is the body's left (−y) and its y the
#: body's up (−z).
BOARD_FROM_MARKER = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])

VEHICLE_BODY = "vehicle/base"  # drivers/sim/model.py's VEHICLE_BODY (it imports this module)
PLATE_M = 0.001  # the printed face's thickness, in front of the board


def marker_texture(dictionary: str, marker_id: int, size_m: float, board_m: float,
                   px_per_cell: int = 16) -> tuple[np.ndarray, float]:
    """The board's face as a grey-scale image: the marker (black square of side ``size_m``,
    code cells of ``px_per_cell`` texels) centred in a white quiet zone. Returns the image and
    the board side it spans (within a texel of ``board_m``, so that the marker is exactly
    ``size_m``)."""
    d = aruco_dictionary(dictionary)
    if not 0 <= marker_id < d.bytesList.shape[0]:
        raise ValueError(f"{dictionary} has no marker {marker_id}")
    if board_m < size_m:
        raise ValueError("the board must be at least as large as the marker")
    side = (d.markerSize + 2) * px_per_cell
    marker = cv2.aruco.generateImageMarker(d, marker_id, side, borderBits=1)
    n = round(board_m / size_m * side)
    n += (n - side) % 2  # an even margin, so the marker sits in the middle
    image = np.full((n, n), 255, np.uint8)
    margin = (n - side) // 2
    image[margin:margin + side, margin:margin + side] = marker
    return image, n * size_m / side


@dataclass
class MarkerBoard(ScenarioObject):
    """A square board carrying a fiducial marker, moved along a trajectory.

    The body's origin is the marker's centre on the printed face; its x axis is the face's
    normal (out of the face), y right and z down as seen from behind the board (FRD), so its
    truth ``attitude_q`` is a heading: the direction the face looks in. The board stays
    upright and turns its face to the vehicle (``drone``), along its direction of travel
    (``travel``), against it (``trail``: towards a follower behind it), or to the fixed
    heading ``yaw_deg`` (``fixed``). The marker frame (OpenCV's) is
    ``R_ned_body @ BOARD_FROM_MARKER``; see :func:`marker_rotation_ned`.

    The face is a thin textured plate (MuJoCo maps a 2D texture onto each face of a box; on the
    −x face it shows mirrored, so the plate's back is buried in the board), the board a plain
    box behind it: no geometry beyond two boxes, no shadows, a texture of a few hundred texels.
    """

    name: str
    marker_id: int
    trajectory: Trajectory | Callable[[float], tuple[np.ndarray, np.ndarray, float]]
    dictionary: str = "DICT_ARUCO_ORIGINAL"
    size_m: float = 0.16
    board_m: float = 0.3
    thickness_m: float = 0.01
    facing: Facing = "drone"
    yaw_deg: float = 0.0  # the face's heading with ``fixed`` (NED, 0 = north)
    board_rgba: tuple[float, float, float, float] = (0.85, 0.85, 0.85, 1.0)
    px_per_cell: int = 16
    _mocap_id: int = field(default=-1, init=False)
    _vehicle_qpos: int = field(default=-1, init=False)
    _origin: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), init=False)
    _vehicle_start_ned: np.ndarray = field(default_factory=lambda: np.zeros(3), init=False)

    def __post_init__(self) -> None:
        if self.facing not in ("drone", "travel", "trail", "fixed"):
            raise ValueError(f"facing must be drone, travel, trail or fixed, not {self.facing!r}")
        self.texture, self.board_side_m = marker_texture(self.dictionary, self.marker_id,
                                                         self.size_m, self.board_m,
                                                         self.px_per_cell)

    @property
    def moves(self) -> bool:  # type: ignore[override]
        still = isinstance(self.trajectory, Static) or (
            isinstance(self.trajectory, ClosedPath) and self.trajectory.speed_m_s == 0.0)
        return self.facing == "drone" or not still

    def heading(self, position_ned_m: np.ndarray, path_yaw_rad: float,
                vehicle_ned_m: np.ndarray | None) -> float:
        """The face's heading (NED, rad) for the board at a position."""
        if self.facing == "travel":
            return path_yaw_rad
        if self.facing == "trail":
            return path_yaw_rad + math.pi
        if self.facing == "drone" and vehicle_ned_m is not None:
            dn, de = vehicle_ned_m[0] - position_ned_m[0], vehicle_ned_m[1] - position_ned_m[1]
            if dn * dn + de * de > 1e-8:
                return math.atan2(de, dn)
        return math.radians(self.yaw_deg)

    def build(self, spec: mujoco.MjSpec, frame: WorldFrame) -> None:
        pos, _, yaw = self.trajectory(0.0)
        self._vehicle_start_ned = frame.to_ned(frame.origin_enu_m)
        vehicle = spec.body(VEHICLE_BODY)
        if vehicle is not None:
            self._vehicle_start_ned = frame.to_ned(np.array(vehicle.pos, dtype=float))
        heading = self.heading(pos, yaw, self._vehicle_start_ned)
        n = self.texture.shape[0]
        texture = spec.add_texture(name=f"{self.name}/texture", type=mujoco.mjtTexture.mjTEXTURE_2D,
                                   width=n, height=n, nchannel=3)
        texture.data = np.repeat(self.texture[:, :, None], 3, axis=2).tobytes()
        material = spec.add_material(name=f"{self.name}/face", specular=0.0, shininess=0.0,
                                     reflectance=0.0, rgba=[1.0, 1.0, 1.0, 1.0])
        material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = f"{self.name}/texture"
        body = spec.worldbody.add_body(name=self.name, mocap=True, pos=frame.to_enu(pos),
                                       quat=yaw_quat_enu(heading))
        half = self.board_side_m / 2.0
        # body FLU: the face's normal is +x
        body.add_geom(name=f"{self.name}/face", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[PLATE_M / 2.0, half, half], pos=[-PLATE_M / 2.0, 0.0, 0.0],
                      material=f"{self.name}/face", contype=0, conaffinity=0)
        body.add_geom(name=f"{self.name}/board", type=mujoco.mjtGeom.mjGEOM_BOX,
                      size=[self.thickness_m / 2.0, half, half],
                      pos=[-PLATE_M - self.thickness_m / 2.0, 0.0, 0.0],
                      rgba=list(self.board_rgba), contype=0, conaffinity=0)

    def bind(self, model: mujoco.MjModel, data: mujoco.MjData, frame: WorldFrame) -> None:
        self._mocap_id = int(model.body_mocapid[model.body(self.name).id])
        self._origin = tuple(frame.origin_enu_m.tolist())
        vehicle = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, VEHICLE_BODY)
        if vehicle >= 0 and model.body_jntadr[vehicle] >= 0:
            self._vehicle_qpos = int(model.jnt_qposadr[model.body_jntadr[vehicle]])
        self.update(0.0, data)

    def _vehicle_ned(self, data: mujoco.MjData) -> np.ndarray | None:
        if self._vehicle_qpos < 0:
            return self._vehicle_start_ned
        e, n, u = data.qpos[self._vehicle_qpos:self._vehicle_qpos + 3]
        ox, oy, oz = self._origin
        return np.array((n - oy, e - ox, oz - u))

    def update(self, time_s: float, data: mujoco.MjData) -> None:
        pos, _, yaw = self.trajectory(time_s)
        heading = self.heading(pos, yaw, self._vehicle_ned(data) if self.facing == "drone"
                               else None)
        n, e, d = pos
        ox, oy, oz = self._origin
        data.mocap_pos[self._mocap_id] = (e + ox, n + oy, oz - d)
        data.mocap_quat[self._mocap_id] = yaw_quat_enu(heading)

    def truth(self, time_s: float, data: mujoco.MjData) -> BodyTruth:
        """The marker's centre, the board's motion, and its attitude as rendered."""
        pos, vel, _ = self.trajectory(time_s)
        q = quat_enu_flu_to_ned_frd(np.array(data.mocap_quat[self._mocap_id], dtype=float))
        return BodyTruth(pos, vel, q)


def marker_rotation_ned(board_attitude_q: np.ndarray) -> np.ndarray:
    """The marker frame's axes (OpenCV's: x right, y up, z out of the face) in NED, from a
    board's truth attitude."""
    return quat_to_matrix(board_attitude_q) @ BOARD_FROM_MARKER


def marker_in_camera(board: BodyTruth, vehicle: BodyTruth,
                     camera: CameraInfo) -> tuple[np.ndarray, np.ndarray]:
    """A board's marker seen from a camera, from ground truth: the marker centre in the optical
    frame and ``rotation_cam_marker`` (as :class:`~autopilot.perception.marker.MarkerDetection`
    reports them)."""
    r_ned_body = quat_to_matrix(vehicle.attitude_q)
    r_ned_cam = r_ned_body @ camera.rotation_body_cam
    position = r_ned_cam.T @ (np.asarray(board.position_ned_m) - vehicle.position_ned_m
                              - r_ned_body @ camera.position_body_m)
    return position, r_ned_cam.T @ marker_rotation_ned(board.attitude_q)


def marker_objects(*, marker_id: int = 36, dictionary: str = "DICT_ARUCO_ORIGINAL",
                   size_m: float = 0.16, board_m: float = 0.3, path: PathName = "static",
                   speed_mps: float = 0.0, height_m: float = 1.5, start_distance_m: float = 2.0,
                   path_size_m: float = 6.0, facing: Facing = "drone",
                   yaw_deg: float | None = None, decoys: int = 0,
                   decoy_ids: Sequence[int] = (), seed: int = 0, start_delay_s: float = 0.0,
                   accel_mps2: float = 0.0, origin_north_east_m: Sequence[float] = (0.0, 0.0),
                   heading_deg: float = 0.0, name: str = "marker") -> list[ScenarioObject]:
    """The followed marker board and its decoys, for a mission's scenario.

    The board starts ``start_distance_m`` ahead of ``origin_north_east_m`` along
    ``heading_deg`` (the vehicle's start and heading), its marker's centre ``height_m`` above
    the ground, and moves along ``path`` (as the ball's paths; ``path_size_m`` sets their
    size) at ``speed_mps`` after ``start_delay_s``, reaching that speed at ``accel_mps2`` (0:
    at once). ``facing``: drone | travel | trail | fixed; ``yaw_deg`` is the face's heading when
    fixed (default: back towards the start). ``decoys`` boards with other ids of the same
    dictionary (``decoy_ids``, or drawn with ``seed``) stand still beside the path, facing the
    vehicle. The first object is the followed board, named ``name``; decoys are
    ``{name}_decoy{i}``."""
    heading = math.radians(heading_deg)
    north, east = origin_north_east_m
    start = (north + start_distance_m * math.cos(heading),
             east + start_distance_m * math.sin(heading), -height_m)
    ramp = speed_mps / accel_mps2 if accel_mps2 > 0.0 else 0.0
    trajectory = named_path(path, start, speed_mps, path_size_m, heading, seed,
                            start_delay_s, ramp, accel_m_s2=accel_mps2 or 2.0)
    fixed_yaw = heading_deg + 180.0 if yaw_deg is None else yaw_deg
    board = MarkerBoard(name, marker_id, trajectory, dictionary=dictionary, size_m=size_m,
                        board_m=board_m, facing=facing, yaw_deg=fixed_yaw)
    objects: list[ScenarioObject] = [board]
    if decoys <= 0:
        return objects
    rng = np.random.default_rng(seed + 104729)
    count = aruco_dictionary(dictionary).bytesList.shape[0]
    ids = [i for i in decoy_ids if i != marker_id]
    pool = [i for i in range(count) if i != marker_id and i not in ids]
    ids += [int(i) for i in rng.choice(pool, size=max(0, decoys - len(ids)), replace=False)]
    origin = np.array([north, east, 0.0])
    for i, decoy_id in enumerate(ids[:decoys]):
        for _ in range(100):  # beside the path, clear of the start and of the board's start
            along = trajectory(float(rng.uniform(0.0, 60.0)))[0]
            angle = rng.uniform(0.0, 2.0 * math.pi)
            pos = along + rng.uniform(0.6, 2.5) * np.array([math.cos(angle), math.sin(angle),
                                                            0.0])
            pos[2] = -float(rng.uniform(0.5, 2.5))
            if (np.linalg.norm(pos[:2] - origin[:2]) > 1.5
                    and np.linalg.norm(pos - np.asarray(start)) > 0.6):
                break
        objects.append(MarkerBoard(f"{name}_decoy{i}", decoy_id, Static(tuple(pos)),
                                   dictionary=dictionary, size_m=size_m, board_m=board_m,
                                   facing="drone"))
    return objects


# --------------------------------------------------------------------------------------------
# Calibration boards
# --------------------------------------------------------------------------------------------
