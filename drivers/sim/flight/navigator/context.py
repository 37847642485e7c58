"""What the navigator's modes share (PX4's ``Navigator`` object, which its ``NavigatorMode``
classes reach through): the parameters, the local origin and home, the time, the newest
estimate, the hold point and heading, the cruise speed asked for, the events and texts, and
the setpoints every mode builds on (hold there, come to a stop, descend to land)."""

from __future__ import annotations

import enum
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivers.base import FlightMode
from drivers.geo import GlobalOrigin
from drivers.geometry import wrap_pi
from drivers.mission import GLOBAL_FRAMES, RELATIVE_ALT_FRAMES, Frame, MissionItem
from drivers.sim.flight.params import Parameters
from drivers.sim.flight.position_control import ControlSetpoint

NAN = float("nan")
YAW_TO_TARGET_MIN_M = 1.0  # closer than this, the heading is kept (no spinning on the spot)


class MissionState(enum.IntEnum):
    """MAVLink MISSION_STATE (MISSION_CURRENT.mission_state)."""

    UNKNOWN = 0
    NO_MISSION = 1
    NOT_STARTED = 2
    ACTIVE = 3
    PAUSED = 4
    COMPLETE = 5


@dataclass(frozen=True, slots=True)
class MissionStatus:
    """The mission as MISSION_CURRENT reports it (immutable: read from other threads)."""

    total: int
    current: int
    state: MissionState
    in_mission_mode: bool
    mission_id: int
    fence_id: int
    rally_id: int


@dataclass(frozen=True, slots=True)
class NavEvent:
    """``kind``: ``current`` (the current item changed), ``reached`` (an item was reached),
    ``photo`` (take one now; ``seq`` is the photo's index), ``video_start`` / ``video_stop``,
    ``finished`` (the last item is done)."""

    time_s: float
    kind: str
    seq: int


@dataclass(slots=True)
class NavSetpoint:
    sp: ControlSetpoint
    #: the mode wants to leave the ground (a takeoff or a mission's first climb)
    takeoff: bool = False
    #: descending to touch down (the flight stack spools the motors down on contact)
    landing: bool = False


@dataclass(frozen=True, slots=True)
class Estimate:
    """The part of the state estimate the navigator needs (local NED)."""

    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    yaw_rad: float


