"""The simulated vehicle's navigator and failsafes in closed loop, on the lockstep clock:
missions (takeoff, waypoints, speed, hold times, jumps, pause and resume), return to launch,
the geofence, parameters and camera triggering, as PX4 flies them (see the research notes in
drivers/sim/flight/navigator/). Cameras are disabled: photos are counted, not rendered."""

from __future__ import annotations

import asyncio
import contextlib
import math

import numpy as np
import pytest

from autopilot.flight_ops import wait_for_state
from drivers.base import CommandDenied, FlightMode, Health, Setpoint, VehicleState
from drivers.geo import GlobalOrigin
from drivers.mission import Cmd, Frame, MissionItem, MissionRejected, MissionType
from drivers.sim.driver import SimDriver
from drivers.sim.flight.commander import Commander, Inputs
from drivers.sim.flight.navigator import Estimate, MissionState, Navigator
from drivers.sim.flight.params import ParamError, Parameters

from .simtools import Offboard, armable, run, simulator, take_off

NAN = float("nan")


# ----------------------------------------------------------------------------------------
# Helpers
# ----------------------------------------------------------------------------------------

def wp(drv: SimDriver, seq: int, north: float, east: float, alt: float,
       cmd: Cmd = Cmd.NAV_WAYPOINT, **params) -> MissionItem:
    """A mission item at local (north, east) of the driver's origin, ``alt`` above home."""
    lat, lon, _ = drv.global_origin.to_global(north, east, 0.0)
    return MissionItem(seq, Frame.GLOBAL_RELATIVE_ALT_INT, cmd, x=lat, y=lon, z=alt, **params)


def do(seq: int, cmd: Cmd, **params) -> MissionItem:
    """A mission item without a position (DO_*, camera, NAV_RETURN_TO_LAUNCH)."""
    return MissionItem(seq, Frame.MISSION, cmd, **params)


def fence_polygon(drv: SimDriver, cmd: Cmd, corners_ne, first_seq: int = 0) -> list[MissionItem]:
    items = []
    for k, (n, e) in enumerate(corners_ne):
        lat, lon, _ = drv.global_origin.to_global(n, e, 0.0)
        items.append(MissionItem(first_seq + k, Frame.GLOBAL_INT, cmd, param1=len(corners_ne),
                                 x=lat, y=lon, z=0.0, mission_type=MissionType.FENCE))
    return items


def fence_circle(drv: SimDriver, cmd: Cmd, center_ne, radius: float, seq: int = 0
                 ) -> MissionItem:
    lat, lon, _ = drv.global_origin.to_global(*center_ne, 0.0)
    return MissionItem(seq, Frame.GLOBAL_INT, cmd, param1=radius, x=lat, y=lon, z=0.0,
                       mission_type=MissionType.FENCE)


class Recorder:
    """Collects telemetry, mission events, status texts and photos in the background."""

    def __init__(self, drv: SimDriver) -> None:
        self.drv = drv
        self.states: list[VehicleState] = []
        self.mission: list = []
        self.texts: list[tuple[float, str]] = []
        self.photos: list = []
        self._tasks = [asyncio.ensure_future(self._collect(drv.telemetry(1024), self.states)),
                       asyncio.ensure_future(self._collect(drv.mission_events(1024),
                                                           self.mission)),
                       asyncio.ensure_future(self._collect(drv.events(1024), self.texts)),
                       asyncio.ensure_future(self._collect(drv.photos(1024), self.photos))]

    @staticmethod
    async def _collect(stream, into: list) -> None:
        async with contextlib.aclosing(stream) as items:
            async for item in items:
                into.append(item)

    async def aclose(self) -> None:
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task

    def reached(self) -> list[int]:
        return [e.seq for e in self.mission if e.kind == "reached"]

    def event_time(self, kind: str, seq: int) -> float:
        return next(e.time_s for e in self.mission if e.kind == kind and e.seq == seq)

    def text_time(self, fragment: str) -> float:
        return next(t for t, text in self.texts if fragment in text)

    def between(self, t0: float, t1: float) -> list[VehicleState]:
        return [s for s in self.states if t0 <= s.time_s <= t1]


@contextlib.asynccontextmanager
async def flight(config, **params):
    """A connected, armable simulator with ``params`` set, and a recorder running."""
    async with simulator(config) as drv:
        for name, value in params.items():
            await drv.set_param(name, value)
        await armable(drv)
        rec = Recorder(drv)
        try:
            yield drv, rec
        finally:
            await rec.aclose()


async def fly_mission(drv: SimDriver, items: list[MissionItem]) -> None:
    await drv.upload_mission(items)
    await drv.arm()
    await drv.start_mission()


def height(state: VehicleState, home) -> float:
    return float(home[2] - state.position_ned_m[2])


def horizontal(state: VehicleState, point) -> float:
    return float(np.hypot(state.position_ned_m[0] - point[0], state.position_ned_m[1] - point[1]))


