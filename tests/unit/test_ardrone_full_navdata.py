"""Full navdata (``general:navdata_demo`` FALSE): the options at their ``navdata_common.h``
sizes in tag order (checked by pyardrone's own parser, which refuses any other size), the
simulated drone's engine switching to 200 Hz and filling what it models, and the driver's
session asking for full mode and reading its packets."""

import math
from ctypes import sizeof

import numpy as np
import pytest

from drivers.ardrone import at, navdata
from drivers.ardrone.config import DroneConfig
from drivers.ardrone.navdata import ControlState, Demo, State, Tag
from drivers.ardrone.session import FULL_OPTIONS, NavdataSession
from drivers.base import Battery, FlightMode, Health, LandedState, VehicleState
from drivers.sim.ardrone_face import DEMO_RATE_HZ, FULL_RATE_HZ, ArdroneFace
from drivers.sim.flight.ardrone import ArdroneLimits, FirmwareStatus
from drivers.sim.schedule import Schedule

DEMO = Demo(ControlState.FLYING << 16, 80, 1500.0, -2500.0, 90000.0, 1234, 300.0, -200.0,
            50.0)


def _state(time_s=12.5, roll=0.1, pitch=-0.05, yaw=0.3, height=1.2):
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    q = (cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
         cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy)
    return VehicleState(time_s=time_s, position_ned_m=np.array([1.0, 2.0, -height]),
                        velocity_ned_m_s=np.array([0.4, -0.1, 0.05]), attitude_q=np.array(q),
                        angular_velocity_frd_rad_s=np.array([0.1, 0.0, -0.2]), armed=True,
                        mode=FlightMode.OFFBOARD, landed_state=LandedState.IN_AIR,
                        distance_to_ground_m=height, battery=Battery(11.5, 1.0, 0.7),
                        health=Health())


STATUS = FirmwareStatus(ControlState.FLYING, True, False, False, False)


def test_known_options_go_at_their_sizes_in_tag_order_and_read_back():
    packet = navdata.build(State.FLY, 3, DEMO, options={Tag.WIFI: b"", Tag.TIME: b"\x01"})
    got = navdata.parse(packet)
    assert list(got.options) == [Tag.DEMO, Tag.TIME, Tag.WIFI]  # in tag order
    assert len(got.options[Tag.TIME]) == navdata.OPTION_SIZES[Tag.TIME] - 4
    assert got.options[Tag.TIME] == b"\x01\x00\x00\x00"  # padded with zeros
    assert got.demo == DEMO
    with pytest.raises(ValueError, match="its size is 8"):
        navdata.build(0, 1, options={Tag.TIME: bytes(5)})


def test_every_option_of_the_full_mask_as_pyardrone_reads_it():
    pyardrone = pytest.importorskip("pyardrone.navdata")
    from pyardrone.navdata.options import index

    # the size table agrees with an independent transcription of navdata_common.h
    assert {int(t): sizeof(index[int(t)]) for t in Tag} == navdata.OPTION_SIZES
    face = ArdroneFace(command=lambda *c: None, limits=ArdroneLimits(), config=DroneConfig())
    for key, value in (("general:navdata_options", navdata.FULL_MASK),
                       ("general:navdata_demo", False)):
        face.on_datagram(at.AtCommands().config(key, value))
    packet = face.navdata(_state(), STATUS)
    parsed = pyardrone.NavData(packet)  # raises on a size, an order or the checksum
    assert not parsed.metadata.state & State.NAVDATA_DEMO
    assert parsed.altitude.altitude_vision == 1200
    assert parsed.demo.altitude == 1200
    assert parsed.eular_angles.phi_a == pytest.approx(math.degrees(0.1) * 1000, rel=1e-4)
    assert parsed.magneto.heading_fusion_unwrapped == pytest.approx(math.degrees(0.3), rel=1e-4)
    assert parsed.phys_measures.phys_gyros[2] == pytest.approx(math.degrees(-0.2), rel=1e-4)
    assert navdata.time_seconds(parsed.time.time) == pytest.approx(12.5, abs=1e-6)


