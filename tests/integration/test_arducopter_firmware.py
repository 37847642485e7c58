"""The simulated vehicle as ArduCopter (``sim.firmware: ardupilot``), through the simulator's
own driver on the lockstep clock: its modes, arming rules, GUIDED (takeoff, targets that never
take off, the velocity timeout), LAND and RTL disarming at touchdown, AUTO from the ground,
CIRCLE and the parameters in ArduPilot's units (docs/reference/ardupilot-mavlink.md)."""

import math

import numpy as np
import pytest

from autopilot.flight_ops import wait_for_state
from drivers.base import CommandDenied, FlightMode, Setpoint
from drivers.mavlink.ardupilot import CopterMode
from drivers.mission import MissionItem
from tests.conftest import sim_with

from .simtools import GROUND_Z, armable, record_truth, run, simulator

GUIDED, LOITER, LAND, RTL, AUTO = (int(CopterMode.GUIDED), int(CopterMode.LOITER),
                                   int(CopterMode.LAND), int(CopterMode.RTL),
                                   int(CopterMode.AUTO))


@pytest.fixture
def copter(sim_config):
    return sim_with(sim_config, firmware="ardupilot")


def _mode(drv) -> int:
    return drv.simulator.flight.custom_mode


async def _guided_takeoff(drv, altitude_m: float = 3.0) -> None:
    await armable(drv)
    await drv.firmware_command("set_copter_mode", GUIDED)
    await drv.arm()
    await drv.takeoff(altitude_m)
    await wait_for_state(drv, lambda s: -s.position_ned_m[2] > altitude_m - 0.2, 20.0,
                         "takeoff")
    await drv.clock.sleep(3.0)


def test_boots_in_stabilize_and_arms_only_where_arducopter_allows(copter):
    async def main():
        async with simulator(copter) as drv:
            assert _mode(drv) == int(CopterMode.STABILIZE)
            assert drv.latest_state.mode is FlightMode.MANUAL
            await armable(drv)
            for mode in (RTL, LAND, AUTO):
                await drv.firmware_command("set_copter_mode", mode)  # disarmed: any mode
                with pytest.raises(CommandDenied, match=r"Arm: \w+ mode not armable"):
                    await drv.arm()
            with pytest.raises(CommandDenied, match="No such mode 13"):
                await drv.firmware_command("set_copter_mode", 13)  # SPORT is not built
            await drv.firmware_command("set_copter_mode", GUIDED)
            with pytest.raises(CommandDenied, match=r"not in a mode that takes off|not armed"):
                await drv.takeoff(3.0)
            await drv.arm()
            # armed on the ground and not taking off: disarmed after DISARM_DELAY (10 s)
            state = await wait_for_state(drv, lambda s: not s.armed, 12.0, "auto-disarm")
            assert not state.armed

    run(main())


def test_guided_takeoff_targets_and_velocity_timeout(copter):
    async def main():
        async with simulator(copter) as drv:
            await armable(drv)
            await drv.firmware_command("set_copter_mode", GUIDED)
            await drv.arm()
            # a target above a landed vehicle does not take off (only NAV_TAKEOFF does)
            await drv.send_setpoint(Setpoint(position_ned_m=[0.0, 0.0, -3.0]))
            truth = (await record_truth(drv, 2.0))[-1]
            assert truth.vehicle.position_ned_m[2] == pytest.approx(GROUND_Z, abs=0.02)
            await drv.takeoff(3.0)
            await wait_for_state(drv, lambda s: -s.position_ned_m[2] > 2.8, 20.0, "takeoff")
            await drv.clock.sleep(3.0)
            assert _mode(drv) == GUIDED  # a GUIDED takeoff holds in GUIDED
            z = float(drv.latest_state.position_ned_m[2])
            assert z == pytest.approx(GROUND_Z - 3.0, abs=0.3)
            # one velocity target, never repeated: flown for GUID_TIMEOUT (3 s), then stop
            await drv.send_setpoint(Setpoint(velocity_m_s=[1.0, 0.0, 0.0], yaw_rad=0.0))
            truth = await record_truth(drv, 8.0)
            x = np.array([t.vehicle.position_ned_m[0] for t in truth])
            t = np.array([t.time_s for t in truth]) - truth[0].time_s
            assert 2.0 < x[t < 3.2][-1] < 3.5  # ~1 m/s for 3 s
            assert abs(x[-1] - x[t > 6.0][0]) < 0.1  # stopped and holding
            assert np.max(x) < 5.0
            # a position target never times out
            await drv.send_setpoint(Setpoint(position_ned_m=[6.0, 2.0, -4.0], yaw_rad=0.0))
            truth = (await record_truth(drv, 12.0))[-1]
            np.testing.assert_allclose(truth.vehicle.position_ned_m[:2], [6.0, 2.0], atol=0.2)

    run(main())