def ground_speed(state: VehicleState) -> float:
    return float(np.hypot(*state.velocity_ned_m_s[:2]))


def home_of(drv: SimDriver) -> np.ndarray:
    return drv.home()[3]


async def wait_mode(drv: SimDriver, mode: FlightMode, timeout_s: float) -> VehicleState:
    return await wait_for_state(drv, lambda s: s.mode is mode, timeout_s, mode.value)


async def wait_near(drv: SimDriver, north: float, east: float, timeout_s: float,
                    radius_m: float = 1.0) -> VehicleState:
    return await wait_for_state(drv, lambda s: horizontal(s, (north, east)) < radius_m and
                                ground_speed(s) < 0.3, timeout_s, f"at ({north}, {east})")


async def go_to(drv: SimDriver, north: float, east: float, alt: float,
                timeout_s: float = 20.0) -> None:
    """DO_REPOSITION (goto) to local (north, east) at ``alt`` above home, and wait there."""
    home = home_of(drv)
    await drv.reposition([north, east, home[2] - alt])
    await wait_near(drv, north, east, timeout_s)


# ----------------------------------------------------------------------------------------
# Missions
# ----------------------------------------------------------------------------------------

@pytest.mark.parametrize(("takeoff_alt", "first_alt"), [(3.0, 6.0), (8.0, 4.0)])
def test_mission_from_the_ground_takes_off_flies_in_order_and_loiters(no_camera_config,
                                                                      takeoff_alt, first_alt):
    """PX4: started on the ground, a mission first climbs straight up to
    max(MIS_TAKEOFF_ALT, first waypoint altitude), then flies its items in order; at the end
    it loiters at the last waypoint, still in MISSION, COMPLETE."""
    async def main():
        async with flight(no_camera_config, MIS_TAKEOFF_ALT=takeoff_alt) as (drv, rec):
            items = [wp(drv, 0, 12, 0, first_alt), wp(drv, 1, 12, 12, 5.0),
                     wp(drv, 2, 0, 12, 5.0)]
            await fly_mission(drv, items)
            home = home_of(drv)
            await wait_for_state(drv, lambda s: drv.mission_status.state is
                                 MissionState.COMPLETE, 40.0, "mission complete")
            finished_at = drv.clock.now()
            await drv.clock.sleep(4.0)

            climb = max(takeoff_alt, first_alt)
            assert any(f"Takeoff to {climb:.1f} meters above home" in t for _, t in rec.texts)
            # the climb is vertical: no horizontal motion before the takeoff altitude
            moving = next(s for s in rec.states if horizontal(s, home) > 0.5)
            assert height(moving, home) == pytest.approx(climb, abs=0.3)
            assert max(height(s, home) for s in rec.states) < climb + 0.5
            # items in order, each reached once, MISSION_CURRENT follows
            assert rec.reached() == [0, 1, 2]
            currents = [e.seq for e in rec.mission if e.kind == "current"]
            assert currents == sorted(currents)
            assert currents[-1] >= 2
            assert [e.kind for e in rec.mission][-1] == "finished"
            assert any("mission finished, loitering" in t for _, t in rec.texts)
            # loitering at the last waypoint, in MISSION mode, COMPLETE
            after = rec.between(finished_at, finished_at + 4.0)
            assert all(s.mode is FlightMode.MISSION and s.in_air for s in after)
            assert max(horizontal(s, (0, 12)) for s in after) < 0.5
            assert height(after[-1], home) == pytest.approx(5.0, abs=0.3)
            status = drv.mission_status
            assert status.state is MissionState.COMPLETE
            assert status.in_mission_mode

    run(main())


def test_cruise_speed_parameter_and_do_change_speed(no_camera_config):
    """MPC_XY_CRUISE is the mission's speed between waypoints; a DO_CHANGE_SPEED item
    overrides it for the rest of the mission."""
    async def main():
        async with flight(no_camera_config, MPC_XY_CRUISE=8.0) as (drv, rec):
            items = [wp(drv, 0, 0, 0, 5.0), wp(drv, 1, 60, 0, 5.0),
                     do(2, Cmd.DO_CHANGE_SPEED, param1=1, param2=3.0, param3=-1),
                     wp(drv, 3, 60, -36, 5.0)]
            await fly_mission(drv, items)
            await wait_for_state(drv, lambda s: drv.mission_status.state is
                                 MissionState.COMPLETE, 50.0, "mission complete")
            leg1 = [ground_speed(s) for s in rec.states
                    if 20 < s.position_ned_m[0] < 40 and abs(s.position_ned_m[1]) < 1]
            leg2 = [ground_speed(s) for s in rec.states
                    if abs(s.position_ned_m[0] - 60) < 1 and -28 < s.position_ned_m[1] < -8]
            assert float(np.median(leg1)) == pytest.approx(8.0, abs=0.3)
            assert float(np.median(leg2)) == pytest.approx(3.0, abs=0.2)

    run(main())


