"""The ArduCopter face's reading of GUIDED targets and LANDING_TARGET, as ArduCopter's
``GCS_MAVLink_Copter.cpp`` and ``AC_PrecLand`` read them (docs/reference/ardupilot-mavlink.md
§3.2, §8), its parameter table's routing of ArduPilot's units into the flight code, and its
mode table."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from drivers.base import Battery, FlightMode, Health, LandedState, VehicleState
from drivers.geometry import quat_from_euler
from drivers.mavlink import px4
from drivers.mavlink.face_ardupilot_commands import (
    BODY_FRD,
    BODY_NED,
    LOCAL_FRD,
    LOCAL_NED,
    LOCAL_OFFSET_NED,
    guided_setpoint,
    landing_target_ned,
)
from drivers.sim.flight.arducopter import internal_values
from drivers.sim.flight.arducopter_modes import MODES, Flown, mode_name
from drivers.sim.flight.arducopter_nav import rtl_return_altitude_m, starts_with_takeoff
from drivers.sim.flight.arducopter_params import SPECS, si_limits
from drivers.sim.flight.params import Parameters

POS_ONLY, VEL_ONLY, POS_VEL = 0x0DF8, 0x0DC7, 0x0DC0
ZERO = (0.0, 0.0, 0.0)


def _state(position=(10.0, 5.0, -3.0), yaw=math.pi / 2, roll=0.0) -> VehicleState:
    return VehicleState(0.0, np.array(position), np.zeros(3),
                        np.array(quat_from_euler(roll, 0.0, yaw)), np.zeros(3), True,
                        FlightMode.OFFBOARD, LandedState.IN_AIR, math.nan,
                        Battery(16.0, 1.0, 1.0), Health())


def test_type_mask_selects_position_velocity_or_both():
    s = _state()
    sp = guided_setpoint(LOCAL_NED, POS_ONLY, (1.0, 2.0, -4.0), (9.0, 9.0, 9.0), ZERO, 0.0,
                         0.0, s)
    np.testing.assert_allclose(sp.position_ned_m, [1.0, 2.0, -4.0])
    assert np.isnan(sp.velocity_m_s).all()
    sp = guided_setpoint(LOCAL_NED, VEL_ONLY, (1.0, 2.0, -4.0), (1.0, 0.0, 0.0), ZERO, 0.0,
                         0.0, s)
    assert np.isnan(sp.position_ned_m).all()
    np.testing.assert_allclose(sp.velocity_m_s, [1.0, 0.0, 0.0])
    both = guided_setpoint(LOCAL_NED, POS_VEL, (1.0, 2.0, -4.0), (1.0, 0.0, 0.0), ZERO, 0.0,
                           0.0, s)
    assert np.isfinite(both.position_ned_m).all()
    assert np.isfinite(both.velocity_m_s).all()
    # ArduCopter: *any* ignored position axis ignores all three
    sp = guided_setpoint(LOCAL_NED, VEL_ONLY & ~0x3, (1.0, 2.0, -4.0), (1.0, 0.0, 0.0), ZERO,
                         0.0, 0.0, s)
    assert np.isnan(sp.position_ned_m).all()


@pytest.mark.parametrize("why", ["nan velocity", "force", "frame", "nothing"])
def test_what_arducopter_answers_with_a_stop(why):
    mask, frame, vel = VEL_ONLY, LOCAL_NED, (1.0, 0.0, 0.0)
    if why == "nan velocity":
        vel = (math.nan, 0.0, 0.0)
    elif why == "force":
        mask = 0x0C07 & ~0x1C0 | 0x200  # acceleration with FORCE
    elif why == "frame":
        frame = 6  # GLOBAL_RELATIVE_ALT_INT in a LOCAL_NED message
    else:
        mask = 0x0FFF
    sp = guided_setpoint(frame, mask, ZERO, vel, ZERO, 0.0, 0.0, _state())
    np.testing.assert_allclose(sp.velocity_m_s, [0.0, 0.0, 0.0])  # brake and hold
    assert np.isnan(sp.position_ned_m).all()


def test_offset_and_body_frames_are_relative_to_the_vehicle():
    s = _state(yaw=math.pi / 2)  # facing east
    sp = guided_setpoint(LOCAL_OFFSET_NED, POS_ONLY, (1.0, 0.0, 0.0), ZERO, ZERO, 0.0, 0.0, s)
    np.testing.assert_allclose(sp.position_ned_m, [11.0, 5.0, -3.0])
    sp = guided_setpoint(BODY_NED, POS_ONLY & ~px4.IGNORE_YAW, (2.0, 0.0, -1.0), ZERO, ZERO,
                         0.5, 0.0, s)
    np.testing.assert_allclose(sp.position_ned_m, [10.0, 7.0, -4.0], atol=1e-9)  # 2 m ahead
    assert sp.yaw_rad == pytest.approx(math.pi / 2 + 0.5)  # yaw relative in body frames
    sp = guided_setpoint(BODY_NED, VEL_ONLY, ZERO, (1.0, 0.0, 0.0), ZERO, 0.0, 0.0, s)
    np.testing.assert_allclose(sp.velocity_m_s, [0.0, 1.0, 0.0], atol=1e-9)


def test_landing_target_in_local_and_body_frd_becomes_a_world_position():
    s = _state(position=(0.0, 0.0, -5.0), yaw=math.pi / 2)
    local = SimpleNamespace(frame=LOCAL_FRD, position_valid=1, x=1.0, y=0.0, z=5.0,
                            angle_x=0.0, angle_y=0.0, distance=0.0)
    np.testing.assert_allclose(landing_target_ned(local, s), [0.0, 1.0, 0.0], atol=1e-9)
    tilted = _state(position=(0.0, 0.0, -5.0), yaw=0.0, roll=math.radians(10))
    body = SimpleNamespace(frame=BODY_FRD, position_valid=1, x=0.0, y=0.0, z=5.0,
                           angle_x=0.0, angle_y=0.0, distance=0.0)
    ned = landing_target_ned(body, tilted)
    assert ned[1] == pytest.approx(-5.0 * math.sin(math.radians(10)), abs=1e-6)
    # angles with a distance: a line of sight (x right in the image is +y in FRD)
    angles = SimpleNamespace(frame=BODY_FRD, position_valid=0, x=0.0, y=0.0, z=0.0,
                             angle_x=math.atan(0.2), angle_y=0.0, distance=5.0)
    ned = landing_target_ned(angles, _state(position=(0.0, 0.0, -5.0), yaw=0.0))
    assert ned[1] > 0.9
    angles.distance = 0.0  # no distance and no rangefinder: no measurement
    assert landing_target_ned(angles, s) is None


def test_arducopter_units_reach_the_flight_code():
    values = {name: spec.default for name, spec in SPECS.items()}
    values.update(WPNAV_SPEED=500.0, RTL_ALT=2500, LAND_SPEED=70, ANGLE_MAX=2000,
                  FS_GCS_ENABLE=1, FENCE_ENABLE=1, FENCE_RADIUS=80.0, FENCE_TYPE=3)
    out = internal_values(values, si_limits(values))
    assert out["MPC_XY_CRUISE"] == pytest.approx(5.0)  # cm/s → m/s
    assert out["RTL_RETURN_ALT"] == pytest.approx(25.0)  # cm → m
    assert out["MPC_LAND_SPEED"] == pytest.approx(0.7)
    assert out["MPC_TILTMAX_AIR"] == pytest.approx(20.0)  # cdeg → deg
    assert out["NAV_DLL_ACT"] == 2  # RTL
    assert out["GF_MAX_HOR_DIST"] == 80.0
    assert out["GF_ACTION"] == 3  # FENCE_ACTION 1: RTL
    values["FENCE_ENABLE"] = 0
    assert internal_values(values, si_limits(values))["GF_ACTION"] == 0


def test_rtl_return_altitude_follows_mode_rtl():
    params = Parameters(specs=SPECS.values())
    si = si_limits(params.snapshot())
    home = np.zeros(3)
    # far from home, low: climbs to RTL_ALT (15 m)
    assert rtl_return_altitude_m(params, si, np.array([100.0, 0.0, -5.0]), home) == 15.0
    # 2 m from home at 5 m: the cone (slope 3 → 6 m) but at least 2.5 m above now (7.5 m)
    assert rtl_return_altitude_m(params, si, np.array([2.0, 0.0, -5.0]), home) == 7.5
    # higher than RTL_ALT: returns where it is
    assert rtl_return_altitude_m(params, si, np.array([100.0, 0.0, -30.0]), home) == 30.0


def test_mode_table():
    assert mode_name(4) == "GUIDED"
    assert mode_name(21) == "SMARTRTL"
    assert mode_name(99) == "Mode(99)"
    assert MODES[next(m for m in MODES if m.name == "RTL")].gcs_arm is False
    assert {m.name for m, spec in MODES.items() if spec.flown is Flown.PILOT} >= {
        "STABILIZE", "ALT_HOLD", "ACRO", "POSHOLD"}
    assert starts_with_takeoff([178, 22, 16])  # a DO item first, then the takeoff
    assert not starts_with_takeoff([16, 22])
