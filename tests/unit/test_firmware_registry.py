"""Every simulated firmware is served everywhere it must be: its flight code
(drivers/sim/firmwares.py), the vehicle flown in process (autopilot.run.SIM_VEHICLES) and
``autopilot sim``'s server for it (autopilot.cli.sim.FACES), under the names the configuration
accepts (drivers.sim.config.FIRMWARE_NAMES)."""

import typing

from autopilot.cli.sim import FACES
from autopilot.run import SIM_VEHICLES
from drivers.sim.config import FIRMWARE_NAMES, SimConfig
from drivers.sim.firmwares import FIRMWARE_TITLES, FIRMWARES


def test_each_firmware_is_registered_in_every_place_that_serves_it():
    names = set(FIRMWARE_NAMES)
    assert set(FIRMWARES) == names
    assert set(SIM_VEHICLES) == names
    assert set(FACES) == names
    assert set(FIRMWARE_TITLES) == names
    assert set(typing.get_args(SimConfig.model_fields["firmware"].annotation)) == names