def test_hold_time_loiter_time_and_fly_through(no_camera_config):
    """NAV_WAYPOINT param1 and NAV_LOITER_TIME param1 stop at the point for that long (the item
    counts as reached after it); a waypoint without hold time on a straight line is flown
    through at speed."""
    async def main():
        async with flight(no_camera_config) as (drv, rec):
            items = [wp(drv, 0, 15, 0, 5.0), wp(drv, 1, 30, 0, 5.0, param1=3.0),
                     wp(drv, 2, 30, 15, 5.0, Cmd.NAV_LOITER_TIME, param1=4.0),
                     wp(drv, 3, 30, 25, 5.0)]
            await fly_mission(drv, items)
            await wait_for_state(drv, lambda s: drv.mission_status.state is
                                 MissionState.COMPLETE, 50.0, "mission complete")
            # flown through: no slowing down around waypoint 0
            near0 = [ground_speed(s) for s in rec.states if horizontal(s, (15, 0)) < 3.0]
            assert min(near0) > 4.0
            for seq, point, hold_s in ((1, (30, 0), 3.0), (2, (30, 15), 4.0)):
                stopped = [s.time_s for s in rec.states
                           if horizontal(s, point) < 1.0 and ground_speed(s) < 0.3]
                arrived, left = stopped[0], stopped[-1]
                assert left - arrived >= hold_s - 0.1
                assert left - arrived < hold_s + 2.0
                # reached once the hold time is over (PX4 reports the item then)
                assert rec.event_time("reached", seq) - arrived == pytest.approx(hold_s,
                                                                                 abs=1.0)
            assert rec.reached() == [0, 1, 2, 3]

    run(main())


def test_do_jump_repeats_a_leg(no_camera_config):
    """DO_JUMP (param1 target, param2 repeat count) flies the leg again that many times, then
    goes on after it."""
    async def main():
        async with flight(no_camera_config) as (drv, rec):
            items = [wp(drv, 0, 6, 0, 4.0), wp(drv, 1, 6, 6, 4.0),
                     do(2, Cmd.DO_JUMP, param1=0, param2=2), wp(drv, 3, 0, 6, 4.0)]
            await fly_mission(drv, items)
            await wait_for_state(drv, lambda s: drv.mission_status.state is
                                 MissionState.COMPLETE, 50.0, "mission complete")
            nav_reached = [seq for seq in rec.reached() if seq != 2]
            assert nav_reached == [0, 1, 0, 1, 0, 1, 3]
            assert drv.latest_state.mode is FlightMode.MISSION

    run(main())


def test_pause_resume_and_set_current(no_camera_config):
    """HOLD pauses the mission where the vehicle can stop; MISSION again continues with the
    current item; MISSION_SET_CURRENT makes another item the next one."""
    async def main():
        async with flight(no_camera_config) as (drv, rec):
            items = [wp(drv, 0, 30, 0, 5.0), wp(drv, 1, 30, 30, 5.0), wp(drv, 2, 0, 30, 5.0)]
            await fly_mission(drv, items)
            await wait_for_state(drv, lambda s: s.position_ned_m[0] > 10, 20.0, "on the leg")
            await drv.hold()
            paused = await wait_for_state(drv, lambda s: s.mode is FlightMode.HOLD and
                                          ground_speed(s) < 0.2, 5.0, "stopped")
            status = drv.mission_status
            assert status.state is MissionState.PAUSED
            assert status.current == 0
            assert not status.in_mission_mode
            await drv.clock.sleep(3.0)
            assert horizontal(drv.latest_state, paused.position_ned_m) < 0.3
            assert paused.position_ned_m[0] < 25  # stopped short of the waypoint
            await drv.start_mission()
            await wait_near(drv, 30, 0, 20.0)
            await wait_for_state(drv, lambda s: drv.mission_status.current == 1, 5.0, "item 1")
            await drv.set_mission_current(2)
            assert drv.mission_status.current == 2
            await wait_for_state(drv, lambda s: drv.mission_status.state is
                                 MissionState.COMPLETE, 30.0, "mission complete")
            assert rec.reached() == [0, 2]
            # straight from (30, 0) to (0, 30): never near waypoint 1
            assert min(horizontal(s, (30, 30)) for s in rec.states) > 15

    run(main())


def test_mission_rtl_item_switches_to_return(no_camera_config):
    async def main():
        async with flight(no_camera_config, RTL_RETURN_ALT=8.0) as (drv, rec):
            items = [wp(drv, 0, 15, 0, 5.0), do(1, Cmd.NAV_RETURN_TO_LAUNCH)]
            await fly_mission(drv, items)
            home = home_of(drv)
            await wait_mode(drv, FlightMode.RETURN, 20.0)
            assert rec.reached() == [0, 1]
            last = await wait_for_state(drv, lambda s: not s.armed, 40.0, "landed and disarmed")
            assert horizontal(last, home) < 1.0
            # climbed to RTL_RETURN_ALT before returning
            assert max(height(s, home) for s in rec.states) == pytest.approx(8.0, abs=0.4)

    run(main())


