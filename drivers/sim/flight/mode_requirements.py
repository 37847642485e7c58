"""Whether a flight mode can run now, as PX4's mode requirements decide it (commander's
``ModeUtil``): OFFBOARD needs a setpoint younger than COM_OF_LOSS_T that the vehicle can fly
(a valid local position); the position modes need a valid local position; MISSION a mission
the navigator accepts; RETURN a home position."""

from __future__ import annotations

from drivers.base import FlightMode, Health

#: the modes that fly on the local position
POSITION_MODES = (FlightMode.HOLD, FlightMode.MISSION, FlightMode.RETURN, FlightMode.TAKEOFF,
                  FlightMode.PRECLAND)


def mode_problem(mode: FlightMode, *, health: Health, setpoint_age_s: float,
                 offboard_loss_s: float, navigator, landed: bool,
                 arming: bool = False) -> str | None:
    """Why ``mode`` cannot run now, None if it can (``arming``: asked as the vehicle arms)."""
    if mode is FlightMode.OFFBOARD:
        if setpoint_age_s > offboard_loss_s:
            return f"no offboard setpoint within COM_OF_LOSS_T ({offboard_loss_s:g} s)"
        if not health.local_position_ok:  # what position and velocity setpoints need
            return "offboard setpoint needs a valid local position"
    if mode in POSITION_MODES and not health.local_position_ok:
        return "no valid local position"
    if mode is FlightMode.MISSION:
        problem = navigator.mission_problem(landed=landed or arming)
        if problem is not None:
            return f"mission rejected: {problem}"
    if mode is FlightMode.RETURN and navigator.home is None and not arming:
        return "no home position"
    return None
