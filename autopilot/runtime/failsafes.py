"""The failsafes: telemetry silence and loss, the geofence, the battery reserve, a step that
cannot go on (its perception raised, the event loop stalled in flight), the console's
emergency stop. Each hands over the same way, :meth:`Failsafes.take_over`: the console's keys
let go, no setpoint streamed on, the failsafe logged and told to the hooks, and the mission's
fallback (hold, land; or the way home) flying."""

from __future__ import annotations

import contextlib
import enum
from collections.abc import Awaitable, Callable

from autopilot.behaviors.base import BehaviorInputs, RequestKind, VehicleRequest
from autopilot.behaviors.flight import ReturnHome, SafeStop
from autopilot.control.battery import BatteryReserve, ReserveSettings
from autopilot.control.geofence import FenceSettings, Geofence
from autopilot.mission import MissionOutput
from autopilot.runtime.flight import LAND_RETRY_S, LANDING_PHASES, Flight
from autopilot.runtime.recorder import MissionRecorder
from autopilot.runtime.telemetry import TelemetryIntake
from drivers.base import FlightMode, LandedState, VehicleError


class Verdict(enum.Enum):
    """What the control tick does after the failsafes looked (with the output to apply)."""

    GO_ON = "go on"  # nothing to act on: the mission (or the console) flies this tick
    NEXT = "next"  # acted (the output, if any, applied): the next tick
    END = "end"  # the run ends (the emergency stop)


def make_fence(flight: Flight) -> Geofence:
    """The autopilot's own geofence (``failsafe.geofence``), checked on every setpoint."""
    gf = flight.config.failsafe.geofence
    return Geofence(FenceSettings(
        gf.max_distance_m or None, gf.max_altitude_m or None,
        tuple(tuple(p) for p in gf.polygon_m) if gf.polygon_m else None, gf.lookahead_s))