def test_the_accelerometers_read_gravity_on_the_drone_axes():
    face = ArdroneFace(command=lambda *c: None, limits=ArdroneLimits(), config=DroneConfig())
    c = at.AtCommands()
    face.on_datagram(c.config("general:navdata_options", navdata.option_mask(Tag.PHYS_MEASURES)))
    face.on_datagram(c.config("general:navdata_demo", True))
    level = navdata.parse(face.navdata(_state(roll=0.0, pitch=0.0), STATUS))
    accs = np.frombuffer(level.options[Tag.PHYS_MEASURES][6:18], dtype="<f4")
    assert accs == pytest.approx([0.0, 0.0, -1000.0], abs=1e-3)  # at rest z reads -1 g
    nose_up = navdata.parse(face.navdata(_state(roll=0.0, pitch=0.2), STATUS))
    accs = np.frombuffer(nose_up.options[Tag.PHYS_MEASURES][6:18], dtype="<f4")
    assert accs[0] == pytest.approx(1000.0 * math.sin(0.2), rel=1e-4)


def test_the_rate_follows_the_mode_and_demo_mode_adds_the_masked_options():
    face = ArdroneFace(command=lambda *c: None, limits=ArdroneLimits(), config=DroneConfig())
    assert face.navdata_rate_hz == DEMO_RATE_HZ  # bootstrap
    c = at.AtCommands()
    face.on_datagram(c.config("general:navdata_demo", True))
    assert face.navdata_rate_hz == DEMO_RATE_HZ
    demo = navdata.parse(face.navdata(_state(), STATUS))
    # navdata_options' default (65537): the demo and vision-detect options
    assert set(demo.options) == {Tag.DEMO, Tag.VISION_DETECT}
    face.on_datagram(c.config("general:navdata_demo", False))
    assert face.navdata_rate_hz == FULL_RATE_HZ
    face.on_datagram(c.config("general:navdata_options", navdata.option_mask(Tag.TIME)))
    full = navdata.parse(face.navdata(_state(), STATUS))
    assert set(full.options) == {Tag.TIME}  # full mode: only what the mask selects
    assert full.demo is None


def test_the_time_word_keeps_seconds_in_11_bits_and_microseconds_in_21():
    assert navdata.time_word(3.25) == (3 << 21) | 250000
    assert navdata.time_seconds(navdata.time_word(2047.999999)) == pytest.approx(2047.999999)
    assert navdata.time_seconds(navdata.time_word(2049.5)) == pytest.approx(1.5)  # wraps


def test_the_session_asks_for_full_navdata_and_reads_it_from_the_engine():
    face = ArdroneFace(command=lambda *c: None, limits=ArdroneLimits(), config=DroneConfig())
    session = NavdataSession(at.AtCommands(), mode="full")
    used = []
    for k in range(12):
        step = session.on_packet(navdata.parse(face.navdata(_state(time_s=k / 15), STATUS)),
                                 k / 15)
        for datagram in step.commands:
            face.on_datagram(datagram)
        if step.navdata is not None:
            used.append(step.navdata)
    assert face.config.get_int("general:navdata_options") == FULL_OPTIONS
    assert face.config.get_bool("general:navdata_demo") is False
    assert face.navdata_rate_hz == FULL_RATE_HZ
    assert used
    last = used[-1]
    assert last.demo is not None
    assert last.demo.altitude_mm == 1200
    assert navdata.option_altitude(last)[3] == 1200
    assert navdata.option_time_s(last) == pytest.approx(11 / 15, abs=1e-6)
    with pytest.raises(ValueError, match="expected 'demo'"):
        NavdataSession(at.AtCommands(), mode="fast")


def test_a_schedule_retimed_keeps_its_grid_from_then_on():
    s = Schedule(10.0)
    for step in range(0, 31, 10):
        s.advance(step)
    assert s.next_step == 40
    s.retime(2.0, 33)  # faster from step 33
    assert s.next_step == 33
    steps = []
    while s.next_step < 40:
        steps.append(s.next_step)
        s.advance(s.next_step)
    assert steps == [33, 35, 37, 39]
