"""The firmwares the simulated vehicle can run (``sim.firmware``), registered here and nowhere
else: each makes the autopilot the simulator ticks (``observe``, ``update_outer``,
``update_inner``, ``events``, ``nav_events``, the reported ``armed`` / ``mode`` /
``landed_state`` / ``failsafe``) and answers the commands its protocol's face sends through
:meth:`~drivers.sim.simulator.Simulator.command`.

==========  =================================================================================
firmware    what it is
==========  =================================================================================
px4         the PX4-like flight stack (:mod:`drivers.sim.flight.flight_stack`), over MAVLink
ardupilot   ArduCopter (:mod:`drivers.sim.flight.arducopter`) on the same cascade, over
            MAVLink as ArduCopter SITL; its parameters are ArduPilot's
ardrone     a Parrot AR.Drone 2.0's firmware (:mod:`drivers.sim.flight.ardrone`), over its
            SDK protocol (AT commands, navdata, PaVE video)
==========  =================================================================================

Each also names its parameters (:data:`FIRMWARE_PARAMS`): the PX4-like cascade's, which the
simulator's own models read (battery, auto-disarm, …), and the ones a ground station sees —
the same object for PX4, ArduPilot's table kept in step with the cascade's for ArduCopter.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from drivers.geo import GlobalOrigin
from drivers.sim.config import SimConfig
from drivers.sim.flight.flight_stack import Airframe
from drivers.sim.flight.params import Parameters, config_defaults


def _px4_params(config: SimConfig) -> tuple[Parameters, Parameters]:
    params = Parameters(config_defaults(config))
    return params, params


def _ardupilot_params(config: SimConfig) -> tuple[Parameters, Parameters]:
    from drivers.sim.flight.arducopter_params import ARDUCOPTER_PARAMS

    # the simulated pack's capacity, as its user sets BATT_CAPACITY
    ground = {"BATT_CAPACITY": round(config.battery.capacity_mah), **config.params}
    return (Parameters(config_defaults(config, overrides=False)),
            Parameters(ground, specs=ARDUCOPTER_PARAMS))


def _px4(config: SimConfig, airframe: Airframe, params: Parameters, ground: Parameters,
         origin: GlobalOrigin):
    from drivers.sim.flight.flight_stack import FlightStack

    return FlightStack(config.flight_stack, airframe, config.flight_stack.motor_idle_fraction,
                       params, origin)


def _ardupilot(config: SimConfig, airframe: Airframe, params: Parameters, ground: Parameters,
               origin: GlobalOrigin):
    from drivers.sim.flight.arducopter import ArduCopterFirmware

    return ArduCopterFirmware(config.flight_stack, airframe,
                              config.flight_stack.motor_idle_fraction, ground, params, origin,
                              battery_resistance_ohm=config.battery.internal_resistance_ohm)


def _ardrone(config: SimConfig, airframe: Airframe, params: Parameters, ground: Parameters,
             origin: GlobalOrigin):
    from drivers.sim.flight.ardrone import ArdroneFirmware

    return ArdroneFirmware(config.flight_stack, airframe,
                           config.flight_stack.motor_idle_fraction)


#: firmware name → its factory (config, airframe, the cascade's parameters, the ground
#: station's, global origin)
FIRMWARES: dict[str, Callable[[SimConfig, Airframe, Parameters, Parameters, GlobalOrigin],
                              Any]] = {
    "px4": _px4,
    "ardupilot": _ardupilot,
    "ardrone": _ardrone,
}

#: firmware name → its parameters: (the cascade's, the ground station's)
FIRMWARE_PARAMS: dict[str, Callable[[SimConfig], tuple[Parameters, Parameters]]] = {
    "px4": _px4_params,
    "ardupilot": _ardupilot_params,
    "ardrone": _px4_params,
}


#: firmware name → the vehicle it makes, as tables and reports name it
FIRMWARE_TITLES = {"px4": "PX4-like vehicle", "ardupilot": "ArduCopter vehicle",
                   "ardrone": "AR.Drone 2.0"}


def make_params(config: SimConfig) -> tuple[Parameters, Parameters]:
    """The parameters of ``config.firmware``: (the cascade's, the ground station's)."""
    return FIRMWARE_PARAMS[config.firmware](config)


def make_firmware(config: SimConfig, airframe: Airframe, params: Parameters,
                  ground: Parameters, origin: GlobalOrigin):
    """The autopilot ``config.firmware`` names, for this airframe."""
    return FIRMWARES[config.firmware](config, airframe, params, ground, origin)
