"""Builds the MuJoCo model: world + airframe + onboard cameras + scenario objects.

The airframe's physical parameters (mass, inertia, rotor layout, spin, thrust limits) are read
back from the compiled model, so the MJCF file is their single source.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import mujoco
import numpy as np

from drivers.base import CameraInfo, CameraIntrinsics
from drivers.camera_model import pinhole
from drivers.geometry import matrix_to_quat, quat_from_euler
from drivers.resources import sim_model_path
from drivers.sim.config import CameraConfig, SimConfig
from drivers.sim.flight.flight_stack import Airframe
from drivers.sim.frames import FLU_FROM_FRD, FRD_FROM_FLU, quat_ned_frd_to_enu_flu
from drivers.sim.scenario import ScenarioObject, WorldFrame

VEHICLE_PREFIX = "vehicle/"
VEHICLE_BODY = VEHICLE_PREFIX + "base"
_MUJOCO_CAM_FROM_OPTICAL = np.diag([1.0, -1.0, -1.0])  # MuJoCo cameras look along -z, y up


@dataclass(frozen=True, slots=True, eq=False)
class BuiltModel:
    model: mujoco.MjModel
    frame: WorldFrame
    airframe: Airframe
    body_id: int
    actuator_ids: np.ndarray
    cameras: dict[str, tuple[int, CameraInfo]]  # name → (MuJoCo camera id, info)


def camera_rotation_body(pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """Optical frame → body FRD for a camera whose boresight has the given elevation/azimuth."""
    p, y = math.radians(pitch_deg), math.radians(yaw_deg)
    z = np.array([math.cos(p) * math.cos(y), math.cos(p) * math.sin(y), -math.sin(p)])
    x = np.array([-math.sin(y), math.cos(y), 0.0])
    yv = np.cross(z, x)
    return np.column_stack((x, yv, z))


def camera_info(name: str, cfg: CameraConfig) -> CameraInfo:
    """The camera a configuration section describes: intrinsics and mounting."""
    return CameraInfo(name=name, intrinsics=camera_intrinsics(cfg),
                      rotation_body_cam=camera_rotation_body(cfg.pitch_deg, cfg.yaw_deg),
                      position_body_m=cfg.position_frd_m, rate_hz=cfg.rate_hz)


def mount_error(name: str, cfg: CameraConfig, seed: int) -> np.ndarray:
    """The rotation (optical → optical) by which camera ``name`` is really turned off its
    nominal mount: a rotation vector of ``mount_error_deg`` σ per axis, drawn once from
    (seed, camera); the identity for an ideal camera."""
    if not cfg.realistic or cfg.mount_error_deg <= 0.0:
        return np.eye(3)
    rng = np.random.default_rng((seed, zlib.crc32(name.encode()), 4))
    rvec = np.radians(cfg.mount_error_deg) * rng.standard_normal(3)
    return cv2.Rodrigues(rvec)[0]


def true_camera_info(name: str, cfg: CameraConfig, seed: int) -> CameraInfo:
    """The camera as it really is (what is rendered): the true intrinsics, the mount with its
    error."""
    nominal = camera_info(name, cfg)
    return CameraInfo(name=name, intrinsics=nominal.intrinsics,
                      rotation_body_cam=nominal.rotation_body_cam @ mount_error(name, cfg, seed),
                      position_body_m=nominal.position_body_m, rate_hz=cfg.rate_hz)


def reported_camera_info(name: str, cfg: CameraConfig) -> CameraInfo:
    """The camera as its frames describe it to the autopilot: the nominal mount, and the
    intrinsics of its ``calibration`` file (the true ones when it has none), as a MAVLink
    vehicle's camera with a calibration file."""
    info = camera_info(name, cfg)
    if cfg.calibration is None:
        return info
    from drivers.calibration import load_calibration

    intrinsics = load_calibration(cfg.calibration)
    if (intrinsics.width_px, intrinsics.height_px) != (cfg.width_px, cfg.height_px):
        raise ValueError(f"camera {name}: calibration {cfg.calibration} is for "
                         f"{intrinsics.width_px}x{intrinsics.height_px}, the camera is "
                         f"{cfg.width_px}x{cfg.height_px}")
    return dataclasses.replace(info, intrinsics=intrinsics)


def camera_intrinsics(cfg: CameraConfig) -> CameraIntrinsics:
    """The camera's intrinsics as delivered with its frames: MuJoCo's pinhole (square pixels,
    principal point centred; OpenCV puts pixel centres at integer coordinates, hence the
    half-pixel) with the configured lens distortion when the camera is ``realistic`` (the
    rendered image is then distorted to match; see drivers/sim/camera.py), none otherwise."""
    distortion = cfg.distortion if cfg.realistic else (0.0, 0.0, 0.0, 0.0, 0.0)
    return pinhole(cfg.width_px, cfg.height_px, cfg.hfov_deg, distortion)


