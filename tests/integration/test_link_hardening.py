"""The MAVLink drivers' link to a real vehicle, hardened: it locks onto the vehicle, ignores
other senders, takes only its own TIMESYNC answers, cleans up after every failed connect,
never sends a setpoint its caller gave up on, and signs (and checks) with a key.

Against the simulator's MAVLink face in real time, on loopback, bounded by timeouts."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import socket
import threading
from types import SimpleNamespace

import pytest
from pymavlink.dialects.v20 import common as mavlink

from autopilot.flight_ops import wait_for_state
from drivers.base import CommandDenied, CommandTimeout, ConnectionLost, Setpoint
from drivers.mavlink.link import LinkError, TimesyncRequests, UrlError
from drivers.mavlink.mavsdk_driver import MavsdkDriver
from drivers.mavlink.pymavlink_driver import PymavlinkDriver
from drivers.mavlink.signing import Signing

from .mavtools import CLIENT_URL, INSTANCE, collected, served

pytestmark = pytest.mark.serial  # the simulator's MAVLink face in real time

CLIENT_PORT = 14540 + INSTANCE
DRIVERS = [PymavlinkDriver, MavsdkDriver]


def _rogue() -> tuple[socket.socket, mavlink.MAVLink]:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    # it claims to be the vehicle itself: system 1, component 1
    return sock, mavlink.MAVLink(None, srcSystem=1, srcComponent=1)


async def _orphans() -> list[asyncio.Task]:
    await asyncio.sleep(0)
    return [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]


@pytest.mark.parametrize("driver_class", DRIVERS)
def test_a_second_sender_is_ignored_and_cannot_redirect_setpoints(no_camera_config, driver_class,
                                                                   caplog):
    async def main():
        async with served(no_camera_config) as (_vehicle, face):
            driver = driver_class(CLIENT_URL)
            await driver.connect(timeout_s=10.0)
            sock, mav = _rogue()
            watching = collected(driver.telemetry(buffer=64))
            states = await watching.__aenter__()
            try:
                with caplog.at_level(logging.WARNING):
                    for _ in range(20):
                        for msg in (mav.heartbeat_encode(2, 12, 129, 0x00060000, 4),
                                    mav.local_position_ned_encode(10**6, 1000.0, 1000.0, -50.0,
                                                                  0, 0, 0)):
                            sock.sendto(msg.pack(mav), ("127.0.0.1", CLIENT_PORT))
                        await asyncio.sleep(0.05)
                assert states, "no telemetry while the rogue was sending"
                assert all(abs(s.position_ned_m[0]) < 10.0 for s in states)
                assert driver._link.stats.ignored >= 40
                assert any("locked onto the vehicle" in r.getMessage() and "ignoring" in
                           r.getMessage() for r in caplog.records)
                # the setpoints still go to the vehicle, none to the rogue
                before = face.stats.setpoints
                for _ in range(5):
                    await driver.send_setpoint(Setpoint.velocity_ned(0.0, 0.0, 0.0))
                    await asyncio.sleep(0.05)
                await asyncio.sleep(0.3)
                assert face.stats.setpoints >= before + 5
                with pytest.raises(BlockingIOError):
                    sock.recv(4096)
            finally:
                await watching.__aexit__(None, None, None)
                sock.close()
                await driver.close()

    asyncio.run(main())


def test_timesync_answers_count_only_for_our_own_requests():
    requests = TimesyncRequests(keep=4)
    requests.sent(1_000, 1.0)
    assert requests.answer(999) is None  # someone else's exchange
    assert requests.answer(1_000) == 1.0
    assert requests.answer(1_000) is None  # answered once
    for ts1 in range(10):
        requests.sent(ts1, float(ts1))
    assert requests.answer(0) is None  # long forgotten
    assert requests.answer(9) == 9.0

    driver = PymavlinkDriver()
    answer = SimpleNamespace(tc1=5_000_000_000, ts1=123_456)
    driver._on_timesync(answer)
    assert not driver._boot.ready  # an answer to a request we never sent
    driver._timesync_sent.sent(123_456, driver.clock.now())
    driver._on_timesync(answer)
    assert driver._boot.ready


@pytest.mark.parametrize("driver_class", DRIVERS)
def test_connect_cleans_up_on_every_error(driver_class):
    async def main():
        # the port is taken
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
            taken.bind(("127.0.0.1", CLIENT_PORT))
            with pytest.raises(LinkError, match="address already in use"):
                await driver_class(CLIENT_URL).connect(timeout_s=1.0)
        assert await _orphans() == []
        # nobody there
        with pytest.raises(ConnectionLost, match=r"within 1 s"):
            await driver_class(CLIENT_URL).connect(timeout_s=1.0)
        assert await _orphans() == []
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as again:
            again.bind(("127.0.0.1", CLIENT_PORT))  # released
        # not a URL we know
        for url in ("bogus://x", "udpin://127.0.0.1", "serial://ttyUSB0", "tcp://host:port"):
            with pytest.raises(UrlError):
                await driver_class(url).connect(timeout_s=1.0)
        assert await _orphans() == []

    asyncio.run(main())


def test_a_setpoint_goes_out_at_once_whatever_mavsdk_s_threads_are_doing(no_camera_config):
    """Setpoints are encoded and sent on the event loop (a control tick never waits for a
    thread to be scheduled): with MAVSDK's sender thread held up, one still goes out at once."""
    async def main():
        async with served(no_camera_config) as (_vehicle, face):
            driver = MavsdkDriver(CLIENT_URL)
            await driver.connect(timeout_s=10.0)
            busy = threading.Event()
            try:
                driver._sender.submit(busy.wait, 5.0)  # the send thread is busy for a while
                before = face.stats.setpoints
                await asyncio.wait_for(driver.send_setpoint(
                    Setpoint.velocity_ned(1.0, 0.0, 0.0)), 0.01)
                for _ in range(50):
                    if face.stats.setpoints > before:
                        break
                    await asyncio.sleep(0.01)
                assert face.stats.setpoints == before + 1
                assert not busy.is_set()  # (it came while the thread was still busy)
            finally:
                busy.set()
                await driver.close()

    asyncio.run(main())


