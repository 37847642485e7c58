"""The firmwares the simulated vehicle can run (``sim.firmware``), registered here and nowhere
else: each makes the autopilot the simulator ticks (``observe``, ``update_outer``,
``update_inner``, ``events``, ``nav_events``, the reported ``armed`` / ``mode`` /
``landed_state`` / ``failsafe``) and answers the commands its protocol's face sends through
:meth:`~drivers.sim.simulator.Simulator.command`.

==========  =================================================================================
firmware    what it is
==========  =================================================================================
px4         the PX4-like flight stack (:mod:`drivers.sim.flight.flight_stack`), over MAVLink
ardrone     a Parrot AR.Drone 2.0's firmware (:mod:`drivers.sim.flight.ardrone`), over its
            SDK protocol (AT commands, navdata, PaVE video)
==========  =================================================================================
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from drivers.geo import GlobalOrigin
from drivers.sim.config import SimConfig
from drivers.sim.flight.flight_stack import Airframe
from drivers.sim.flight.params import Parameters


def _px4(config: SimConfig, airframe: Airframe, params: Parameters, origin: GlobalOrigin):
    from drivers.sim.flight.flight_stack import FlightStack

    return FlightStack(config.flight_stack, airframe, config.flight_stack.motor_idle_fraction,
                       params, origin)


def _ardrone(config: SimConfig, airframe: Airframe, params: Parameters, origin: GlobalOrigin):
    from drivers.sim.flight.ardrone import ArdroneFirmware

    return ArdroneFirmware(config.flight_stack, airframe,
                           config.flight_stack.motor_idle_fraction)


#: firmware name → its factory (config, airframe, PX4 parameters, global origin)
FIRMWARES: dict[str, Callable[[SimConfig, Airframe, Parameters, GlobalOrigin], Any]] = {
    "px4": _px4,
    "ardrone": _ardrone,
}


#: firmware name → the vehicle it makes, as tables and reports name it
FIRMWARE_TITLES = {"px4": "PX4-like vehicle", "ardrone": "AR.Drone 2.0"}


def make_firmware(config: SimConfig, airframe: Airframe, params: Parameters,
                  origin: GlobalOrigin):
    """The autopilot ``config.firmware`` names, for this airframe."""
    return FIRMWARES[config.firmware](config, airframe, params, origin)