class Failsafes:
    def __init__(self, flight: Flight, recorder: MissionRecorder, telemetry: TelemetryIntake,
                 fence: Geofence) -> None:
        self.flight = flight
        self.recorder = recorder
        self.telemetry = telemetry
        self.fence = fence
        # wired by the runtime once the rooms exist: the console lets go of the vehicle, the
        # setpoint stream stops, a vehicle request is performed, the step resumes
        self.hand_back: Callable[[], None] = lambda: None
        self.drop_setpoints: Callable[[], None] = lambda: None
        self.perform: Callable[[VehicleRequest], Awaitable[None]] | None = None
        self.resume: Callable[[], None] = lambda: None
        b = flight.config.failsafe.battery
        #: the battery reserve for the way home (autopilot/control/battery.py)
        self.battery_reserve = BatteryReserve(ReserveSettings(
            b.reserve_fraction, b.speed_m_s, b.descent_m_s, b.margin,
            return_altitude_m=b.return_altitude_m, climb_m_s=b.climb_m_s,
            fast_descent_m_s=b.fast_descent_m_s, slow_below_m=b.slow_below_m,
            land_here=b.action == "land"))
        self._battery_handled = False
        self.fence_breach: str | None = None
        self._fence_handled = False
        #: a failure the step cannot fly on: it fails into the fallback at the next tick
        self._step_failure: str | None = None
        #: the console's emergency stop (confirmed): the motors stop at the next tick
        self.emergency: str | None = None
        self.stale = False  # telemetry lost (a silence past the grace): no more setpoints
        #: a silence under the grace: when it began (None: telemetry flowing), and whether
        #: the vehicle was told to hold (the step then asks for OFFBOARD again on resuming)
        self.silent_since: float | None = None
        self._silence_held = False
        #: when to ask again for a landing the vehicle refused (:meth:`land_where_it_is`)
        self._land_retry_s: float | None = None
        self.last_tick_s = float("-inf")  # (the clock) the newest control tick

    # -- what other rooms report -----------------------------------------------------------

    def quiet(self) -> bool:
        """Telemetry silent or lost: no setpoint is streamed on an old pose."""
        return self.stale or self.silent_since is not None

    def fail_step(self, why: str) -> None:
        """The running step cannot go on (its perception raised, …): it fails into the
        fallback at the next control tick (the first reason wins)."""
        executor = self.flight.executor
        if self._step_failure is None and executor is not None and not executor.in_fallback:
            self._step_failure = why

    def fence_breached(self, why: str) -> None:
        """A setpoint the geofence refused: the control loop hands over at once."""
        if self.fence_breach is None:
            self.fence_breach = why
            self.flight.nudge()

    def on_loop_stall(self, seconds: float) -> None:
        """The event loop was stalled for ``runtime.loop_stall_s`` or more (the one threshold:
        autopilot/watchdog.py). In real time, flying, the step does not resume blindly on what
        it saw before the stall (its setpoints lapsed meanwhile, and PX4's offboard-loss
        failsafe may have acted): it fails into the fallback."""
        f = self.flight
        if f.clock.lockstep:  # simulated time waited for the loop: the flight lost nothing
            return
        now = f.clock.now()
        text = f"event loop stalled for {seconds:.2f} s"
        # the vehicle's own time since the last control tick: a real-time simulator slowed
        # with a starved CPU (drivers/clock.py, PacedClock) may have waited for the loop, and
        # then no setpoint lapsed on its clock; a real vehicle never waits
        waited = now - self.last_tick_s
        if waited < f.config.runtime.setpoint_expiry_s:
            self.recorder.event(now, "runtime", f"{text} (the vehicle's clock {waited:.2f} s: "
                                "its world waited)")
            return
        self.recorder.event(now, "runtime", text)
        if f.in_air:
            self.fail_step(text)

    # -- the hand-over ---------------------------------------------------------------------

    async def take_over(self, reason: str, inputs: BehaviorInputs, *, name: str = "failsafe",
                        fail: bool = False, hold_first: bool = False,
                        fallback=None) -> MissionOutput:
        """Take control back from the step (and the console): the keys let go, no setpoint
        streamed on, ``reason`` logged and told to the hooks (``mission``/``name``), the
        vehicle told to hold first if ``hold_first``, and the mission's fallback (or
        ``fallback``) flying — as a failure of the step (``fail``) or an abort."""
        self.hand_back()
        self.drop_setpoints()
        self.recorder.failsafe(name, reason)
        if hold_first:
            await self._hold()
        executor = self.flight.executor
        if fail:
            return executor.fail(reason, inputs)
        return executor.abort(reason, inputs, fallback)

    async def check_link(self, inputs: BehaviorInputs) -> tuple[Verdict, MissionOutput | None]:
        """Telemetry: silent (hold, wait up to the grace), lost (the fallback), back."""
        f = self.flight
        grace = f.config.runtime.telemetry_grace_s
        if self.stale:
            pass  # lost for good: the fallback flies on the vehicle's own modes
        elif (silence := self.telemetry.silence()) is not None:
            if self.silent_since is None:
                await self._hold_silent(silence, inputs)
            if self.emergency is not None:  # the motors stop, whatever we know
                await self.emergency_stop(inputs)
                return Verdict.END, None
            if silence <= grace and not f.stop_requested.is_set():
                return Verdict.NEXT, None  # holding: the step waits (up to the grace)
            # flying blind for longer than the grace (or asked to stop meanwhile): the
            # mission's fallback brings the vehicle down, as for a lost link
            self.stale = True
            why = f"telemetry lost: nothing new received for {silence:.2f} s (grace {grace:g} s)"
            if f.executor.in_fallback:
                # already coming down or home: a vehicle flying its own return or landing
                # goes on with it (a hold would stop it); otherwise it lands where it is
                self.recorder.failsafe("failsafe", why)
                if inputs.state.mode not in ReturnHome.RETURN_MODES:
                    await self.land_where_it_is()
                return Verdict.NEXT, None
            return Verdict.NEXT, await self.take_over(why, inputs)
        elif self.silent_since is not None:
            gap = self.telemetry.last_heard_s - self.silent_since
            self.silent_since = None
            # back within the grace: the step resumes from where the vehicle is (OFFBOARD
            # asked again if it was told to hold)
            if self._silence_held:
                self.resume()
            self.recorder.event(f.clock.now(), "runtime",
                                f"telemetry back after {gap:.2f} s: {f.cursor.step or 'mission'} "
                                "resumes")
        if self._land_retry_s is not None and f.clock.now() >= self._land_retry_s:
            await self.land_where_it_is()
        return Verdict.GO_ON, None

    async def check_flight(self, inputs: BehaviorInputs
                           ) -> tuple[Verdict, MissionOutput | None]:
        """The geofence, the battery reserve, a failed step, the emergency stop."""
        f = self.flight
        if self.fence_breach is None and self.fence.settings.active and inputs.state.in_air:
            where = self.fence.check_state(inputs.state, f.vehicle.home_ned_m)
            if where is not None:
                self.fence_breach = f"the vehicle is {where}"
        if self.fence_breach is not None and not self._fence_handled:
            # geofence: no setpoint went out; the mission's fallback (hold, land) takes over
            self._fence_handled = True
            why = f"geofence: {self.fence_breach}"
            if f.executor.in_fallback:
                # the fallback is already taking the vehicle down or home (the vehicle's
                # return climbing above the ceiling, a landing blown outside): it lands
                # where it is now; a hold would stop the fallback, not end the flight
                self.hand_back()
                self.drop_setpoints()
                self.recorder.failsafe("geofence", why)
                self.recorder.event(f.clock.now(), "failsafe",
                                    "geofence during the fallback: landing where it is")
                await self.land_where_it_is()
                return Verdict.NEXT, None
            return Verdict.NEXT, await self.take_over(why, inputs, name="geofence",
                                                      hold_first=True)
        if (call := self._battery_call(inputs)) is not None:
            reason, fallback = call
            return Verdict.NEXT, await self.take_over(reason, inputs, name="battery_reserve",
                                                      fallback=fallback)
        if self._step_failure is not None:
            why, self._step_failure = self._step_failure, None
            return Verdict.NEXT, await self.take_over(why, inputs, fail=True)
        if self.emergency is not None:
            await self.emergency_stop(inputs)
            return Verdict.END, None
        return Verdict.GO_ON, None

    def _battery_call(self, inputs: BehaviorInputs):
        """The battery reserve (autopilot/control/battery.py): time to go home? (the reason,
        and the fallback: the way home or a landing where it is)"""
        f = self.flight
        if self._battery_handled or not self.battery_reserve.active or \
                f.executor is None or f.executor.in_fallback:
            return None
        s = inputs.state
        if s.mode in (FlightMode.LAND, FlightMode.PRECLAND) or \
                s.landed_state is LandedState.LANDING or f.cursor.phase in LANDING_PHASES:
            return None  # already on the cheapest way down: a landing is not interrupted
        call = self.battery_reserve.check(
            inputs.now_s, s.battery.remaining_fraction, s.position_ned_m,
            f.vehicle.home_ned_m, s.in_air)
        if call is None:
            return None
        self._battery_handled = True
        go_home = call.go_home and f.config.failsafe.battery.action == "return"
        why = f"battery reserve: {call.reason}; " + ("returning home" if go_home else "landing")
        return why, ReturnHome if go_home else SafeStop

    # -- the vehicle's own safe states -----------------------------------------------------

    async def _hold(self) -> None:
        f = self.flight
        with contextlib.suppress(VehicleError, TimeoutError):
            await f.clock.wait_for(f.vehicle.hold(), 2.0)

    async def _hold_silent(self, silence: float, inputs: BehaviorInputs) -> None:
        """A silence began: no motion setpoint goes out on an old pose. A vehicle flown by our
        setpoints is told to HOLD (as PX4 holds on offboard loss); one flying its own mode
        (takeoff, land, return) goes on with it."""
        f = self.flight
        now = f.clock.now()
        self.silent_since = now - silence  # (the last news)
        self.drop_setpoints()
        self.hand_back()  # the step (or the fallback) flies again after, whatever the keys
        self._silence_held = inputs.state.mode is FlightMode.OFFBOARD
        grace = f.config.runtime.telemetry_grace_s
        what = "holding" if self._silence_held else f"the vehicle's {inputs.state.mode.value} " \
            "goes on"
        self.recorder.event(now, "runtime", f"telemetry silent: nothing new for {silence:.2f} s;"
                            f" setpoints stopped, {what} (up to {grace:g} s)")
        if self._silence_held:
            with contextlib.suppress(VehicleError, TimeoutError):
                await f.clock.wait_for(self.perform(VehicleRequest(RequestKind.HOLD)), 2.0)

    async def land_where_it_is(self) -> None:
        """Land now (a failsafe during the fallback); a land the vehicle refuses or does not
        answer is asked for again every ``LAND_RETRY_S`` until it takes it."""
        f = self.flight
        try:
            await f.clock.wait_for(f.vehicle.land(), 2.0)
        except (VehicleError, TimeoutError) as exc:
            self.recorder.event(f.clock.now(), "runtime", f"land refused ({exc}): asking again")
            self._land_retry_s = f.clock.now() + LAND_RETRY_S
        else:
            self._land_retry_s = None

    async def emergency_stop(self, inputs: BehaviorInputs) -> None:
        """R, confirmed: the motors stop now — flight termination in the air (a forced
        disarm, PX4's kill), a disarm on the ground — and the run ends."""
        f = self.flight
        in_air = inputs.state.in_air
        reason = self.emergency or "emergency stop"
        self.drop_setpoints()
        self.hand_back()
        self.recorder.console(inputs.now_s, "emergency", f"{reason}: "
                              + ("flight termination (motors off in the air)" if in_air
                                 else "disarm on the ground"))
        try:
            await f.clock.wait_for(self.perform(VehicleRequest(RequestKind.DISARM,
                                                               force=in_air)), 2.0)
        except (VehicleError, TimeoutError) as exc:
            self.recorder.event(f.clock.now(), "runtime", f"emergency disarm failed: {exc}")
            await self.last_resort()
        f.status, f.reason = "aborted", reason

    async def last_resort(self) -> None:
        """The orderly stop failed or the link broke: one bounded attempt to land."""
        f = self.flight
        with contextlib.suppress(Exception):
            await f.clock.wait_for(f.vehicle.land(), 2.0)