KEY = Signing(bytes(range(32)))
WRONG_KEY = Signing(bytes(range(1, 33)))


@pytest.mark.parametrize("driver_class", DRIVERS)
def test_signing_with_the_right_key_flies(no_camera_config, driver_class):
    async def main():
        async with served(no_camera_config, signing=KEY) as (vehicle, face):
            driver = driver_class(CLIENT_URL, signing=KEY)
            await driver.connect(timeout_s=10.0)
            try:
                await wait_for_state(driver, lambda s: s.health.armable, 30.0, "armable")
                await driver.arm()
                await wait_for_state(vehicle, lambda s: s.armed, 5.0, "armed")
                # setpoints signed beside MAVSDK's own (re-signed) frames: none taken for a
                # replay of the other stream's
                before = face.stats.setpoints
                for _ in range(60):
                    await driver.send_setpoint(Setpoint.velocity_ned(0.0, 0.0, 0.0))
                    await asyncio.sleep(0.005)
                await asyncio.sleep(0.3)
                assert face.stats.setpoints - before == 60
                await driver.disarm()
                assert face.stats.commands >= 2
                assert face.stats.bad_signature == 0
                assert driver._link.stats.bad_signature == 0
            finally:
                await driver.close()

    asyncio.run(main())


@pytest.mark.parametrize("driver_class", DRIVERS)
def test_signing_with_a_wrong_key_or_none_is_refused(no_camera_config, driver_class):
    async def main():
        async with served(no_camera_config, signing=KEY) as (vehicle, face):
            # a wrong key: the driver hears nothing it can trust, the vehicle obeys nothing
            with pytest.raises(ConnectionLost, match="wrong signature: is the signing key"):
                await driver_class(CLIENT_URL, signing=WRONG_KEY).connect(timeout_s=2.0)
            # no key at all: the driver hears the vehicle, but the vehicle drops what it sends
            keyless = driver_class(CLIENT_URL)
            await keyless.connect(timeout_s=10.0)
            try:
                await wait_for_state(keyless, lambda s: s.health.armable, 30.0, "armable")
                with pytest.raises(CommandTimeout):
                    await keyless.arm()
            finally:
                await keyless.close()
            sock, mav = _rogue()
            try:
                mav.srcSystem, mav.srcComponent = 255, 190
                for _ in range(3):  # an unsigned arm command
                    sock.sendto(mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
                                .pack(mav), ("127.0.0.1", face.ports["offboard"][0]))
                await asyncio.sleep(0.5)
            finally:
                sock.close()
            assert face.stats.bad_signature > 0
            assert face.stats.commands == 0
            assert not vehicle.latest_state.armed

    asyncio.run(main())


