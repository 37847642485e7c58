"""The vehicle's telemetry, taken in: the newest state for every room, the pose history each
pipeline places its detections with, the flown track for the console's map, and when the
vehicle last said something new (the telemetry-silence failsafe judges on that)."""

from __future__ import annotations

import contextlib
import math
from collections import deque
from collections.abc import Callable

from autopilot.flightlog import records as ch
from autopilot.runtime.flight import Flight
from autopilot.runtime.recorder import MissionRecorder
from drivers.base import VehicleState


class TelemetryIntake:
    def __init__(self, flight: Flight, recorder: MissionRecorder,
                 consumers: list[Callable[[VehicleState], None]]) -> None:
        self.flight = flight
        self.recorder = recorder
        #: told of every state as it arrives (photo geotags, the pipelines' pose history)
        self.consumers = consumers
        #: when (our clock) a newer position / attitude than any before was last received
        self.position_heard_s = -math.inf
        self.attitude_heard_s = -math.inf
        #: the flown track (north, east), every 10 cm or more: the console's map
        self.track_ne_m: deque[tuple[float, float]] = deque(maxlen=4000)

    async def run(self) -> None:
        f = self.flight
        async with contextlib.aclosing(f.vehicle.telemetry(buffer=64)) as samples:
            async for state in samples:
                previous, f.state = f.state, state
                now = f.clock.now()
                if previous is None or state.time_s > previous.time_s:
                    self.position_heard_s = now
                if previous is None or state.attitude_time_s > previous.attitude_time_s:
                    self.attitude_heard_s = now
                self.recorder.state_events(previous, state)
                ne = (round(float(state.position_ned_m[0]), 2),
                      round(float(state.position_ned_m[1]), 2))
                last = self.track_ne_m[-1] if self.track_ne_m else None
                if last is None or math.hypot(ne[0] - last[0], ne[1] - last[1]) >= 0.1:
                    self.track_ne_m.append(ne)
                for consumer in self.consumers:
                    consumer(state)
                record = ch.vehicle_state_record(state)
                record["received_s"] = f.clock.now()
                f.log.write(ch.VEHICLE_STATE, state.time_s, record)

    @property
    def last_heard_s(self) -> float:
        """When the vehicle last said something new (the older of position and attitude)."""
        return min(self.position_heard_s, self.attitude_heard_s)

    def silence(self) -> float | None:
        """How long the vehicle has said nothing new (no newer position or attitude received),
        on our clock; None while that is under ``runtime.telemetry_silence_s``. Judged on
        arrival, not on the capture stamps' age: a vehicle whose clock lags ours (a starved
        simulator) or a link with latency is not silent while its samples keep coming."""
        f = self.flight
        if f.state is None:
            return None
        silence = f.clock.now() - self.last_heard_s
        return silence if silence > f.config.runtime.telemetry_silence_s else None

    async def first_state(self) -> VehicleState:
        f = self.flight
        while f.state is None:
            await f.clock.sleep(0.01)
        return f.state