class NavContext:
    def __init__(self, params: Parameters, origin: GlobalOrigin, *,
                 request_mode: Callable[[FlightMode], None],
                 complete: Callable[[FlightMode, FlightMode], None],
                 event: Callable[[str], None]) -> None:
        self.params = params
        self.origin = origin
        self.request_mode = request_mode  # a mode asks the commander for another
        self.complete = complete  # a mode is done: (it, the one to switch to)
        self.event = event  # a text for the ground station (STATUSTEXT)
        self.events: deque[NavEvent] = deque(maxlen=1024)
        #: home in local NED (set when the vehicle arms), None before
        self.home: np.ndarray | None = None
        self.now = 0.0
        self.flying = False  # the vehicle has left the ground (its takeoff ramp is over)
        self.mode: FlightMode | None = None
        self.est: Estimate | None = None
        #: where the vehicle holds, and its heading there (several modes end holding)
        self.hold_pos = np.zeros(3)
        self.hold_yaw = 0.0
        self.yaw_sp = 0.0  # the heading setpoint, slewed towards hold_yaw
        #: DO_CHANGE_SPEED's horizontal speed (NaN: MPC_XY_CRUISE)
        self.speed_override = NAN

    def emit(self, kind: str, seq: int) -> None:
        self.events.append(NavEvent(self.now, kind, seq))

    def cruise_m_s(self) -> float:
        return self.speed_override if math.isfinite(self.speed_override) \
            else self.params["MPC_XY_CRUISE"]

    def home_or(self, fallback: np.ndarray) -> np.ndarray:
        return self.home if self.home is not None else fallback

    def hold_setpoint(self) -> ControlSetpoint:
        return ControlSetpoint(self.hold_pos.tolist(), [NAN, NAN, NAN], self.hold_yaw,
                               xy_vel_max_m_s=self.params["MPC_XY_CRUISE"])

    def stopping_point(self, est: Estimate, landed: bool) -> np.ndarray:
        """Where the vehicle comes to rest braking at MPC_ACC_HOR (PX4's loiter brake)."""
        pos = est.position_ned_m.astype(float).copy()
        if landed:
            return pos
        vel = est.velocity_ned_m_s
        speed = float(np.hypot(vel[0], vel[1]))
        pos[:2] += vel[:2] * speed / (2.0 * self.params["MPC_ACC_HOR"])
        return pos

    def slew_yaw(self, target: float, dt: float) -> float:
        """Turn towards ``target`` at most at MPC_YAWRAUTO_MAX (auto modes turn gently)."""
        step = math.radians(self.params["MPC_YAWRAUTO_MAX"]) * dt
        err = wrap_pi(target - self.yaw_sp)
        self.yaw_sp = wrap_pi(self.yaw_sp + max(-step, min(step, err)))
        return self.yaw_sp

    def descend(self, est: Estimate, height_agl_m: float, xy) -> NavSetpoint:
        """Land at ``xy``: down at MPC_Z_V_AUTO_DN, slowing to MPC_LAND_SPEED below
        MPC_LAND_ALT2 (linearly between MPC_LAND_ALT1 and MPC_LAND_ALT2)."""
        p = self.params
        home_z = self.home[2] if self.home is not None else 0.0
        height = height_agl_m if math.isfinite(height_agl_m) \
            else home_z - est.position_ned_m[2]
        alt1, alt2 = p["MPC_LAND_ALT1"], p["MPC_LAND_ALT2"]
        slow, fast = p["MPC_LAND_SPEED"], p["MPC_Z_V_AUTO_DN"]
        if height <= alt2 or alt1 <= alt2:
            speed = slow if height <= alt2 else fast
        else:  # between the two altitudes the descent slows down linearly
            blend = min(max((height - alt2) / (alt1 - alt2), 0.0), 1.0)
            speed = slow + blend * (fast - slow)
        return NavSetpoint(ControlSetpoint([float(xy[0]), float(xy[1]), NAN], [NAN, NAN, speed],
                                           self.hold_yaw, xy_vel_max_m_s=p["MPC_XY_CRUISE"],
                                           z_vel_max_down_m_s=max(speed,
                                                                  p["MPC_Z_VEL_MAX_DN"])),
                           landing=True)

    def position_of(self, item: MissionItem, home: np.ndarray,
                    current: np.ndarray | None = None) -> np.ndarray:
        """Local NED of an item's position (a missing or zero lat/lon: ``current``'s)."""
        here = home if current is None else current
        n, e, d = (float(v) for v in here)
        frame = item.frame
        if item.has_position and not (frame in GLOBAL_FRAMES and item.x == 0 and item.y == 0):
            if frame in GLOBAL_FRAMES:
                n, e, _ = self.origin.to_ned(item.x, item.y, self.origin.alt_amsl_m)
            elif frame == Frame.LOCAL_NED:
                n, e = item.x, item.y
        if math.isfinite(item.z):
            if frame in RELATIVE_ALT_FRAMES:
                d = float(home[2]) - item.z
            elif frame in GLOBAL_FRAMES:
                d = self.origin.alt_amsl_m - item.z
            elif frame == Frame.LOCAL_NED:
                d = item.z
        return np.array([n, e, d])


def heading_to(target_ne, est: Estimate) -> float:
    """The heading from the vehicle to ``target_ne`` (NaN when it is nearer than a metre)."""
    delta = np.asarray(target_ne[:2]) - est.position_ned_m[:2]
    if float(np.hypot(*delta)) <= YAW_TO_TARGET_MIN_M:
        return NAN
    return math.atan2(delta[1], delta[0])


def or_default(value: float, default: float) -> float:
    return value if math.isfinite(value) else default