def rotor_count(model_file: str) -> int:
    """How many rotors the airframe ``model_file`` (in sim_models/) has: its site actuators."""
    model = mujoco.MjModel.from_xml_path(str(sim_model_path(model_file)))
    return int(sum(model.actuator_trntype[i] == mujoco.mjtTrn.mjTRN_SITE
                   for i in range(model.nu)))


def build_model(cfg: SimConfig, scenario: Sequence[ScenarioObject] = ()) -> BuiltModel:
    spec = mujoco.MjSpec.from_file(str(sim_model_path(cfg.world)))
    spec.option.timestep = 1.0 / cfg.physics_rate_hz
    airframe_spec = mujoco.MjSpec.from_file(str(sim_model_path(cfg.vehicle.model)))

    north, east = cfg.vehicle.initial_north_east_m
    frame = WorldFrame(np.array([east, north, 0.0]))
    base = airframe_spec.body("base")
    if base is None:
        raise ValueError(f"{cfg.vehicle.model}: the airframe needs a body named 'base'")
    base.pos = [east, north, float(base.pos[2])]
    base.quat = quat_ned_frd_to_enu_flu(
        quat_from_euler(0.0, 0.0, math.radians(cfg.vehicle.initial_yaw_deg)))
    body = spec.worldbody.add_frame().attach_body(base, VEHICLE_PREFIX, "")

    enabled = {n: c for n, c in cfg.cameras.items() if c.enabled}
    for name, cam in enabled.items():
        r_body_cam = true_camera_info(name, cam, cfg.seed).rotation_body_cam
        r_flu_mjcam = FLU_FROM_FRD @ r_body_cam @ _MUJOCO_CAM_FROM_OPTICAL
        intr = camera_intrinsics(cam)
        body.add_camera(
            name=VEHICLE_PREFIX + name,
            pos=FLU_FROM_FRD @ np.array(cam.position_frd_m, dtype=float),
            quat=matrix_to_quat(r_flu_mjcam),
            fovy=math.degrees(2.0 * math.atan((cam.height_px / 2.0) / intr.fy)),
        )
    spec.visual.global_.offwidth = max([640, *(c.width_px for c in enabled.values())])
    spec.visual.global_.offheight = max([480, *(c.height_px for c in enabled.values())])

    for obj in scenario:
        obj.build(spec, frame)

    model = spec.compile()
    body_id = model.body(VEHICLE_BODY).id
    airframe, actuator_ids = _airframe(model, body_id)
    cameras = {
        name: (
            model.camera(VEHICLE_PREFIX + name).id,
            true_camera_info(name, cam, cfg.seed),
        )
        for name, cam in enabled.items()
    }
    return BuiltModel(model, frame, airframe, body_id, actuator_ids, cameras)


def _airframe(model: mujoco.MjModel, body_id: int) -> tuple[Airframe, np.ndarray]:
    com_flu = model.body_ipos[body_id]
    if not np.allclose(model.body_iquat[body_id], [1, 0, 0, 0], atol=1e-6):
        raise ValueError("the airframe's inertia must be given in body axes (diaginertia)")
    ids, positions, yaw_coeffs, thrust_max = [], [], [], []
    for i in range(model.nu):
        if model.actuator_trntype[i] != mujoco.mjtTrn.mjTRN_SITE:
            continue
        site = model.actuator_trnid[i, 0]
        if model.site_bodyid[site] != body_id:
            continue
        if not np.allclose(model.site_quat[site], [1, 0, 0, 0], atol=1e-6):
            raise ValueError(f"rotor site {model.site(site).name} must be aligned with the body")
        gear = model.actuator_gear[i]
        if not np.allclose(gear[:5], [0, 0, 1, 0, 0]):
            raise ValueError(f"rotor {model.actuator(i).name}: gear must be (0 0 1 0 0 k)")
        ids.append(i)
        positions.append(FRD_FROM_FLU @ (model.site_pos[site] - com_flu))
        yaw_coeffs.append(-gear[5])  # about z-down
        thrust_max.append(model.actuator_ctrlrange[i, 1])
    if len(ids) < 4:
        raise ValueError(f"the airframe needs at least 4 rotor actuators, found {len(ids)}")
    inertia = model.body_inertia[body_id].copy()  # principal moments, unchanged by FLU → FRD
    airframe = Airframe(
        mass_kg=float(model.body_subtreemass[body_id]),
        inertia_frd_kg_m2=inertia,
        rotor_positions_frd_m=np.array(positions),
        yaw_coefficients_m=np.array(yaw_coeffs),
        thrust_max_n=np.array(thrust_max),
    )
    return airframe, np.array(ids)
