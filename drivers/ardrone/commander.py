"""What the AR.Drone driver's AT loop sends each tick (:class:`Commander`: REF, PCMD, the
offboard timeout, the climb after the drone's own takeoff). Synchronous."""

from __future__ import annotations

import math

from drivers.ardrone.at import AtCommands
from drivers.ardrone.navdata import ControlState
from drivers.ardrone.outer_loop import OuterLoop
from drivers.ardrone.telemetry import (
    AIRBORNE,
    HOVER,
    DroneLimits,
    clamp_fraction,
    encode_pcmd,
)
from drivers.base import (
    FlightMode,
    ProgressiveCommand,
    Setpoint,
    VehicleState,
)

NAN = math.nan

# --------------------------------------------------------------------------------------------
# What the AT loop sends
# --------------------------------------------------------------------------------------------


class Commander:
    """The driver's intent, and the REF and PCMD that carry it each AT tick.

    REF's takeoff bit is what was asked last (take off / land); ``None`` until the first
    navdata says whether the drone flies, so that connecting to a flying drone does not land
    it. An emergency is REF's emergency bit raised for :data:`EMERGENCY_TICKS` ticks (the
    drone acts on its rising edge; a few, as datagrams get lost). PCMD: in offboard, the
    outer loop on the newest setpoint (a setpoint that carries a progressive command, a seed
    rule's ``cmd_vel``, flies that command as it is) while it is younger than
    ``offboard_timeout_s`` —
    then the hover, and offboard is left (PX4's offboard loss: HOLD); during the climb after
    a takeoff to a given altitude, the outer loop to that height; otherwise the hover.
    """

    EMERGENCY_TICKS = 5
    #: the climb after the drone's own takeoff is over within this of its height, and given
    #: up (the hover) if it has not got there this long after it began
    CLIMB_TOLERANCE_M = 0.1
    CLIMB_TIMEOUT_S = 30.0

    def __init__(self, commands: AtCommands, loop: OuterLoop,
                 offboard_timeout_s: float = 0.5) -> None:
        self.at = commands
        self.loop = loop
        self.offboard_timeout_s = offboard_timeout_s
        #: REF's takeoff bit (None: not known yet whether the drone flies)
        self.takeoff_bit: bool | None = None
        self.offboard = False
        #: the height (m) to climb to after the drone's own takeoff (None: none)
        self.climb_to_m: float | None = None
        self._emergency_ticks = 0
        self._climb_deadline_s: float | None = None
        self._airborne = False
        self._setpoint: Setpoint | None = None
        self._setpoint_s = -math.inf
        #: the PCMD sent last (None before the first)
        self.last_pcmd: ProgressiveCommand | None = None
        #: times the offboard timeout ended offboard
        self.offboard_timeouts = 0

    # -- intents -----------------------------------------------------------------------------

    def on_state(self, state: VehicleState, control_state: ControlState | int | None) -> None:
        """Telemetry came: the first tells whether the drone already flies; a drone back on
        the ground (landed, cut, out of battery) has its takeoff bit cleared, or REF would
        take it off again."""
        airborne = control_state in AIRBORNE
        if self.takeoff_bit is None:
            self.takeoff_bit = airborne and state.armed
        elif self._airborne and not airborne and control_state is ControlState.LANDED:
            self.takeoff_bit = False
            self.offboard = False
            self.climb_to_m = None
        self._airborne = airborne

    def takeoff(self, altitude_m: float | None, limits: DroneLimits) -> None:
        self.takeoff_bit = True
        self.offboard = False
        self.climb_to_m = None if altitude_m is None else \
            min(float(altitude_m), limits.altitude_max_m - 0.1)
        self._climb_deadline_s = None

    def land(self) -> None:
        self.takeoff_bit = False
        self.offboard = False
        self.climb_to_m = None

    def hold(self) -> None:
        self.offboard = False
        self.climb_to_m = None

    def emergency(self) -> None:
        """Raise REF's emergency bit (cut the motors in the air; reset the emergency state on
        the ground); the takeoff bit is cleared."""
        self._emergency_ticks = self.EMERGENCY_TICKS
        self.takeoff_bit = False
        self.offboard = False
        self.climb_to_m = None

    def setpoint(self, setpoint: Setpoint, now_s: float) -> None:
        self._setpoint, self._setpoint_s = setpoint, now_s

    def setpoint_fresh(self, now_s: float) -> bool:
        return self._setpoint is not None and now_s - self._setpoint_s <= self.offboard_timeout_s

    def start_offboard(self, now_s: float) -> str | None:
        """Enter offboard; the reason it cannot (None: entered)."""
        if not self.setpoint_fresh(now_s):
            return f"no setpoint within the offboard timeout ({self.offboard_timeout_s:g} s)"
        if not self.offboard:
            self.loop.reset()
        self.offboard = True
        self.climb_to_m = None
        return None

    def stop_offboard(self) -> None:
        self.offboard = False

    # -- the tick ----------------------------------------------------------------------------

    def pcmd(self, now_s: float, state: VehicleState | None,
             control_state: ControlState | int | None) -> ProgressiveCommand:
        """The PCMD for this tick."""
        if state is None or control_state not in (ControlState.HOVERING, ControlState.FLYING):
            if control_state is not ControlState.TAKING_OFF:
                self.loop.reset()
            return HOVER
        if self.offboard:
            if self.setpoint_fresh(now_s):
                assert self._setpoint is not None
                command = self._setpoint.progressive
                if command is not None:  # (a progressive command: flown as it is)
                    self.loop.reset()
                    return command if command.hover else ProgressiveCommand(
                        clamp_fraction(command.roll), clamp_fraction(command.pitch),
                        clamp_fraction(command.gaz),
                        clamp_fraction(command.yaw), hover=False)
                return self.loop.update(self._setpoint, state, now_s)
            self.offboard = False  # the offboard timeout: the hover, in HOLD
            self.offboard_timeouts += 1
            self.loop.reset()
            return HOVER
        if self.climb_to_m is not None:
            if self._climb_deadline_s is None:
                self._climb_deadline_s = now_s + self.CLIMB_TIMEOUT_S
            if abs(state.altitude_m - self.climb_to_m) <= self.CLIMB_TOLERANCE_M or \
                    now_s > self._climb_deadline_s:
                self.climb_to_m = None
                self.loop.reset()
                return HOVER
            climb = Setpoint(position_ned_m=(NAN, NAN, -self.climb_to_m),
                             velocity_m_s=(0.0, 0.0, NAN))
            return self.loop.update(climb, state, now_s)
        self.loop.reset()
        return HOVER

    def tick(self, now_s: float, state: VehicleState | None,
             control_state: ControlState | int | None) -> list[bytes]:
        """The AT commands of one tick: REF (once the drone's state is known) and PCMD."""
        out = []
        if self.takeoff_bit is not None:
            emergency = self._emergency_ticks > 0
            self._emergency_ticks = max(0, self._emergency_ticks - 1)
            out.append(self.at.ref(takeoff=self.takeoff_bit and not emergency,
                                   emergency=emergency))
        pcmd = self.pcmd(now_s, state, control_state)
        self.last_pcmd = pcmd
        out.append(encode_pcmd(pcmd, self.at))
        return out

    def mode(self, state: VehicleState, control_state: ControlState | int | None) -> FlightMode:
        """The mode the driver reports: the drone's, unless the driver is flying it
        (OFFBOARD while its setpoints fly it, TAKEOFF until the climb is over) or hovering it
        (HOLD: a FLYING drone is ours, between a hover and the next PCMD)."""
        airborne = control_state in (ControlState.HOVERING, ControlState.FLYING)
        if airborne and self.offboard:
            return FlightMode.OFFBOARD
        if self.climb_to_m is not None and (airborne or control_state is ControlState.TAKING_OFF):
            return FlightMode.TAKEOFF
        if control_state is ControlState.FLYING:
            return FlightMode.HOLD
        return state.mode