def test_mission_land_item_lands_there_and_disarms(no_camera_config):
    async def main():
        async with flight(no_camera_config) as (drv, rec):
            items = [wp(drv, 0, 10, 0, 5.0), wp(drv, 1, 10, 10, 5.0, Cmd.NAV_LAND)]
            await fly_mission(drv, items)
            last = await wait_for_state(drv, lambda s: not s.armed, 40.0, "landed and disarmed")
            assert horizontal(last, (10, 10)) < 1.0
            assert rec.reached() == [0, 1]
            assert drv.mission_status.state is MissionState.COMPLETE
            assert any("mission finished, landed" in t for _, t in rec.texts)
            # the descent starts above the landing point, not on the way there
            descending = next(s for s in rec.states if s.time_s > rec.event_time("reached", 0)
                              and s.velocity_ned_m_s[2] > 0.3)
            assert horizontal(descending, (10, 10)) < 1.5

    run(main())


# ----------------------------------------------------------------------------------------
# Return to launch
# ----------------------------------------------------------------------------------------

def test_rtl_from_far_climbs_returns_and_lands_directly(no_camera_config):
    """Beyond RTL_MIN_DIST: climb vertically to RTL_RETURN_ALT, fly home at it, and with
    RTL_LAND_DELAY 0 descend straight into the landing (no stop at RTL_DESCEND_ALT); touch down
    within a metre of home and disarm COM_DISARM_LAND later."""
    async def main():
        async with flight(no_camera_config, RTL_RETURN_ALT=12.0, RTL_DESCEND_ALT=6.0,
                          COM_DISARM_LAND=1.5) as (drv, rec):
            await take_off(drv, 4.0)
            home = home_of(drv)
            await go_to(drv, 25, 0, 4.0)
            start = drv.clock.now()
            await drv.return_to_launch()
            last = await wait_for_state(drv, lambda s: not s.armed, 60.0, "landed, disarmed")
            rtl = rec.between(start, last.time_s)
            assert horizontal(last, home) < 1.0
            # climbed where it was, up to RTL_RETURN_ALT
            leaving = next(s for s in rtl if horizontal(s, (25, 0)) > 0.5)
            assert height(leaving, home) == pytest.approx(12.0, abs=0.3)
            assert max(height(s, home) for s in rtl) < 12.5
            # returned at that altitude, then descended without a stop on the way
            over_home = next(s for s in rtl if horizontal(s, home) < 1.0)
            assert height(over_home, home) == pytest.approx(12.0, abs=0.5)
            descent = [s for s in rtl if s.time_s > over_home.time_s and
                       1.0 < height(s, home) < 10.0]
            assert min(s.velocity_ned_m_s[2] for s in descent) > 0.4
            assert not any("loitering" in t for _, t in rec.texts)
            landed = rec.text_time("landed")
            disarmed = rec.text_time("auto-disarmed after landing")
            assert disarmed - landed == pytest.approx(1.5, abs=0.2)

    run(main())


@pytest.mark.parametrize(("cone_deg", "expected_alt"), [(45, 8.0), (0, 15.0)])
def test_rtl_cone_inside_rtl_min_dist(no_camera_config, cone_deg, expected_alt):
    """Within RTL_MIN_DIST the return altitude is limited by the RTL_CONE_ANG cone above home
    (8 m away at 45°: 8 m); without the cone it is RTL_RETURN_ALT."""
    async def main():
        async with flight(no_camera_config, RTL_RETURN_ALT=15.0, RTL_MIN_DIST=20.0,
                          NAV_ACC_RAD=2.0, RTL_CONE_ANG=cone_deg) as (drv, rec):
            await take_off(drv, 3.0)
            home = home_of(drv)
            await go_to(drv, 0, 8, 3.0, timeout_s=10.0)
            start = drv.clock.now()
            await drv.return_to_launch()
            await wait_for_state(drv, lambda s: horizontal(s, home) < 0.5, 30.0, "over home")
            top = max(height(s, home) for s in rec.states if s.time_s >= start)
            assert top == pytest.approx(expected_alt, abs=0.4)

    run(main())


