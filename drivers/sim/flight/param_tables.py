"""Each simulated firmware's parameter table — what a ground station finds on the vehicle and
``sim.params`` may set — by firmware name (``sim.firmware``); a test checks every firmware
has one. The AR.Drone has no parameter protocol: the PX4-like cascade's table stands in."""

from __future__ import annotations

from dataclasses import dataclass

from drivers.sim.flight.arducopter_params import SPECS as ARDUCOPTER_SPECS
from drivers.sim.flight.params import SPECS as PX4_SPECS
from drivers.sim.flight.params import ParamSpec


@dataclass(frozen=True, slots=True)
class ParamTable:
    specs: dict[str, ParamSpec]
    #: the firmware, as messages name it
    title: str
    #: where the table is written
    source: str


_PX4 = ParamTable(PX4_SPECS, "PX4", "drivers/sim/flight/params.py")
PARAM_TABLES: dict[str, ParamTable] = {
    "px4": _PX4,
    "ardrone": _PX4,
    "ardupilot": ParamTable(ARDUCOPTER_SPECS, "ArduCopter",
                            "drivers/sim/flight/arducopter_params.py"),
}
