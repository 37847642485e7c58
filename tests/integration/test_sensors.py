"""What the autopilot receives: telemetry rates, latency and noise, rangefinder, battery, wind."""

import asyncio
import contextlib
import math

import numpy as np
import pytest

from drivers.geometry import euler_from_quat

from ..conftest import sim_with
from .simtools import GROUND_Z, Offboard, record_truth, run, simulator, take_off


def test_telemetry_rate_latency_and_stamps(sim_config):
    tel = sim_config.telemetry

    async def main():
        async with simulator(sim_config) as drv:
            received = []
            async with contextlib.aclosing(drv.telemetry(buffer=16)) as stream:
                async for state in stream:
                    received.append((drv.clock.now(), state))
                    if state.time_s >= 2.0:
                        break
            return received

    received = run(main())
    stamps = np.array([s.time_s for _, s in received])
    assert np.all(np.diff(stamps) > 0)
    assert np.diff(stamps).mean() == pytest.approx(1.0 / tel.rate_hz, rel=0.01)
    latency = np.array([arrived - s.time_s for arrived, s in received])
    step = 1.0 / sim_config.physics_rate_hz
    assert latency.min() >= tel.latency_s - 1e-9
    assert latency.max() <= tel.latency_s + tel.latency_jitter_s + step + 1e-9


def test_estimate_is_close_to_truth_but_not_truth(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            await take_off(drv, 2.0)
            errors = []
            async with contextlib.aclosing(drv.ground_truth(buffer=64)) as truth:
                async for sample in truth:
                    state = drv.latest_state
                    if abs(state.time_s - sample.time_s) < 1e-9:
                        errors.append(state.position_ned_m - sample.vehicle.position_ned_m)
                    if len(errors) >= 100:
                        break
            return np.array(errors)

    errors = run(main())
    sigma = sim_config.estimator.chosen.horizontal_error_m
    assert np.all(np.abs(errors) < 5 * sigma)
    assert np.any(np.abs(errors) > 1e-4)


def test_rangefinder_reads_height(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            await take_off(drv, 3.0)
            truth = (await record_truth(drv, 0.5))[-1]
            return drv.latest_state.distance_to_ground_m, -truth.vehicle.position_ned_m[2]

    reading, height = run(main())
    assert reading == pytest.approx(height, abs=0.03)


def test_rangefinder_out_of_range_is_nan(sim_config):
    cfg = sim_with(sim_config, **{"rangefinder.max_m": 1.0})

    async def main():
        async with simulator(cfg) as drv:
            on_ground = drv.latest_state
            await take_off(drv, 2.0)
            return on_ground, drv.latest_state

    on_ground, flying = run(main())
    assert on_ground.distance_to_ground_m == pytest.approx(-GROUND_Z, abs=0.02)
    assert math.isnan(flying.distance_to_ground_m)


def test_battery_drains_with_thrust(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            idle = drv.latest_state.battery
            await take_off(drv, 2.0)
            hover = drv.latest_state.battery
            await drv.clock.sleep(30.0)
            return idle, hover, drv.latest_state.battery

    idle, hover, later = run(main())
    assert idle.current_a < 1.0 < hover.current_a
    assert 5.0 < later.current_a < 30.0  # ~160 W hovering on a 4S pack
    assert later.voltage_v < idle.voltage_v
    drained = hover.remaining_fraction - later.remaining_fraction
    expected = later.current_a * 30.0 / (sim_config.battery.capacity_mah * 3.6)
    assert drained == pytest.approx(expected, rel=0.1)


def test_steady_wind_is_resisted(sim_config):
    cfg = sim_with(sim_config, **{"wind.steady_ned_m_s": [0.0, 5.0, 0.0]})

    async def main():
        async with simulator(cfg) as drv:
            await take_off(drv, 2.0)
            offboard = Offboard(drv)
            here = await offboard.start_holding_here()
            await drv.clock.sleep(10.0)
            samples = await record_truth(drv, 5.0)
            await offboard.aclose()
            return here, samples

    here, samples = run(main())
    err = np.array([s.vehicle.position_ned_m - here for s in samples])
    assert np.max(np.linalg.norm(err[:, :2], axis=1)) < 0.15
    # the wind blows towards the east: the vehicle leans west (rolls left) to hold position
    rolls = [euler_from_quat(s.vehicle.attitude_q)[0] for s in samples]
    assert np.mean(rolls) < -math.radians(1.0)


def test_gusts_move_the_vehicle_and_are_seeded(sim_config):
    cfg = sim_with(sim_config, **{"wind.gust_mps": 2.0})

    async def wind_series(seed):
        async with simulator(cfg, seed=seed) as drv:
            samples = await record_truth(drv, 3.0)
            return np.array([s.wind_ned_m_s for s in samples])

    a, b, c = (asyncio.run(wind_series(s)) for s in (1, 1, 2))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert 0.5 < np.std(a[:, :2]) < 4.0