@pytest.mark.parametrize("delay_s", [-1.0, 3.0])
def test_rtl_land_delay_loiters_at_descend_altitude(no_camera_config, delay_s):
    """RTL_LAND_DELAY ≠ 0: descend to RTL_DESCEND_ALT over home and wait there that long
    (−1: for good, "RTL: completed, loitering"), then land."""
    async def main():
        async with flight(no_camera_config, RTL_RETURN_ALT=12.0, RTL_DESCEND_ALT=6.0,
                          RTL_LAND_DELAY=delay_s) as (drv, rec):
            await take_off(drv, 4.0)
            home = home_of(drv)
            await go_to(drv, 15, 0, 4.0)
            await drv.return_to_launch()
            at_loiter = await wait_for_state(
                drv, lambda s: horizontal(s, home) < 1.0 and abs(height(s, home) - 6.0) < 0.3
                and abs(s.velocity_ned_m_s[2]) < 0.1, 40.0, "loitering at RTL_DESCEND_ALT")
            if delay_s < 0:
                await drv.clock.sleep(8.0)
                assert any("RTL: completed, loitering" in t for _, t in rec.texts)
                hover = rec.between(at_loiter.time_s, at_loiter.time_s + 8.0)
                assert all(s.mode is FlightMode.RETURN and s.in_air for s in hover)
                assert max(abs(height(s, home) - 6.0) for s in hover) < 0.3
            else:
                await wait_for_state(drv, lambda s: not s.armed, 40.0, "landed, disarmed")
                land_at = rec.text_time("RTL: land at destination")
                assert land_at - at_loiter.time_s == pytest.approx(delay_s, abs=0.6)
                assert horizontal(drv.latest_state, home) < 1.0

    run(main())


def test_rtl_return_altitude_table():
    """RTL::computeReturnAltitude (research notes 6.3), without flying."""
    params = Parameters({"RTL_RETURN_ALT": 30.0, "RTL_MIN_DIST": 20.0, "NAV_ACC_RAD": 2.0})
    nav = Navigator(params, GlobalOrigin(47.397742, 8.545594, 488.0),
                    request_mode=lambda m: None, complete=lambda m, t: None,
                    event=lambda text: None)
    nav.home = np.zeros(3)

    def alt(north: float, height_m: float) -> float:
        return nav.return_altitude_m(Estimate(np.array([north, 0.0, -height_m]), np.zeros(3),
                                              0.0))

    assert alt(50.0, 5.0) == 30.0  # beyond RTL_MIN_DIST
    assert alt(50.0, 40.0) == 40.0  # never descends first
    assert alt(10.0, 1.0) == pytest.approx(10.0)  # the 45° cone
    assert alt(1.0, 0.5) == pytest.approx(2.0)  # inside NAV_ACC_RAD: twice the distance
    assert alt(2.5, 0.5) == pytest.approx(4.0)  # at least twice NAV_ACC_RAD
    params.set("RTL_CONE_ANG", 0)
    assert alt(10.0, 1.0) == 30.0


# ----------------------------------------------------------------------------------------
# Geofence
# ----------------------------------------------------------------------------------------

def test_geofence_max_distance_hold(no_camera_config):
    """GF_ACTION 2: HOLD at once when GF_MAX_HOR_DIST is crossed (even while flying a
    DO_REPOSITION in HOLD: the vehicle stops, it does not fly on)."""
    async def main():
        async with flight(no_camera_config, GF_MAX_HOR_DIST=20.0, GF_ACTION=2) as (drv, rec):
            await take_off(drv, 4.0)
            home = home_of(drv)
            await drv.reposition([40.0, 0.0, home[2] - 4.0])
            breach = await wait_for_state(drv, lambda s: s.failsafe, 20.0, "failsafe")
            assert breach.mode is FlightMode.HOLD
            assert horizontal(breach, home) == pytest.approx(20.0, abs=0.5)
            await drv.clock.sleep(6.0)
            state = drv.latest_state
            assert state.mode is FlightMode.HOLD
            assert state.failsafe
            assert ground_speed(state) < 0.2
            assert horizontal(state, home) < 26.0  # braked at MPC_ACC_HOR
            text = next(t for _, t in rec.texts if "geofence breached" in t)
            assert "GF_MAX_HOR_DIST 20 m" in text

    run(main())


@pytest.mark.parametrize(("action", "mode"), [(3, FlightMode.RETURN), (5, FlightMode.LAND)])
def test_geofence_rtl_and_land_after_the_failsafe_delay(no_camera_config, action, mode):
    """GF_ACTION 3 (return) and 5 (land): HOLD for COM_FAIL_ACT_T, then the action."""
    async def main():
        async with flight(no_camera_config, GF_MAX_HOR_DIST=15.0, GF_ACTION=action,
                          COM_FAIL_ACT_T=2.0, RTL_RETURN_ALT=6.0) as (drv, rec):
            await take_off(drv, 4.0)
            home = home_of(drv)
            items = [wp(drv, 0, 30, 0, 4.0)]
            await drv.upload_mission(items)
            await drv.start_mission()
            held = await wait_for_state(drv, lambda s: s.failsafe, 20.0, "failsafe")
            assert held.mode is FlightMode.HOLD
            acting = await wait_mode(drv, mode, 5.0)
            assert acting.time_s - held.time_s == pytest.approx(2.0, abs=0.1)
            assert acting.failsafe
            last = await wait_for_state(drv, lambda s: not s.armed, 40.0, "landed, disarmed")
            if mode is FlightMode.RETURN:
                assert horizontal(last, home) < 1.0
            else:
                assert horizontal(last, home) > 15.0  # landed where it stopped
            # the mode stayed with the failsafe until landing (no toggling back and forth)
            after = [s.mode for s in rec.states if acting.time_s <= s.time_s < last.time_s]
            assert set(after) == {mode}

    run(main())


