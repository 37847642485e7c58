"""Pieces of the simulated ArduCopter (:mod:`drivers.sim.flight.arducopter`): what it passes to
the cascade underneath, GUIDED's commands, the commands of
the simulator's own driver in ArduCopter's modes, RTL's return altitude, CIRCLE's orbit and
the cascade's events in ArduCopter's words."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from drivers.base import FlightMode, LandedState, Setpoint
from drivers.geometry import yaw_from_quat
from drivers.mavlink.ardupilot import CopterMode, copter_mode
from drivers.mission import MissionItem, MissionType
from drivers.sim.flight.arducopter_modes import MODES
from drivers.sim.flight.arducopter_params import SiLimits
from drivers.sim.flight.commander import CommandRejected
from drivers.sim.flight.flight_stack import FlightStack
from drivers.sim.flight.guided import GuidedInput
from drivers.sim.flight.params import Parameters

#: RTL never returns lower than this above the current height when the cone limits it
RTL_ABS_MIN_CLIMB_M = 2.5
NAN = float("nan")


class OnCascade:
    """What the simulated ArduCopter passes straight to the PX4-like cascade underneath."""

    stack: FlightStack

    @property
    def armed(self) -> bool:
        return self.stack.armed

    @property
    def failsafe(self) -> str | None:
        return self.stack.failsafe

    @property
    def landed(self) -> bool:
        return self.stack.landed

    @property
    def landed_state(self) -> LandedState:
        return self.stack.landed_state

    @property
    def geofence_breach(self) -> str | None:
        return self.stack.geofence_breach

    def disarm(self, force: bool = False) -> None:
        self.stack.disarm(force)

    def set_mission(self, items: Sequence[MissionItem],
                    mission_type: int = MissionType.MISSION) -> None:
        self.stack.set_mission(items, mission_type)

    def set_mission_current(self, seq: int) -> None:
        self.stack.set_mission_current(seq)

    def landing_target(self, position_ned_m: Sequence[float], time_s: float) -> None:
        self.stack.landing_target(position_ned_m, time_s)

    def update_inner(self, dt: float, q: list[float], gyro: list[float]) -> list[float]:
        return self.stack.update_inner(dt, q, gyro)



class FlightModeCommands:
    """What the simulator's own driver asks (its :class:`~drivers.base.FlightMode` commands),
    as the Copter modes that do it — as the MAVLink drivers' ArduCopter profile asks."""

    def set_copter_mode(self, number: int) -> None:
        raise NotImplementedError

    def mission_start(self) -> None:
        raise NotImplementedError

    def land(self) -> None:
        """NAV_LAND: the LAND mode."""
        self.set_copter_mode(int(CopterMode.LAND))

    def return_to_launch(self) -> None:
        self.set_copter_mode(int(CopterMode.RTL))

    def hold(self) -> None:
        """NAV_LOITER_UNLIM: the LOITER mode."""
        self.set_copter_mode(int(CopterMode.LOITER))

    def set_mode(self, mode: FlightMode) -> None:
        """A FlightMode asked for: the Copter mode that does it (HOLD is BRAKE)."""
        try:
            number = copter_mode(mode)
        except ValueError:
            raise CommandRejected(f"{mode.value}: no such ArduCopter mode") from None
        self.set_copter_mode(int(number))

    def start_offboard(self) -> None:
        self.set_copter_mode(int(CopterMode.GUIDED))

    def stop_offboard(self) -> None:
        self.set_copter_mode(int(CopterMode.BRAKE))

    def start_mission(self) -> None:
        self.mission_start()

    def precision_land(self) -> None:
        self.land()  # LAND with PLND_ENABLED lands on the target


