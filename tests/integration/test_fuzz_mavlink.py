"""Fuzzing MAVLink at the link's edges (Hypothesis): datagrams of random bytes, valid packets
truncated, with a broken checksum, oversized, duplicated, or addressed to another system,
thrown at the simulator's MAVLink face (its offboard and ground-station ports) and at each
driver's port while a driver flies it. Nothing crashes: the face goes on answering commands,
the driver goes on receiving telemetry and being obeyed."""

from __future__ import annotations

import asyncio
import contextlib
import socket

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink

from autopilot.flight_ops import wait_for_state
from drivers.mavlink.mavsdk_driver import MavsdkDriver
from drivers.mavlink.pymavlink_driver import PymavlinkDriver

from .mavtools import CLIENT_URL, INSTANCE, collected, served

pytestmark = pytest.mark.serial  # the simulator's MAVLink face in real time

_MAV = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
_VALID = [
    _MAV.heartbeat_encode(2, 12, 129, 0x00060000, 4).pack(_MAV),
    _MAV.command_long_encode(1, 1, 400, 0, 0, 21196, 0, 0, 0, 0, 0).pack(_MAV),  # kill, forced
    _MAV.command_long_encode(99, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(_MAV),  # another system
    _MAV.set_position_target_local_ned_encode(0, 1, 1, 1, 0b110111111000, 100.0, 100.0, -50.0,
                                              0, 0, 0, 0, 0, 0, 0, 0).pack(_MAV),
    _MAV.param_set_encode(1, 1, b"COM_OF_LOSS_T", 0.0, 9).pack(_MAV),
    _MAV.local_position_ned_encode(10**6, 1000.0, 1000.0, -50.0, 0, 0, 0).pack(_MAV),
]


def _mutations():
    valid = st.sampled_from(_VALID)
    return st.one_of(
        st.binary(max_size=300),  # noise
        st.builds(lambda p, n: p[:n], valid, st.integers(0, 40)),  # truncated
        st.builds(lambda p, i, b: p[:i % len(p)] + bytes([b]) + p[i % len(p) + 1:],
                  valid, st.integers(0, 400), st.integers(0, 255)),  # one byte changed (CRC)
        st.builds(lambda p, n: p * n, valid, st.integers(2, 40)),  # several in one datagram
        st.builds(lambda p, extra: p + extra, valid, st.binary(min_size=200, max_size=1200)),
        st.just(b"\xfd" + b"\xff" * 1400),  # a v2 start with an oversized length
    )


@pytest.mark.parametrize("driver_class", [PymavlinkDriver, MavsdkDriver])
def test_garbage_at_the_face_and_the_driver_changes_nothing(no_camera_config, driver_class):
    async def main():
        async with served(no_camera_config) as (_vehicle, face):
            driver = driver_class(CLIENT_URL)
            await driver.connect(timeout_s=10.0)
            rogue = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            rogue.bind(("127.0.0.1", 0))
            targets = [("127.0.0.1", face.ports["offboard"][0]),
                       ("127.0.0.1", face.ports["gcs"][0]),
                       ("127.0.0.1", 14540 + INSTANCE)]
            sent = [0]

            @settings(deadline=None, max_examples=150, derandomize=True)
            @given(_mutations(), st.sampled_from(targets))
            def throw(datagram, target):
                with contextlib.suppress(OSError):  # (too large for a datagram: refused)
                    rogue.sendto(datagram, target)
                    sent[0] += 1

            watching = collected(driver.telemetry(buffer=64))
            states = await watching.__aenter__()
            try:
                # the garbage goes out from a thread while the loop serves both ends
                await asyncio.to_thread(throw)
                assert sent[0] >= 100
                received = len(states)
                # (the vehicle answers the last sender, as PX4 does: a rogue's valid frame
                # takes the stream until the driver's next message, its 1 Hz heartbeat; on a
                # loaded machine that can be late)
                await asyncio.sleep(1.0)
                for _ in range(40):
                    if len(states) > received:
                        break
                    await asyncio.sleep(0.1)
                assert len(states) > received, "telemetry stopped"
                assert all(abs(s.position_ned_m[0]) < 10.0 for s in states)
                state = states[-1]
                assert not state.armed  # (the forged kill and arming changed nothing)
                # the vehicle still obeys its driver (armed once it says it is armable, as a
                # ground station does: a simulator slowed by a busy machine may not have
                # reached its estimator's init_time_s yet — "preflight checks failed")
                await wait_for_state(driver, lambda s: s.health.armable, 30.0, "armable")
                await driver.arm()
                await driver.takeoff(2.0)
                await wait_for_state(driver, lambda s: s.altitude_m > 1.5, 30.0, "climb")
                await driver.land()
                await wait_for_state(driver, lambda s: not s.armed, 60.0, "landed")
                assert face.stats.received > 0
            finally:
                await watching.__aexit__(None, None, None)
                rogue.close()
                await driver.close()

    asyncio.run(main())
