"""The simulated vehicle's autopilot as a Parrot AR.Drone 2.0's firmware (``sim.firmware:
ardrone``), in place of the PX4-like :class:`~drivers.sim.flight.flight_stack.FlightStack`.

What the AR.Drone's firmware does, as its SDK 2.0 developer guide describes it (chapters 2, 6
and 8) and its users measured it:

* No position control and no GPS: the drone is flown by *progressive commands* (``AT*PCMD``
  with its progressive bit): roll and pitch as fractions of ``control:euler_angle_max``
  (tilt angles, not velocities), the vertical speed as a fraction of ``control:control_vz_max``
  and the yaw rate as a fraction of ``control:control_yaw``. With the progressive bit clear
  the drone *hovers*: it holds its horizontal velocity at zero with its optical-flow camera
  (so it drifts as its velocity estimate does: over poor texture, more) and its height with
  the sonar.
* ``AT*REF``: its takeoff bit starts an automatic takeoff to about 1 m, then the drone hovers;
  clearing it lands (a steady descent, the motors stopped at touchdown). Its emergency bit cuts
  the motors wherever the drone is, and (once landed in emergency) resets the emergency state.
* Height never above ``control:altitude_max`` (a climb is stopped there).
* The communication watchdog: a drone that receives no command for 2 s considers the Wi-Fi
  link lost and hovers until commands come again (the guide, 6.1); with the battery too low to
  fly (``general:vbat_min``) it lands.

The flight states are the demo navdata's (:class:`~drivers.ardrone.navdata.ControlState`). The
commands are :meth:`ArdroneFirmware.ref`, :meth:`~ArdroneFirmware.pcmd`,
:meth:`~ArdroneFirmware.ftrim` and :meth:`~ArdroneFirmware.alive` (the AT interpreter of the
simulated drone decodes the datagrams and calls them through the simulator's ``command``);
the limits live in its :class:`ArdroneLimits`, which ``AT*CONFIG`` changes.

The control: the velocity hold (hover) and the progressive tilt make an attitude setpoint; the
height loop (P on height, PI on vertical speed) the collective thrust; PX4's attitude and rate
loops (:class:`~drivers.sim.flight.rate_loop.RateLoop`) fly it on the airframe. The reported
mode for the simulator's own records (truth, events) maps the states onto PX4's names.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from drivers.ardrone.navdata import ControlState
from drivers.base import Battery, FlightMode, Health, LandedState, ProgressiveCommand
from drivers.geometry import quat_from_euler, yaw_from_quat
from drivers.sim.config import FlightStackConfig
from drivers.sim.flight.commander import CommandRejected
from drivers.sim.flight.land_detector import LandDetector
from drivers.sim.flight.position_control import (
    GRAVITY_M_S2,
    AttitudeSetpoint,
    body_z_to_attitude,
)
from drivers.sim.flight.rate_loop import RateLoop

__all__ = ["ArdroneFirmware", "ArdroneLimits", "CommandRejected", "FirmwareStatus", "Progressive"]

#: the guide's 6.1: no command for this long and the drone takes the link as lost (hovers)
COM_LOST_S = 2.0
#: ... and it sets the navdata's watchdog bit after this long without a command
COM_WATCHDOG_S = 0.05
#: the height an automatic takeoff climbs to (the drone's ~1 m)
TAKEOFF_HEIGHT_M = 1.0
#: the takeoff's and the landing's vertical speeds
TAKEOFF_SPEED_M_S = 0.75
LAND_SPEED_M_S = 0.5
#: the navdata's low-battery bit below this charge (general:vbat_min, 9 V of a 3-cell pack)
VBAT_LOW_FRACTION = 0.1
#: the height below which a landing cuts the motors once it stops descending (the sonar's
#: reading at rest on the ground is its mount height, ~0.05 m under the hull)
_TOUCHDOWN_HEIGHT_M = 0.25

_MODE = {ControlState.LANDED: FlightMode.HOLD, ControlState.TAKING_OFF: FlightMode.TAKEOFF,
         ControlState.HOVERING: FlightMode.HOLD, ControlState.FLYING: FlightMode.OFFBOARD,
         ControlState.LANDING: FlightMode.LAND, ControlState.DEFAULT: FlightMode.UNKNOWN}


@dataclass
class ArdroneLimits:
    """The configuration keys the firmware's control obeys (``control:*``), in SI units;
    the AR.Drone 2.0's defaults (a drone's own configuration dump: euler_angle_max
    2.0943999e-01 rad, control_vz_max 700 mm/s, control_yaw 1.7453293 rad/s, altitude_max
    3000 mm)."""

    euler_angle_max_rad: float = 0.20943999
    control_vz_max_m_s: float = 0.7
    control_yaw_rad_s: float = 1.7453293
    altitude_max_m: float = 3.0
    altitude_min_m: float = 0.05


@dataclass(frozen=True, slots=True)
class FirmwareStatus:
    """What the navdata says of the firmware: its flight state and its flags."""

    control_state: ControlState
    motors_on: bool
    emergency: bool
    com_watchdog: bool
    com_lost: bool
    battery_low: bool = False


#: one ``AT*PCMD``, as the firmware takes it
Progressive = ProgressiveCommand


class ArdroneFirmware:
    """The AR.Drone's flight behaviour, with the tick interface the simulator drives
    (:meth:`observe`, :meth:`update_outer`, :meth:`update_inner`) as the PX4-like stack's."""

    #: gains of the velocity hold (tilt per m/s of error; integral per s) and the height loop
    VEL_P = 0.35
    VEL_I = 0.03
    HEIGHT_P = 1.5
    VZ_P = 4.0
    VZ_I = 2.0

    def __init__(self, cfg: FlightStackConfig, airframe, motor_idle_fraction: float,
                 limits: ArdroneLimits | None = None) -> None:
        self.cfg = cfg
        self.airframe = airframe
        self.limits = limits or ArdroneLimits()
        self.hover_thrust = cfg.position.hover_thrust or airframe.hover_thrust
        self.rate_loop = RateLoop(cfg, airframe, motor_idle_fraction)
        self.land_detector = LandDetector(cfg.land_detector, cfg.position.thrust_min,
                                          self.hover_thrust)
        #: (time_s, text) of state changes, drained by the simulator
        self.events: deque[tuple[float, str]] = deque(maxlen=256)
        #: the navigator's events (missions, photos): the AR.Drone has none
        self.nav_events: deque = deque()
        self.state = ControlState.LANDED
        self.emergency = False
        self.geofence_breach: str | None = None
        self.command_s = -math.inf  # when the last command arrived
        self._progressive = Progressive()
        self._now = 0.0
        self._est = None
        self._health = Health(local_position_ok=False)
        self._battery_fraction = 1.0
        self._height_m = math.nan
        self._height_hold_m = TAKEOFF_HEIGHT_M
        self._yaw_sp = 0.0
        self._vel_int = [0.0, 0.0]
        self._vz_int = 0.0
        self._thrust = 0.0
        self._motors_on = False
        self.att_sp = AttitudeSetpoint((1.0, 0.0, 0.0, 0.0), 0.0, 0.0)

    # ------------------------------------------------------------------------------------
    # Reported state
    # ------------------------------------------------------------------------------------

    @property
    def armed(self) -> bool:
        """The motors turning."""
        return self._motors_on

    @property
    def mode(self) -> FlightMode:
        return _MODE.get(self.state, FlightMode.UNKNOWN)

    @property
    def failsafe(self) -> str | None:
        return "communication lost" if self.com_lost else None

    @property
    def com_lost(self) -> bool:
        return self.flying and self._now - self.command_s > COM_LOST_S

    @property
    def com_watchdog(self) -> bool:
        return self._now - self.command_s > COM_WATCHDOG_S

    @property
    def flying(self) -> bool:
        return self.state in (ControlState.TAKING_OFF, ControlState.HOVERING,
                              ControlState.FLYING, ControlState.LANDING)

    def status(self) -> FirmwareStatus:
        """What the navdata says of the firmware now."""
        return FirmwareStatus(self.state, self._motors_on, self.emergency, self.com_watchdog,
                              self.com_lost, self._battery_fraction <= VBAT_LOW_FRACTION)

    @property
    def landed_state(self) -> LandedState:
        return {ControlState.TAKING_OFF: LandedState.TAKING_OFF,
                ControlState.LANDING: LandedState.LANDING,
                ControlState.HOVERING: LandedState.IN_AIR,
                ControlState.FLYING: LandedState.IN_AIR}.get(self.state, LandedState.ON_GROUND)

    # ------------------------------------------------------------------------------------
    # Commands (what the AT interpreter calls)
    # ------------------------------------------------------------------------------------

    def alive(self) -> None:
        """A command that only feeds the communication watchdog (``COMWDG``, ``CONFIG``,
        ``CTRL``...)."""
        self.command_s = self._now

    def ref(self, takeoff: bool, emergency: bool = False) -> None:
        """``AT*REF``: take off (``takeoff``) or land; ``emergency`` cuts the motors (or, on
        the ground in emergency, resets the emergency state)."""
        self.command_s = self._now
        if emergency:
            if self.flying or self._motors_on:
                self._cut("emergency: motors cut")
            elif self.emergency:
                self.emergency = False
                self._event("emergency reset")
            return
        if self.emergency:
            return  # the emergency state holds until it is reset
        if takeoff and self.state is ControlState.LANDED:
            if self._battery_fraction <= 0.0:
                raise CommandRejected("battery empty")
            self._motors_on = True
            self.state = ControlState.TAKING_OFF
            self._height_hold_m = min(TAKEOFF_HEIGHT_M, self.limits.altitude_max_m)
            self._yaw_sp = self._yaw()
            self._reset()
            self._event("taking off")
        elif not takeoff and self.state in (ControlState.TAKING_OFF, ControlState.HOVERING,
                                            ControlState.FLYING):
            self.state = ControlState.LANDING
            self._event("landing")

    def pcmd(self, command: Progressive) -> None:
        """``AT*PCMD``: a progressive command, or the hover."""
        self.command_s = self._now
        self._progressive = command

    def ftrim(self) -> None:
        """``AT*FTRIM``: flat trim, on the ground only."""
        self.command_s = self._now
        if self.flying:
            raise CommandRejected("flat trim on the ground only")

    # ------------------------------------------------------------------------------------
    # The loop
    # ------------------------------------------------------------------------------------

    def observe(self, now_s: float, est, health: Health) -> None:
        self._now = now_s
        self._est = est
        self._health = health

    def update_outer(self, now_s: float, dt_s: float, est, health: Health,
                     height_agl_m: float, battery: Battery,
                     surface_velocity_ned_m_s: np.ndarray | None = None) -> None:
        self.observe(now_s, est, health)
        self._battery_fraction = battery.remaining_fraction
        # the drone's height: its fused estimate (sonar, IMU), not a raw echo, which can be
        # an outlier or absent (below the sonar's 0.2 m, over soft surfaces)
        self._height_m = -float(est.position_ned_m[2])
        yaw = self._yaw()
        relative = est.velocity_ned_m_s if surface_velocity_ned_m_s is None else \
            est.velocity_ned_m_s - surface_velocity_ned_m_s
        if not self._motors_on:
            self.att_sp = AttitudeSetpoint(body_z_to_attitude((0.0, 0.0, 1.0), yaw), 0.0, 0.0)
            self.land_detector.update(now_s, False, relative, est.rates_frd_rad_s, 0.0, False,
                                      height_agl_m)
            return
        if self.flying and battery.remaining_fraction <= 0.0 and \
                self.state is not ControlState.LANDING:
            self.state = ControlState.LANDING
            self._event("battery too low: landing")
        self._outer(dt_s, est, yaw)
        self.land_detector.update(now_s, True, relative, est.rates_frd_rad_s, self._thrust,
                                  self.state is ControlState.LANDING, height_agl_m)

    def _outer(self, dt: float, est, yaw: float) -> None:
        lim = self.limits
        height = self._height_m
        pcmd = self._progressive
        state = self.state
        if state in (ControlState.HOVERING, ControlState.FLYING):
            progressive = not pcmd.hover and not self.com_lost
            self.state = ControlState.FLYING if progressive else ControlState.HOVERING
        else:
            progressive = False
        # vertical: a climb rate (down positive in NED)
        if state is ControlState.TAKING_OFF:
            vz_sp = -TAKEOFF_SPEED_M_S
            if height >= self._height_hold_m - 0.05:
                self.state = ControlState.HOVERING
                self._height_hold_m = height
                self._event("hovering")
        elif state is ControlState.LANDING:
            vz_sp = LAND_SPEED_M_S
        elif progressive and abs(pcmd.gaz) > 1e-3:
            vz_sp = -pcmd.gaz * lim.control_vz_max_m_s
            self._height_hold_m = height
        else:
            vz_sp = -self.HEIGHT_P * (self._height_hold_m - height)
            vz_sp = max(-lim.control_vz_max_m_s, min(lim.control_vz_max_m_s, vz_sp))
        if vz_sp < 0.0:  # a climb slows to a stop at altitude_max
            vz_sp = max(vz_sp, -self.HEIGHT_P * (lim.altitude_max_m - height))
            self._height_hold_m = min(self._height_hold_m, lim.altitude_max_m)
        # horizontal: tilt angles (roll right, pitch nose up, in the heading frame)
        if progressive:
            roll = pcmd.roll * lim.euler_angle_max_rad
            pitch = pcmd.pitch * lim.euler_angle_max_rad
            self._yaw_sp = yaw
            yaw_rate = pcmd.yaw * lim.control_yaw_rad_s
            self._vel_int = [0.0, 0.0]
        else:
            roll, pitch = self._velocity_hold(dt, est, yaw)
            yaw_rate = 0.0
        # the collective thrust from the vertical speed error (PI), tilt-compensated
        vz = float(est.velocity_ned_m_s[2])
        err = vz - vz_sp
        airborne = state is not ControlState.TAKING_OFF or height > 0.2
        if airborne:
            self._vz_int = max(-0.3, min(0.3, self._vz_int + self.VZ_I * err * dt / GRAVITY_M_S2))
        accel = self.VZ_P * err / GRAVITY_M_S2 + self._vz_int
        tilt = max(math.cos(roll) * math.cos(pitch), 0.5)
        thrust = self.hover_thrust * (1.0 + accel) / tilt
        if state is ControlState.LANDING and self.land_detector.ground_contact:
            thrust = 0.0
        self._thrust = max(0.0, min(self.cfg.position.thrust_max, thrust))
        if state is ControlState.LANDING and self.land_detector.landed:
            self._motors_on = False
            self.state = ControlState.LANDED
            self._event("landed")
        q = quat_from_euler(roll, pitch, self._yaw_sp if yaw_rate == 0.0 else yaw)
        self.att_sp = AttitudeSetpoint(tuple(q.tolist()), self._thrust, yaw_rate)

    def _velocity_hold(self, dt: float, est, yaw: float) -> tuple[float, float]:
        """The hover: tilt that brings the (estimated) horizontal velocity to zero."""
        c, s = math.cos(yaw), math.sin(yaw)
        vn, ve = float(est.velocity_ned_m_s[0]), float(est.velocity_ned_m_s[1])
        forward, right = c * vn + s * ve, -s * vn + c * ve
        ints = self._vel_int
        ints[0] = max(-0.04, min(0.04, ints[0] + self.VEL_I * forward * dt))
        ints[1] = max(-0.04, min(0.04, ints[1] + self.VEL_I * right * dt))
        limit = self.limits.euler_angle_max_rad
        pitch = max(-limit, min(limit, self.VEL_P * forward + ints[0]))  # nose up brakes
        roll = max(-limit, min(limit, -(self.VEL_P * right + ints[1])))
        return roll, pitch

    def update_inner(self, dt: float, q: list[float], gyro: list[float]) -> list[float]:
        return self.rate_loop.update(dt, q, gyro, self.att_sp, armed=self._motors_on,
                                     on_ground=self._motors_on and self._thrust <= 0.0)

    # ------------------------------------------------------------------------------------
    # Internals
    # ------------------------------------------------------------------------------------

    def _yaw(self) -> float:
        return yaw_from_quat(self._est.q_ned_frd) if self._est is not None else 0.0

    def _reset(self) -> None:
        self._vel_int = [0.0, 0.0]
        self._vz_int = 0.0
        self.rate_loop.reset()

    def _cut(self, why: str) -> None:
        self._motors_on = False
        self.emergency = True
        self.state = ControlState.LANDED
        self._thrust = 0.0
        self._event(why)

    def _event(self, text: str) -> None:
        self.events.append((self._now, text))

