"""Typed messages for unit tests, with plain defaults: a vehicle hovering 2 m up, a 640×480
forward camera with 90° of horizontal field of view."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from drivers.base import (
    Battery,
    CameraInfo,
    CameraIntrinsics,
    FlightMode,
    Health,
    LandedState,
    VehicleState,
)
from drivers.geometry import quat_from_euler
from drivers.sim.model import camera_rotation_body


def vehicle_state(t: float = 0.0, pos: Sequence[float] = (0.0, 0.0, -2.0),
                  vel: Sequence[float] = (0.0, 0.0, 0.0), yaw: float = 0.0, *,
                  armed: bool = True, mode: FlightMode = FlightMode.OFFBOARD,
                  in_air: bool = True) -> VehicleState:
    return VehicleState(t, tuple(pos), tuple(vel), quat_from_euler(0.0, 0.0, yaw),
                        (0.0, 0.0, 0.0), armed, mode,
                        LandedState.IN_AIR if in_air else LandedState.ON_GROUND,
                        -pos[2] if in_air else math.nan, Battery(16.0, 10.0, 0.9),
                        Health())


def front_camera(pitch_down_deg: float = 0.0) -> CameraInfo:
    """At the body origin, looking forward, pitched down by ``pitch_down_deg``."""
    return CameraInfo("front", CameraIntrinsics(640, 480, 320.0, 320.0, 319.5, 239.5),
                      camera_rotation_body(-pitch_down_deg, 0.0), np.zeros(3), 30.0)
