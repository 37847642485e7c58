"""Small vehicle-level helpers built on the vehicle interface (any driver, any clock)."""

from __future__ import annotations

import contextlib
from collections.abc import Callable

from drivers.base import Setpoint, Vehicle, VehicleState


async def wait_for_state(vehicle: Vehicle, predicate: Callable[[VehicleState], bool],
                         timeout_s: float, what: str = "condition") -> VehicleState:
    """Wait (on the vehicle's clock) for a telemetry sample satisfying ``predicate``.

    Raises ``TimeoutError`` naming ``what`` if none arrives within ``timeout_s``.
    """

    async def first_match() -> VehicleState:
        async with contextlib.aclosing(vehicle.telemetry()) as samples:
            async for state in samples:
                if predicate(state):
                    return state
        raise TimeoutError(f"telemetry ended while waiting for {what}")

    try:
        return await vehicle.clock.wait_for(first_match(), timeout_s)
    except TimeoutError:
        raise TimeoutError(f"timed out after {timeout_s:g} s waiting for {what}") from None


async def stream_setpoints(vehicle: Vehicle, next_setpoint: Callable[[], Setpoint | None],
                           rate_hz: float) -> None:
    """Send ``next_setpoint()`` at ``rate_hz`` until cancelled; nothing is sent for a tick
    where it returns None (so the vehicle's offboard-loss failsafe sees a real stop)."""
    period = 1.0 / rate_hz
    clock = vehicle.clock
    next_time = clock.now()
    while True:
        setpoint = next_setpoint()
        if setpoint is not None:
            await vehicle.send_setpoint(setpoint)
        next_time += period
        await clock.sleep_until(next_time)