def test_geofence_warning_only(no_camera_config):
    """GF_ACTION 1: a warning in the status texts, and the mission goes on."""
    async def main():
        async with flight(no_camera_config, GF_MAX_HOR_DIST=15.0, GF_ACTION=1) as (drv, rec):
            items = [wp(drv, 0, 30, 0, 4.0)]
            await fly_mission(drv, items)
            await wait_for_state(drv, lambda s: drv.mission_status.state is
                                 MissionState.COMPLETE, 40.0, "mission complete")
            warnings = [t for _, t in rec.texts if t.startswith("warning: geofence breached")]
            assert len(warnings) == 1
            assert "GF_MAX_HOR_DIST 15 m" in warnings[0]
            assert not any(s.failsafe for s in rec.states)
            assert {s.mode for s in rec.states if s.armed} == {FlightMode.MISSION}

    run(main())


def test_inclusion_polygon_breach_then_the_user_flies_back(no_camera_config):
    """An uploaded inclusion polygon: leaving it holds (GF_ACTION 2); the user's RTL then
    takes over and is flown home although the vehicle is still outside (PX4: the user's
    mode switch takes over, the failsafe ends once the condition is gone)."""
    async def main():
        async with flight(no_camera_config, GF_ACTION=2, RTL_RETURN_ALT=8.0) as (drv, rec):
            square = [(-20, -20), (-20, 20), (20, 20), (20, -20)]
            await drv.upload_mission(fence_polygon(drv, Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                                                   square), MissionType.FENCE)
            await take_off(drv, 4.0)
            home = home_of(drv)
            await drv.reposition([0.0, 40.0, home[2] - 4.0])
            breach = await wait_for_state(drv, lambda s: s.failsafe, 20.0, "failsafe")
            assert breach.mode is FlightMode.HOLD
            assert breach.position_ned_m[1] == pytest.approx(20.0, abs=0.5)
            assert drv.geofence_breach == "outside the inclusion polygon 0"
            await wait_for_state(drv, lambda s: ground_speed(s) < 0.2, 5.0, "stopped")
            assert drv.geofence_breach is not None  # still outside
            await drv.return_to_launch()
            taken = drv.clock.now()
            await wait_for_state(drv, lambda s: not s.armed, 60.0, "home and disarmed")
            modes = {s.mode for s in rec.states if s.armed and s.time_s > taken + 0.1}
            assert modes == {FlightMode.RETURN}
            assert horizontal(drv.latest_state, home) < 1.0
            assert any("user took over" in t for _, t in rec.texts)

    run(main())


def test_exclusion_circle_breach_and_a_mission_through_it_is_refused(no_camera_config):
    async def main():
        async with flight(no_camera_config, GF_ACTION=5, COM_FAIL_ACT_T=0.0) as (drv, rec):
            await drv.upload_mission([fence_circle(drv, Cmd.NAV_FENCE_CIRCLE_EXCLUSION,
                                                   (20.0, 0.0), 5.0)], MissionType.FENCE)
            await drv.upload_mission([wp(drv, 0, 20, 0, 4.0)])
            await take_off(drv, 4.0)
            with pytest.raises(CommandDenied, match="Geofence violation for waypoint 1"):
                await drv.start_mission()
            home = home_of(drv)
            await drv.reposition([40.0, 0.0, home[2] - 4.0])
            breach = await wait_for_state(drv, lambda s: s.failsafe, 20.0, "failsafe")
            assert breach.mode is FlightMode.LAND  # COM_FAIL_ACT_T 0: at once
            assert breach.position_ned_m[0] == pytest.approx(15.0, abs=0.5)
            assert any("inside the exclusion circle 0" in t for _, t in rec.texts)
            await wait_for_state(drv, lambda s: not s.armed, 30.0, "landed, disarmed")

    run(main())


def test_a_malformed_fence_upload_is_refused_and_the_old_one_stays(no_camera_config):
    async def main():
        async with simulator(no_camera_config) as drv:
            good = fence_polygon(drv, Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                                 [(-20, -20), (-20, 20), (20, 20)])
            await drv.upload_mission(good, MissionType.FENCE)
            fence_id = drv.mission_status.fence_id
            bad = fence_polygon(drv, Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION, [(0, 0), (0, 5)])
            with pytest.raises(MissionRejected) as info:
                await drv.upload_mission(bad, MissionType.FENCE)
            assert info.value.result == 1  # MAV_MISSION_ERROR
            assert drv.mission_items(MissionType.FENCE) == good
            assert drv.mission_status.fence_id == fence_id

    run(main())