def test_target_outside_guided_is_ignored_and_land_disarms_at_touchdown(copter):
    async def main():
        async with simulator(copter) as drv:
            await _guided_takeoff(drv)
            await drv.firmware_command("set_copter_mode", LOITER)
            await drv.send_setpoint(Setpoint(velocity_m_s=[2.0, 0.0, 0.0], yaw_rad=0.0))
            truth = await record_truth(drv, 3.0)
            assert abs(truth[-1].vehicle.position_ned_m[0]) < 0.3  # LOITER holds
            with pytest.raises(CommandDenied, match="Mode change to STABILIZE failed"):
                await drv.firmware_command("set_copter_mode", int(CopterMode.STABILIZE))
            await drv.firmware_command("set_copter_mode", LAND)
            landed = await wait_for_state(drv, lambda s: not s.armed, 30.0, "LAND disarms")
            assert landed.position_ned_m[2] > GROUND_Z - 0.2
            assert _mode(drv) == LAND  # ArduCopter stays in LAND, disarmed

    run(main())


def test_rtl_climbs_to_rtl_alt_returns_and_disarms(copter):
    async def main():
        async with simulator(copter) as drv:
            await drv.set_param("RTL_ALT", 800)  # cm
            await drv.set_param("RTL_LOIT_TIME", 1000)  # ms
            await _guided_takeoff(drv, 3.0)
            await drv.send_setpoint(Setpoint(position_ned_m=[12.0, 0.0, -3.0], yaw_rad=0.0))
            await wait_for_state(drv, lambda s: s.position_ned_m[0] > 11.7, 20.0, "out")
            await drv.firmware_command("set_copter_mode", RTL)
            seen = []
            await wait_for_state(drv, lambda s: seen.append(s) or not s.armed, 60.0, "RTL")
            top = max(-s.position_ned_m[2] for s in seen)
            assert top == pytest.approx(8.0, abs=0.4)  # RTL_ALT 8 m (within the cone: 36 m)
            np.testing.assert_allclose(seen[-1].position_ned_m[:2], [0.0, 0.0], atol=0.5)
            assert _mode(drv) == RTL

    run(main())


def test_auto_from_the_ground_needs_a_takeoff_and_mission_start(copter):
    async def main():
        async with simulator(copter) as drv:
            origin = drv.global_origin
            lat, lon, _ = origin.to_global(10.0, 0.0, 0.0)
            wp = MissionItem(seq=1, frame=3, command=16, param1=0.0, x=lat, y=lon, z=4.0)
            await drv.upload_mission([wp])
            await armable(drv)
            await drv.firmware_command("set_copter_mode", GUIDED)
            await drv.arm()
            with pytest.raises(CommandDenied, match="init failed"):
                await drv.firmware_command("set_copter_mode", AUTO)
            takeoff = MissionItem(seq=0, frame=3, command=22, x=0.0, y=0.0, z=4.0)
            land = MissionItem(seq=2, frame=3, command=21, x=0.0, y=0.0, z=0.0)
            await drv.upload_mission([takeoff, wp, land])
            await drv.firmware_command("set_copter_mode", AUTO)
            truth = (await record_truth(drv, 3.0))[-1]
            assert truth.vehicle.position_ned_m[2] == pytest.approx(GROUND_Z, abs=0.02)
            await drv.firmware_command("mission_start")  # MAV_CMD_MISSION_START
            seen = []
            await wait_for_state(drv, lambda s: seen.append(s) or not s.armed, 60.0,
                                 "mission flown and landed")
            assert max(s.position_ned_m[0] for s in seen) > 9.5
            assert min(s.position_ned_m[2] for s in seen) < GROUND_Z - 3.5

    run(main())


