"""PX4 mode semantics of the simulated vehicle: arming checks, takeoff, land, offboard rules
and failsafes. All on the lockstep clock."""

import math

import numpy as np
import pytest

from autopilot.flight_ops import wait_for_state
from drivers.base import CommandDenied, FlightMode, LandedState, Setpoint

from .simtools import GROUND_Z, Offboard, armable, record_truth, run, simulator, take_off


def test_arming_refused_while_unhealthy(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            # the estimator has not converged at boot
            with pytest.raises(CommandDenied, match="preflight checks failed: local_position"):
                await drv.arm()
            await armable(drv)
            await drv.inject_failure("gyro")
            await wait_for_state(drv, lambda s: not s.health.armable, 1.0, "unhealthy")
            with pytest.raises(CommandDenied, match="gyro"):
                await drv.arm()
            await drv.inject_failure("gyro", failed=False)
            await armable(drv)
            await drv.arm()
            state = await wait_for_state(drv, lambda s: s.armed, 1.0, "armed")
            assert state.landed_state is LandedState.ON_GROUND

    run(main())


def test_takeoff_refused_when_disarmed(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            await armable(drv)
            with pytest.raises(CommandDenied, match="not armed"):
                await drv.takeoff(2.0)

    run(main())


def test_takeoff_hold_land_touchdown_and_disarm(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            await take_off(drv, 2.0)
            truth = (await record_truth(drv, 2.0))[-1]
            assert truth.vehicle.position_ned_m[2] == pytest.approx(GROUND_Z - 2.0, abs=0.1)
            assert drv.latest_state.landed_state is LandedState.IN_AIR

            seen = []
            await drv.land()
            await wait_for_state(drv, lambda s: seen.append(s.landed_state) or not s.armed,
                                 20.0, "landing and disarm")
            assert LandedState.LANDING in seen
            assert seen[-1] is LandedState.ON_GROUND
            truth = (await record_truth(drv, 0.2))[-1]
            assert truth.vehicle.position_ned_m[2] == pytest.approx(GROUND_Z, abs=0.01)
            assert np.all(truth.rotor_thrust_n < 0.01)  # motors stopped

    run(main())


def test_preflight_auto_disarm(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            await armable(drv)
            await drv.arm()
            armed_at = drv.clock.now()
            await wait_for_state(drv, lambda s: not s.armed, 15.0, "auto-disarm")
            assert drv.clock.now() - armed_at == pytest.approx(
                sim_config.flight_stack.commander.disarm_preflight_s, abs=0.1)

    run(main())


def test_disarm_in_air_refused_unless_forced(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            await take_off(drv, 3.0)
            with pytest.raises(CommandDenied, match="in the air"):
                await drv.disarm()
            await drv.disarm(force=True)
            samples = await record_truth(drv, 0.5)
            assert samples[-1].vehicle.velocity_ned_m_s[2] > 2.0  # falling
            assert not drv.latest_state.armed

    run(main())


def test_offboard_switch_in_needs_one_recent_setpoint_as_px4(sim_config):
    """PX4's offboardCheck: the signal is there when the newest setpoint is younger than
    COM_OF_LOSS_T; a stream is not needed to switch in (MAVSDK's examples send one)."""
    async def main():
        async with simulator(sim_config) as drv:
            await take_off(drv, 2.0)
            with pytest.raises(CommandDenied, match="no offboard setpoint within COM_OF_LOSS_T"):
                await drv.start_offboard()
            here = drv.latest_state.position_ned_m
            await drv.send_setpoint(Setpoint.position(*here))
            await drv.clock.sleep(drv.simulator.params["COM_OF_LOSS_T"] + 0.1)
            with pytest.raises(CommandDenied, match="COM_OF_LOSS_T"):  # too old by now
                await drv.start_offboard()
            await drv.send_setpoint(Setpoint.position(*here))
            await drv.start_offboard()  # one fresh setpoint is enough
            offboard = Offboard(drv)
            offboard.setpoint = Setpoint.position(*here)
            await wait_for_state(drv, lambda s: s.mode is FlightMode.OFFBOARD, 1.0, "OFFBOARD")
            await offboard.aclose()

    run(main())


def test_mode_changes_are_accepted_disarmed_and_checked_at_arming(sim_config):
    """PX4 always takes a mode change while disarmed; arming checks the mode can run."""
    async def main():
        async with simulator(sim_config) as drv:
            await armable(drv)
            await drv.start_offboard()  # disarmed, no setpoints: accepted
            await wait_for_state(drv, lambda s: s.mode is FlightMode.OFFBOARD, 1.0, "OFFBOARD")
            with pytest.raises(CommandDenied, match="arming denied in offboard"):
                await drv.arm()
            await drv.start_mission()  # no mission uploaded
            with pytest.raises(CommandDenied, match="no mission uploaded"):
                await drv.arm()
            await drv.hold()
            await drv.arm()

    run(main())


def test_setpoint_loss_holds_by_default(sim_config):
    """COM_OBL_RC_ACT 0 (position mode) without a pilot: HOLD, at once, and it stays."""
    async def main():
        async with simulator(sim_config) as drv:
            loss_s = drv.simulator.params["COM_OF_LOSS_T"]
            await take_off(drv, 2.0)
            offboard = Offboard(drv)
            await offboard.start_holding_here()
            await drv.clock.sleep(1.0)
            stopped = drv.clock.now()
            offboard.setpoint = None  # the controller stalls: nothing more is sent
            state = await wait_for_state(drv, lambda s: s.mode is FlightMode.HOLD, 3.0, "HOLD")
            assert state.failsafe
            # in HOLD once the last setpoint is older than the timeout (+ one telemetry period)
            assert state.time_s - stopped == pytest.approx(loss_s, abs=0.1)
            await drv.clock.sleep(10.0)
            assert drv.latest_state.mode is FlightMode.HOLD
            assert drv.latest_state.in_air
            await offboard.aclose()

    run(main())


def test_setpoint_loss_lands_with_com_obl_rc_act_land(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            await drv.set_param("COM_OBL_RC_ACT", 4)
            loss_s = drv.simulator.params["COM_OF_LOSS_T"]
            await take_off(drv, 2.0)
            offboard = Offboard(drv)
            await offboard.start_holding_here()
            await drv.clock.sleep(1.0)
            stopped = drv.clock.now()
            offboard.setpoint = None
            state = await wait_for_state(drv, lambda s: s.mode is FlightMode.LAND, 3.0, "LAND")
            assert state.failsafe
            assert state.time_s - stopped == pytest.approx(loss_s, abs=0.1)  # no action delay
            await wait_for_state(drv, lambda s: not s.armed, 20.0, "touchdown and disarm")
            await offboard.aclose()

    run(main())


def test_setpoints_returning_in_time_resume_offboard(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            await take_off(drv, 2.0)
            offboard = Offboard(drv)
            here = await offboard.start_holding_here()
            await drv.clock.sleep(0.5)
            offboard.setpoint = None
            await wait_for_state(drv, lambda s: s.mode is FlightMode.HOLD, 2.0, "HOLD")
            offboard.setpoint = Setpoint.position(*here)
            state = await wait_for_state(drv, lambda s: s.mode is FlightMode.OFFBOARD, 2.0,
                                         "back to OFFBOARD")
            assert not state.failsafe
            await offboard.aclose()

    run(main())


def test_user_hold_during_offboard(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            await take_off(drv, 2.0)
            offboard = Offboard(drv)
            await offboard.start_holding_here()
            await drv.stop_offboard()
            state = await wait_for_state(drv, lambda s: s.mode is FlightMode.HOLD, 1.0, "HOLD")
            assert not state.failsafe
            await offboard.aclose()

    run(main())


def test_body_frame_velocity_follows_heading(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            await take_off(drv, 2.0)
            offboard = Offboard(drv)
            here = await offboard.start_holding_here()
            offboard.setpoint = Setpoint.position(*here, yaw_rad=math.pi / 2)  # face east
            await wait_for_state(drv, lambda s: abs(s.yaw_rad - math.pi / 2) < 0.02, 5.0,
                                 "facing east")
            offboard.setpoint = Setpoint.velocity_body(1.0, 0.0, 0.0, yaw_rate_rad_s=0.0)
            samples = await record_truth(drv, 4.0)
            vel = samples[-1].vehicle.velocity_ned_m_s
            assert vel[1] == pytest.approx(1.0, abs=0.1)  # forward is east now
            assert abs(vel[0]) < 0.1
            assert abs(vel[2]) < 0.1
            await offboard.aclose()

    run(main())


def test_yaw_rate_setpoint(sim_config):
    async def main():
        async with simulator(sim_config) as drv:
            await take_off(drv, 2.0)
            offboard = Offboard(drv)
            here = await offboard.start_holding_here()
            offboard.setpoint = Setpoint.velocity_ned(0, 0, 0, yaw_rate_rad_s=0.5)
            await drv.clock.sleep(2.0)
            y0 = drv.latest_state.yaw_rad
            await drv.clock.sleep(2.0)
            turned = (drv.latest_state.yaw_rad - y0) % (2 * math.pi)
            assert turned == pytest.approx(1.0, abs=0.05)
            pos = np.array(drv.latest_state.position_ned_m)
            assert np.linalg.norm(pos[:2] - here[:2]) < 0.3
            await offboard.aclose()

    run(main())


def test_takeoff_without_altitude_uses_the_parameter(sim_config):
    expected = sim_config.flight_stack.commander.takeoff_altitude_m  # PX4's MIS_TAKEOFF_ALT

    async def main():
        async with simulator(sim_config) as drv:
            await armable(drv)
            await drv.arm()
            await drv.takeoff()
            await wait_for_state(drv, lambda s: s.mode is FlightMode.HOLD and s.in_air, 20.0,
                                 "takeoff")
            truth = (await record_truth(drv, 1.0))[-1]
            assert -truth.vehicle.position_ned_m[2] == pytest.approx(-GROUND_Z + expected,
                                                                     abs=0.1)

    run(main())