def _inputs(now: float, breach: str | None) -> Inputs:
    return Inputs(now_s=now, landed=False, health=Health(), battery_fraction=1.0,
                  setpoint_age_s=math.inf, setpoint_flyable=True, gcs_silent_s=0.0,
                  geofence_breach=breach, has_home=True)


def test_commander_geofence_takeover_is_edge_triggered():
    """The commander alone: a user's mode change while still outside takes over for as long
    as the breach lasts; a new breach after coming back acts again."""
    params = Parameters({"GF_ACTION": 2})
    texts: list[str] = []
    cmd = Commander(params, texts.append)
    cmd.arm(0.0)
    cmd.request_mode(FlightMode.MISSION)
    cmd.update(_inputs(1.0, None))
    assert cmd.mode is FlightMode.MISSION
    cmd.update(_inputs(2.0, "outside"))
    assert cmd.mode is FlightMode.HOLD
    assert cmd.failsafe == "geofence breached"
    cmd.request_mode(FlightMode.RETURN)  # the user takes over
    for t in range(3, 10):
        cmd.update(_inputs(float(t), "outside"))
        assert cmd.mode is FlightMode.RETURN
        assert cmd.failsafe is None
    cmd.update(_inputs(10.0, None))  # back inside
    cmd.request_mode(FlightMode.MISSION)
    cmd.update(_inputs(11.0, None))
    assert cmd.mode is FlightMode.MISSION
    cmd.update(_inputs(12.0, "outside"))  # a new breach
    assert cmd.mode is FlightMode.HOLD
    assert cmd.failsafe == "geofence breached"
    # without a takeover, coming back inside does not end the failsafe (OnModeChangeOrDisarm)
    cmd.update(_inputs(13.0, None))
    assert cmd.mode is FlightMode.HOLD
    assert cmd.failsafe == "geofence breached"
    cmd.request_mode(FlightMode.MISSION)
    cmd.update(_inputs(14.0, None))
    assert cmd.mode is FlightMode.MISSION
    assert cmd.failsafe is None


# ----------------------------------------------------------------------------------------
# Parameters
# ----------------------------------------------------------------------------------------

def test_parameters_refused_out_of_range_or_of_the_wrong_type(no_camera_config):
    async def main():
        async with simulator(no_camera_config) as drv:
            cruise = drv.param("MPC_XY_CRUISE")
            for name, value, match in [("MPC_XY_CRUISE", 50.0, "out of range"),
                                       ("MPC_XY_CRUISE", NAN, "not a number"),
                                       ("GF_ACTION", 2.5, "not an integer"),
                                       ("RTL_CONE_ANG", 30, "not one of"),
                                       ("NOT_A_PARAM", 1.0, "unknown parameter")]:
                before = drv.param(name) if name in drv.simulator.params else None
                with pytest.raises(ParamError, match=match):
                    await drv.set_param(name, value)
                if before is not None:
                    assert drv.param(name) == before
            assert drv.param("MPC_XY_CRUISE") == cruise
            assert await drv.set_param("GF_ACTION", 3.0) == 3
            assert isinstance(drv.param("GF_ACTION"), int)
            assert await drv.set_param("MPC_XY_CRUISE", 7) == 7.0

    run(main())


# ----------------------------------------------------------------------------------------
# Camera triggering
# ----------------------------------------------------------------------------------------

def test_photos_by_interval_count_and_distance(no_camera_config):
    """IMAGE_START_CAPTURE with an interval takes a photo at once and then one per interval
    (param3 photos in all), DO_SET_CAM_TRIGG_DIST one every so many metres travelled."""
    async def main():
        async with flight(no_camera_config) as (drv, rec):
            items = [wp(drv, 0, 0, 0, 4.0),
                     do(1, Cmd.IMAGE_START_CAPTURE, param1=0, param2=1.0, param3=4),
                     wp(drv, 2, 0, 0, 4.0, param1=6.0),  # hover 6 s: 4 photos, 1 s apart
                     do(3, Cmd.DO_SET_CAM_TRIGG_DIST, param1=5.0, param3=0),
                     wp(drv, 4, 31, 0, 4.0),
                     do(5, Cmd.DO_SET_CAM_TRIGG_DIST, param1=0.0),
                     wp(drv, 6, 31, 10, 4.0)]
            await fly_mission(drv, items)
            await wait_for_state(drv, lambda s: drv.mission_status.state is
                                 MissionState.COMPLETE, 40.0, "mission complete")
            await drv.clock.sleep(0.5)
            photos = rec.photos
            assert all(p.frame is None for p in photos)  # no camera configured
            assert [p.index for p in photos] == list(range(len(photos)))
            timed, spaced = photos[:4], photos[4:]
            assert np.diff([p.time_s for p in timed]) == pytest.approx([1.0] * 3, abs=0.03)
            # 31 m at one photo per 5 m travelled: 6 photos, all on the leg north
            assert len(spaced) == 6
            north = [p.position_ned_m[0] for p in spaced]
            assert np.diff(north) == pytest.approx([5.0] * 5, abs=0.3)
            assert all(abs(p.position_ned_m[1]) < 0.5 for p in spaced)

    run(main())


