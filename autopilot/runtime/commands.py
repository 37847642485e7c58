"""Talking to the vehicle: the setpoint stream (an intent with an expiry, re-sent at
``setpoint_rate_hz`` until it lapses, each passed through the target kinds' setpoint guards —
the keep-out zones — for the newest telemetry, then checked against the geofence) and the
vehicle commands the steps, the failsafes and the console ask for."""

from __future__ import annotations

import math
from collections.abc import Callable

from autopilot.behaviors.base import RequestKind, VehicleRequest
from autopilot.control.geofence import Geofence
from autopilot.flightlog import records as ch
from autopilot.hooks import Event
from autopilot.runtime.flight import Flight, Intent
from autopilot.runtime.recorder import MissionRecorder
from drivers.base import CommandDenied, FlightMode, LandingTarget, Setpoint, VehicleState
from drivers.capabilities import PrecisionLanding

#: a setpoint as the guards let it go: (setpoint, the newest telemetry, step, phase) → setpoint
Guard = Callable[[Setpoint, VehicleState | None, str, str], Setpoint]


class SetpointStream:
    """A setpoint is an *intent with an expiry*: the streaming task re-sends it only until
    ``setpoint_expiry_s`` after the control step made it. If the control task stalls,
    streaming stops, and the vehicle's own offboard-loss failsafe takes over."""

    def __init__(self, flight: Flight, fence: Geofence, on_breach: Callable[[str], None],
                 quiet: Callable[[], bool], guard: Guard | None = None) -> None:
        self.flight = flight
        self.fence = fence
        #: every setpoint, each time it is sent, as the guards let it go (the watch's)
        self.guard: Guard = guard or (lambda setpoint, state, step, phase: setpoint)
        self.on_breach = on_breach  # a setpoint the geofence refused: the failsafes act
        self.quiet = quiet  # telemetry is silent or lost: nothing is re-sent
        self.intent: Intent | None = None
        self.last_send_s = -math.inf
        self.intent_record: dict | None = None  # the newest setpoint, as the log keeps it

    def drop(self) -> None:
        """No setpoint goes out any more (until the next one is made)."""
        self.intent = None

    async def put(self, setpoint: Setpoint, source_frame_s: float | None, step: str,
                  phase: str) -> None:
        """A new setpoint: sent now, and streamed until it expires."""
        now = self.flight.clock.now()
        self.intent = Intent(setpoint, now, now + self.flight.config.runtime.setpoint_expiry_s,
                             source_frame_s, step, phase)
        await self.send(self.intent)

    def keep_alive(self, for_s: float) -> None:
        """The intent (the entry setpoint) lives ``for_s`` longer than its expiry from now."""
        if self.intent is not None:
            self.intent.expires_s = self.flight.clock.now() + for_s + \
                self.flight.config.runtime.setpoint_expiry_s

    async def run(self) -> None:
        f = self.flight
        period = 1.0 / f.config.runtime.setpoint_rate_hz
        while True:
            await f.clock.sleep(period)
            intent = self.intent
            now = f.clock.now()
            if intent is not None and now < intent.expires_s and not self.quiet() and \
                    now - self.last_send_s >= 0.9 * period:
                await self.send(intent)

    async def send(self, intent: Intent) -> None:
        f = self.flight
        state = f.state
        # guarded at every send, not once: the vehicle moves, and zones are found, meanwhile
        setpoint = self.guard(intent.setpoint, state, intent.step, intent.phase)
        if state is not None and self.fence.settings.active:
            why = self.fence.check(setpoint, state, f.vehicle.home_ned_m)
            if why is not None:  # nothing goes out; the control loop hands over to the fallback
                self.on_breach(why)
                self.intent = None
                return
        await f.vehicle.send_setpoint(setpoint)
        now = f.clock.now()
        self.last_send_s = now
        f.stats.setpoints_sent += 1
        if not intent.sent:
            intent.sent = True
            sp = setpoint  # (as it went out)
            latency = None if intent.source_frame_time_s is None \
                else (now - intent.source_frame_time_s) * 1e3
            record = {
                "time_s": now, "source_frame_time_s": intent.source_frame_time_s,
                "latency_ms": latency, "frame": sp.frame.value,
                "position_ned_m": sp.position_ned_m, "velocity_m_s": sp.velocity_m_s,
                "acceleration_m_s2": sp.acceleration_m_s2, "yaw_rad": sp.yaw_rad,
                "yaw_rate_rad_s": sp.yaw_rate_rad_s,
                "expires_s": intent.expires_s, "step": intent.step, "phase": intent.phase}
            self.intent_record = record
            f.log.write(ch.SETPOINTS, now, record)


class VehicleCommands:
    """A request (arm, take off, OFFBOARD, hold, land, …) carried out on the vehicle, told to
    the hooks before and after (``before_cmd_land``, …); a refusal raises VehicleError."""

    def __init__(self, flight: Flight, recorder: MissionRecorder,
                 setpoints: SetpointStream) -> None:
        self.flight = flight
        self.recorder = recorder
        self.setpoints = setpoints

    async def perform(self, request: VehicleRequest) -> None:
        if request.kind is RequestKind.LANDING_TARGET:
            await self._command(request)
            return
        hub, clock = self.flight.events, self.flight.clock
        name = request.kind.value
        data = {"altitude_m": request.altitude_m} if request.altitude_m is not None else {}
        if request.kind is RequestKind.DISARM:
            data["force"] = request.force
        hub.emit(Event("command", name, clock.now(), f"command {name}", "before", data))
        try:
            await self._command(request)
        except Exception as exc:
            hub.emit(Event("command", name, clock.now(), f"command {name} failed: {exc}",
                           "after", {**data, "result": f"{type(exc).__name__}: {exc}"}))
            raise
        hub.emit(Event("command", name, clock.now(), f"command {name} done", "after",
                       {**data, "result": "ok"}))

    async def _command(self, request: VehicleRequest) -> None:
        f = self.flight
        v = f.vehicle
        if request.kind in (RequestKind.LANDING_TARGET, RequestKind.PRECISION_LAND) and \
                not isinstance(v, PrecisionLanding):
            raise CommandDenied(request.kind.value, "this vehicle has no precision landing")
        if request.kind is RequestKind.LANDING_TARGET:  # a stream, as setpoints: not an event
            await v.send_landing_target(LandingTarget(request.time_s, request.position_ned_m))
            return
        if request.kind is RequestKind.START_OFFBOARD and f.state is not None and \
                f.state.mode is FlightMode.OFFBOARD:
            return  # already there (one offboard step after another): nothing to ask
        self.recorder.event(f.clock.now(), "request", f"request {request.kind.value}")
        if request.kind is RequestKind.ARM:
            await v.arm()
        elif request.kind is RequestKind.TAKEOFF:
            await v.takeoff(request.altitude_m)
        elif request.kind is RequestKind.START_OFFBOARD:
            warmup = f.config.runtime.offboard_warmup_s
            self.setpoints.keep_alive(warmup)  # the entry setpoint lives while warming up
            await f.clock.sleep(warmup)
            await v.start_offboard()
        elif request.kind is RequestKind.HOLD:
            await v.hold()
        elif request.kind is RequestKind.LAND:
            await v.land()
        elif request.kind is RequestKind.RETURN:
            await v.return_to_launch()
        elif request.kind is RequestKind.PRECISION_LAND:
            await v.precision_land()
        elif request.kind is RequestKind.DISARM:
            await v.disarm(force=request.force)
