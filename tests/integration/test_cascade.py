"""The whole control cascade in closed loop: step responses and saturation in flight."""

import math

import numpy as np

from autopilot.bench.sitl import step_response
from drivers.base import Setpoint
from drivers.geometry import euler_from_quat

from .simtools import Offboard, record_truth, run, simulator, take_off


def _step(sim_config, step_ned, observe_s):
    async def main():
        async with simulator(sim_config) as drv:
            await take_off(drv, 2.0)
            offboard = Offboard(drv, rate_hz=50.0)
            here = await offboard.start_holding_here()
            await drv.clock.sleep(1.0)
            target = here + np.array(step_ned)
            offboard.setpoint = Setpoint.position(*target, yaw_rad=drv.latest_state.yaw_rad)
            samples = await record_truth(drv, observe_s)
            await offboard.aclose()
            return here, target, samples

    return run(main())


def test_position_step_2m(sim_config):
    here, _target, samples = _step(sim_config, (2.0, 0.0, 0.0), 6.0)
    t = np.array([s.time_s for s in samples])
    north = np.array([s.vehicle.position_ned_m[0] for s in samples]) - here[0]
    resp = step_response(t, north, 2.0, 0.05)
    assert resp.overshoot_pct <= 10.0
    assert resp.settle_time_s <= 3.0
    assert 0.3 < resp.rise_time_s < 1.5
    # the other axes barely move (rotor drag on the tilted airframe lifts it a little)
    offset = np.array([s.vehicle.position_ned_m for s in samples]) - here
    assert np.max(np.abs(offset[:, 1])) < 0.05
    assert np.max(np.abs(offset[:, 2])) < 0.2


def test_altitude_step(sim_config):
    here, _target, samples = _step(sim_config, (0.0, 0.0, -1.0), 6.0)
    t = np.array([s.time_s for s in samples])
    up = here[2] - np.array([s.vehicle.position_ned_m[2] for s in samples])
    resp = step_response(t, up, 1.0, 0.05)
    assert resp.overshoot_pct <= 10.0
    assert resp.settle_time_s <= 3.5


def test_long_step_saturates_speed_and_tilt_and_still_settles(sim_config):
    pos = sim_config.flight_stack.position
    here, _target, samples = _step(sim_config, (30.0, 0.0, 0.0), 12.0)
    speeds = [math.hypot(*s.vehicle.velocity_ned_m_s[:2]) for s in samples]
    tilts = [math.degrees(math.acos(math.cos(r) * math.cos(p)))
             for r, p, _ in (euler_from_quat(s.vehicle.attitude_q) for s in samples)]
    assert max(speeds) <= pos.xy_vel_max_m_s * 1.05
    assert max(tilts) <= pos.tilt_max_deg + 3.0  # attitude tracking overshoots a little
    north = np.array([s.vehicle.position_ned_m[0] for s in samples]) - here[0]
    assert (north.max() - 30.0) / 30.0 * 100 < 10.0  # anti-windup keeps the overshoot small
    assert abs(north[-1] - 30.0) < 0.1