class GuidedCommands:
    """GUIDED's commands on the simulated ArduCopter: NAV_TAKEOFF, DO_REPOSITION, CONDITION_YAW
    and the companion's targets."""

    stack: FlightStack
    guided: GuidedInput
    copter_mode: CopterMode
    _now: float
    armed: bool
    landed: bool

    def set_copter_mode(self, number: int) -> None:
        raise NotImplementedError

    def takeoff(self, altitude_m: float | None = None) -> None:
        """NAV_TAKEOFF to ``altitude_m`` above home (ArduCopter's rules)."""
        spec = MODES[self.copter_mode]
        if not self.armed:
            raise CommandRejected("takeoff: not armed")
        if not spec.user_takeoff:
            raise CommandRejected(f"takeoff: not in a mode that takes off ({spec.name})")
        if not self.landed:
            raise CommandRejected("takeoff: already flying")
        if altitude_m is None or not altitude_m > 0:
            raise CommandRejected("takeoff: altitude must be above the current altitude")
        self.stack.takeoff(altitude_m)

    def reposition(self, target_ned_m: Sequence[float], yaw_rad: float = NAN,
                   speed_m_s: float = NAN) -> None:
        """DO_REPOSITION (in GUIDED, or switching to it): a position target (NaN: keep that
        axis; speed and yaw are ignored, as ArduCopter)."""
        if not self.armed or self.landed:
            raise CommandRejected("reposition needs the vehicle in the air")
        if self.copter_mode is not CopterMode.GUIDED:
            self.set_copter_mode(int(CopterMode.GUIDED))
        est = self.stack.require_estimate()
        target = np.where(np.isfinite(np.asarray(target_ned_m, float)),
                          np.asarray(target_ned_m, float), est.position_ned_m)
        self.push_setpoint(Setpoint(position_ned_m=target), self._now)

    def condition_yaw(self, yaw_rad: float, relative: bool, direction: float = 1.0) -> None:
        """CONDITION_YAW in GUIDED: face ``yaw_rad`` (relative: that far, + clockwise)."""
        if self.copter_mode is CopterMode.GUIDED:
            here = yaw_from_quat(self.stack.require_estimate().q_ned_frd)
            self.guided.face(here + math.copysign(yaw_rad, direction) if relative else yaw_rad)

    def push_setpoint(self, sp: Setpoint, now_s: float) -> None:
        """A GUIDED target (ignored in the other modes, as ArduCopter)."""
        self._now = now_s
        if self.copter_mode is not CopterMode.GUIDED:
            return
        s = self.stack
        s.push_setpoint(sp, now_s)
        if s.commander.user_mode is FlightMode.TAKEOFF and not self.landed:
            s.start_offboard()  # a target in the air ends the takeoff



def rtl_return_altitude_m(params: Parameters, si: SiLimits, position_ned_m: np.ndarray,
                          home_ned_m: np.ndarray) -> float:
    """ArduCopter's RTL return height above home (``mode_rtl.cpp compute_return_target``):
    max(RTL_ALT, current + RTL_CLIMB_MIN), within RTL_CONE_SLOPE × the distance home but at
    least 2.5 m above the current height, never below the current height."""
    height = float(home_ned_m[2] - position_ned_m[2])
    target = max(height + params["RTL_CLIMB_MIN"] / 100.0, si.rtl_altitude_m)
    slope = float(params["RTL_CONE_SLOPE"])
    if slope > 0:
        distance = float(np.hypot(*(position_ned_m[:2] - home_ned_m[:2])))
        target = min(target, max(distance * slope, height + RTL_ABS_MIN_CLIMB_M))
    return max(target, height)


class Circle:
    """CIRCLE: an orbit about a centre ``radius_m`` ahead of where the mode began, the
    vehicle facing the centre; :meth:`setpoint` moves on by the rate (rad/s, + clockwise)."""

    def __init__(self, position_ned_m: np.ndarray, yaw_rad: float, radius_m: float) -> None:
        self.centre = np.asarray(position_ned_m, float) + radius_m * np.array(
            [math.cos(yaw_rad), math.sin(yaw_rad), 0.0])
        self.radius_m = radius_m
        self.angle_rad = yaw_rad + math.pi  # the vehicle's bearing from the centre

    def setpoint(self, dt_s: float, rate_rad_s: float) -> Setpoint:
        self.angle_rad += rate_rad_s * dt_s
        c, s = math.cos(self.angle_rad), math.sin(self.angle_rad)
        return Setpoint(position_ned_m=self.centre + self.radius_m * np.array([c, s, 0.0]),
                        velocity_m_s=self.radius_m * rate_rad_s * np.array([-s, c, 0.0]),
                        yaw_rad=math.atan2(-s, -c))


def arducopter_text(text: str, breach: str | None) -> str | None:
    """A cascade event in ArduCopter's words; None for those ArduCopter does not announce
    (mode changes, arming — the firmware says "Arming motors" itself —, takeoff's end)."""
    if text.startswith(("mode ", "armed", "takeoff", "RTL: ", "landed", "mission", "land ",
                        "loiter")) or text.endswith(": cleared") or "user took over" in text:
        return None  # the cascade's own narration: ArduCopter says none of it
    if text.startswith("failsafe: offboard setpoints lost"):
        return None  # (ArduCopter has no target-loss failsafe: the cascade's, unseen)
    if "disarm" in text:
        return "Disarming motors"
    if text.startswith("failsafe: data link lost"):
        return "GCS Failsafe"
    if text.startswith("failsafe: geofence"):
        return "Max Alt fence breached" if breach is not None and "above home" in breach \
            else "Circle fence breached"
    if text.startswith("failsafe: battery"):
        return "Battery Failsafe"
    if text.startswith("failsafe: local position lost"):
        return "EKF Failsafe"
    return text


def starts_with_takeoff(commands: list[int]) -> bool:
    """The mission's first navigation command is a takeoff (``starts_with_takeoff_cmd``)."""
    for command in commands:
        if command < 80 or command in (84, 85, 92, 93, 94, 95):  # MAV_CMD_NAV_*
            return command == 22
    return False