def test_commander_data_link_loss_action_stays_until_a_mode_change():
    """PX4 (NAV_DLL_ACT, OnModeChangeOrDisarm): the link coming back does not end the
    return; the user's next mode change does."""
    params = Parameters({"NAV_DLL_ACT": 2, "COM_FAIL_ACT_T": 0.0})
    cmd = Commander(params, lambda text: None)
    cmd.arm(0.0)
    cmd.request_mode(FlightMode.MISSION)
    lost = params["COM_DL_LOSS_T"] + 1.0
    cmd.update(Inputs(1.0, False, Health(), 1.0, math.inf, True, lost, None, True))
    assert cmd.mode is FlightMode.RETURN
    cmd.update(_inputs(2.0, None))  # heard again
    assert cmd.mode is FlightMode.RETURN
    cmd.request_mode(FlightMode.HOLD)
    cmd.update(_inputs(3.0, None))
    assert cmd.mode is FlightMode.HOLD
    assert cmd.failsafe is None


@pytest.mark.parametrize(("action", "mode"), [(0, None), (2, FlightMode.LAND),
                                              (3, FlightMode.RETURN)])
def test_battery_critical_follows_com_low_bat_act(no_camera_config, action, mode):
    """BAT_CRIT_THR reached in flight: COM_LOW_BAT_ACT 0 warns, 2 lands, 3 returns, after the
    failsafe delay's hold. (Starts just above a raised threshold, so that a few seconds of
    hover drain it.)"""
    from ..conftest import sim_with

    config = sim_with(no_camera_config, **{"battery.initial_fraction": 0.205,
                                           "battery.low_fraction": 0.12,
                                           "battery.critical_fraction": 0.20})

    async def main():
        async with flight(config, COM_LOW_BAT_ACT=action, COM_FAIL_ACT_T=1.0) as (drv, rec):
            await drv.arm()
            await drv.takeoff(3.0)
            state = await wait_for_state(drv, lambda s: s.battery.remaining_fraction <= 0.20,
                                         60.0, "battery critical")
            assert state.in_air
            await drv.clock.sleep(1.0 + 0.5)  # COM_FAIL_ACT_T, then the action
            texts = [t for _, t in rec.texts]
            assert any("battery critical" in t for t in texts), texts
            if mode is None:
                assert drv.latest_state.mode is FlightMode.HOLD  # warned, nothing else
                assert not drv.latest_state.failsafe
            else:
                await wait_for_state(drv, lambda s: s.mode is mode and s.failsafe, 2.0,
                                     f"{mode.value} after the delay")

    run(main())


def test_camera_commands_and_trigger_distance_outside_missions(no_camera_config):
    """IMAGE_START_CAPTURE as a command (interval and count), and DO_SET_CAM_TRIGG_DIST while a
    companion computer flies in OFFBOARD: photos are not a mission-only thing."""
    async def main():
        async with flight(no_camera_config) as (drv, rec):
            await take_off(drv, 3.0)
            await drv.start_photos(1.0, 3)
            await drv.clock.sleep(4.0)
            times = [p.time_s for p in rec.photos]
            assert len(times) == 3
            assert np.diff(times) == pytest.approx([1.0, 1.0], abs=0.03)
            offboard = Offboard(drv)
            await offboard.start_holding_here()
            await drv.set_trigger_distance(4.0)
            offboard.setpoint = Setpoint.velocity_ned(2.0, 0.0, 0.0, yaw_rad=0.0)
            await drv.clock.sleep(10.0)  # about 18 m north
            await offboard.aclose()
            distance = [p for p in rec.photos[3:]]
            assert 3 <= len(distance) <= 5
            gaps = np.diff([p.position_ned_m[0] for p in distance])
            assert gaps == pytest.approx([4.0] * len(gaps), abs=0.2)

    run(main())


def test_a_takeoff_altitude_is_for_that_takeoff_only(no_camera_config):
    async def main():
        async with flight(no_camera_config) as (drv, _rec):
            default = drv.param("MIS_TAKEOFF_ALT")
            await take_off(drv, 4.0)
            assert drv.latest_state.altitude_m == pytest.approx(4.0 + 0.095, abs=0.2)  # home
            assert drv.param("MIS_TAKEOFF_ALT") == default  # NAV_TAKEOFF's altitude, not the
            # parameter (a ground station's 30 m takeoff must not raise every mission's)

    run(main())