def test_circle_orbits_a_centre_circle_radius_ahead(copter):
    async def main():
        async with simulator(copter) as drv:
            await drv.set_param("CIRCLE_RADIUS", 500)  # cm
            await _guided_takeoff(drv, 3.0)
            start = np.array(drv.latest_state.position_ned_m)
            yaw = drv.latest_state.yaw_rad
            centre = start[:2] + 5.0 * np.array([math.cos(yaw), math.sin(yaw)])
            await drv.firmware_command("set_copter_mode", int(CopterMode.CIRCLE))
            truth = await record_truth(drv, 20.0)
            r = [float(np.hypot(*(t.vehicle.position_ned_m[:2] - centre))) for t in truth]
            assert np.median(r) == pytest.approx(5.0, abs=0.3)
            angles = np.unwrap([math.atan2(*(t.vehicle.position_ned_m[1::-1] - centre[::-1]))
                                for t in truth])
            assert abs(angles[-1] - angles[0]) > math.radians(200)  # 20 °/s for 20 s

    run(main())


def test_parameters_are_arducopters_and_reach_the_flight_code(copter):
    async def main():
        async with simulator(copter) as drv:
            assert drv.param("WPNAV_SPEED") == 1000.0
            assert drv.param("RTL_ALT") == 1500
            with pytest.raises(KeyError):
                drv.param("MPC_XY_CRUISE")
            await drv.set_param("WPNAV_SPEED", 350)
            assert drv.simulator.params["MPC_XY_CRUISE"] == pytest.approx(3.5)
            names = [spec.name for spec in drv.param_specs()]
            assert "GUID_TIMEOUT" in names
            assert "MIS_TAKEOFF_ALT" not in names

    run(main())


def test_follow_ball_flies_in_process_on_the_arducopter_firmware(tmp_path):
    """The whole mission on the simulated ArduCopter, asked as the MAVLink drivers' ArduCopter
    profile asks (GUIDED and NAV_TAKEOFF, GUIDED targets, LAND)."""
    from .simtools import fly_short

    summary, orphans = fly_short(["sim.firmware=ardupilot"], tmp_path)
    assert summary["status"] == "completed", summary.get("reason")
    assert orphans == []
    follow = summary["metrics"]["follow"]
    assert follow["detection_rate"] > 0.95
    assert follow["rms_range_error_m"] < 0.15


def test_land_pad_handed_to_plnd_lands_on_the_pad(tmp_path):
    """land_pad's descent handed to the vehicle's own precision landing: on the ArduCopter
    firmware that is LAND with PLND (AC_PrecLand), fed LANDING_TARGET from the first aligned
    sight, so its estimator has settled (2 s) before the hand-over."""
    from autopilot.flightlog.log import read_log
    from autopilot.mission import load_mission
    from autopilot.run import fly

    plan = load_mission("land_pad", [
        "sim.firmware=ardupilot", "sim.params.PLND_ENABLED=1", "sim.params.PLND_TYPE=1",
        "steps.1.land_pad.method=vehicle_precland", "scenario.seed=5"])
    summary = run(fly(plan, tmp_path))
    assert summary["status"] == "completed", summary.get("reason")
    landing = summary["metrics"]["landing"]
    assert landing["on_pad"]
    assert landing["error_m"] <= 0.2  # (AC_PrecLand's own descent: no final slow-down model)
    log = read_log(tmp_path / "flight.mcap")
    texts = [r["text"] for r in log["/vehicle/status_text"]]
    handed = next(r["time_s"] for r in log["/mission/events"]
                  if r["text"] == "request precision_land")
    complete = next(r["time_s"] for r in log["/vehicle/status_text"]
                    if r["text"] == "PrecLand: Init Complete")
    assert texts.index("PrecLand: Target Found") < texts.index("PrecLand: Init Complete")
    assert complete <= handed  # settled before LAND began
    assert "PrecLand: Failsafe Measures" not in texts