@pytest.mark.parametrize("driver_class", [
    PymavlinkDriver, pytest.param(MavsdkDriver, marks=pytest.mark.long)])
def test_a_lossy_link_still_flies(no_camera_config, driver_class):
    """The simulator's link_loss fault on its MAVLink face (from the arming on): 30 % of the
    datagrams lost each way, 10 % duplicated, 10 % reordered, 50 ms more latency. The driver
    keeps its telemetry (fewer samples, none out of order), and its commands (retried) still
    take the vehicle up and back down."""
    from autopilot.flight_ops import wait_for_state
    from drivers.base import FlightMode

    config = type(no_camera_config).model_validate({**no_camera_config.model_dump(), "faults": [
        {"kind": "link_loss", "fraction": 0.3, "duplicate": 0.1, "reorder": 0.1,
         "latency_s": 0.05}]})
    driver = None

    async def until(command, done, what: str) -> int:
        """A command sent again (as a mission step would) until the telemetry shows it done:
        at 30 % loss each way a command and its answer both get through half the time."""
        for attempt in range(1, 9):
            with contextlib.suppress(CommandTimeout, CommandDenied):
                await command()
            with contextlib.suppress(TimeoutError):
                await wait_for_state(driver, done, 3.0, what)
                return attempt
        raise AssertionError(f"{what}: not done after 8 attempts")

    async def main():
        nonlocal driver
        async with served(config) as (_vehicle, face):
            driver = driver_class(CLIENT_URL)
            await driver.connect(timeout_s=10.0)
            try:
                await wait_for_state(driver, lambda s: s.health.armable, 15.0, "armable")
                await until(driver.arm, lambda s: s.armed, "armed")
                async def takeoff() -> None:
                    # the vehicle disarms itself when it is not taken off soon after arming
                    # (PX4's COM_DISARM_PRFLT): with the takeoffs lost, arm it again first
                    state = driver.latest_state
                    if state is not None and not state.armed:
                        await driver.arm()
                    await driver.takeoff(2.0)

                async with collected(driver.telemetry(buffer=256)) as states:
                    await until(takeoff,
                                lambda s: s.mode is FlightMode.TAKEOFF or
                                -s.position_ned_m[2] > 0.5, "taking off")
                    await wait_for_state(driver, lambda s: -s.position_ned_m[2] > 1.7, 30.0,
                                         "climbed")
                    await until(driver.land, lambda s: s.mode is FlightMode.LAND, "landing")
                    await wait_for_state(driver, lambda s: not s.armed, 40.0, "landed")
                assert -states[-1].position_ned_m[2] < 0.3
                assert face.stats.link_dropped > 50
                stamps = [s.time_s for s in states]
                assert len(stamps) > 20
                assert all(b >= a for a, b in itertools.pairwise(stamps))  # reordered: dropped
                # ... by their boot-time stamps: copies and late ones were seen, and dropped
                assert driver.out_of_order_dropped > 0
            finally:
                await driver.close()

    asyncio.run(main())
