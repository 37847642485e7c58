"""The simulated vehicle's driver as its parts make it: PX4's extras (Px4Services) win over the
Vehicle interface's refusing defaults, and a connect that fails leaves no thread behind."""

import asyncio

import pytest

from drivers.base import Vehicle
from drivers.sim.driver import SimDriver
from drivers.sim.px4_services import Px4Services


def test_px4_services_come_before_the_vehicle_defaults():
    mro = SimDriver.__mro__
    assert mro.index(Px4Services) < mro.index(Vehicle)
    for name in ("return_to_launch", "home_ned_m", "global_origin", "set_mode",
                 "upload_mission", "start_mission", "set_param"):
        assert getattr(SimDriver, name) is getattr(Px4Services, name), name
    # and the driver's own hooks are the ones the services call
    for name in ("_require_sim", "_command", "_call"):
        assert getattr(SimDriver, name) is not getattr(Px4Services, name), name


def test_a_failed_real_time_connect_closes_the_simulator_s_thread(sim_config, monkeypatch):
    import drivers.sim.runner as runner

    class Broken(Exception):
        pass

    def broken(*args, **kwargs):
        raise Broken("no simulator")

    monkeypatch.setattr(runner, "Simulator", broken)
    driver = SimDriver(sim_config, lockstep=False)
    with pytest.raises(Broken):
        asyncio.run(driver.connect())
    assert driver.runner.executor is None  # shut down, not left running