def test_a_landing_handed_to_arducopter_without_plnd_is_refused_before_it_flies(tmp_path):
    """ArduCopter's PLND_ENABLED is 0 by default: its LAND would land wherever the vehicle is.
    A mission that hands land_pad's descent to it is refused once connected (naming the step
    and the parameter), with nothing armed; the vehicle's own precision landing refuses too."""
    from autopilot.config import ConfigError
    from autopilot.mission import load_mission
    from autopilot.run import fly
    from drivers.sim.arducopter_driver import SimArduCopterDriver

    plan = load_mission("land_pad", ["sim.firmware=ardupilot",
                                     "steps.1.land_pad.method=vehicle_precland"])
    with pytest.raises(ConfigError) as caught:
        run(fly(plan, tmp_path))
    text = str(caught.value)
    assert "steps[1].land_pad" in text
    assert "PLND_ENABLED is 0" in text

    async def refused():
        driver = SimArduCopterDriver(plan.config.sim, lockstep=True)
        await driver.connect()
        try:
            with pytest.raises(CommandDenied, match="PLND_ENABLED is 0"):
                await driver.precision_land()
            assert _mode(driver) != LAND
            await driver.set_param("PLND_ENABLED", 1)
            assert "PLND_TYPE is 0" in await driver.precision_landing_problem()
        finally:
            await driver.close()

    run(refused())


def test_a_refused_hand_over_in_flight_lands_with_our_descent(tmp_path, monkeypatch):
    """A land_pad goal is not checked before it flies as a mission is: when the vehicle
    refuses the hand-over in flight, the step flies the descent itself, on the pad."""
    import autopilot.run as run_module
    from autopilot.flightlog.log import read_log
    from autopilot.mission import load_mission

    async def unchecked(plan, vehicle):
        return None

    monkeypatch.setattr(run_module, "check_vehicle_settings", unchecked)
    plan = load_mission("land_pad", ["sim.firmware=ardupilot",
                                     "steps.1.land_pad.method=vehicle_precland"])
    summary = run(run_module.fly(plan, tmp_path))
    assert summary["status"] == "completed", summary.get("reason")
    landing = summary["metrics"]["landing"]
    assert landing["on_pad"]
    assert landing["error_m"] <= 0.1
    events = [r["text"] for r in read_log(tmp_path / "flight.mcap")["/mission/events"]]
    assert any("precision_land refused" in t and "PLND_ENABLED is 0" in t for t in events)


def test_armed_on_the_ground_it_stays_landed_and_takes_off(tmp_path):
    """On the realistic profile the rangefinder gives outliers (its 12 m for a missed return):
    the flight stack gates them, so an ArduCopter armed on the ground stays landed (it used to
    read "in the air" for half a second now and then, and NAV_TAKEOFF was refused with
    "already flying"), and takes off when asked."""
    from autopilot.mission import load_mission
    from autopilot.run import make_sim_vehicle

    plan = load_mission("standby", ["sim.firmware=ardupilot",
                                    "sim.rangefinder.outlier_fraction=0.2"])
    vehicle, _ = make_sim_vehicle(plan)

    async def main():
        await vehicle.connect()
        try:
            await armable(vehicle)
            await vehicle.firmware_command("set_copter_mode", GUIDED)
            await vehicle.arm()
            stack = vehicle.simulator.flight.stack
            t0, landed = vehicle.clock.now(), []
            while vehicle.clock.now() - t0 < 3.0:
                await vehicle.clock.sleep(0.02)
                landed.append(stack.land_detector.landed)
            assert all(landed)
            assert stack.range_gate.rejected > 0  # (the outliers were there)
            await vehicle.takeoff(3.0)
            await wait_for_state(vehicle, lambda s: -s.position_ned_m[2] > 2.5, 20.0,
                                 "takeoff")
        finally:
            await vehicle.close()

    run(main())
