"""The MAVLink link's pieces on their own: URLs, signing's clock and forgery resistance, host
names, a TCP vehicle that reconnects, a serial port that hangs up or cannot keep up."""

from __future__ import annotations

import asyncio
import os
import socket
import tty

import pytest
from pymavlink.dialects.v20 import common as mavlink

from drivers.mavlink.link import MAX_PENDING_B, Endpoint, MavlinkLink, UrlError
from drivers.mavlink.signing import Signing, refresh, signing_timestamp

pytestmark = pytest.mark.serial  # MAVLink links on fixed ports

KEY = Signing(bytes(range(32)))


@pytest.mark.parametrize(("url", "expected"), [
    ("udpin://127.0.0.1:14540", Endpoint("udpin", "127.0.0.1", 14540)),
    ("udp://:14540", Endpoint("udpin", "127.0.0.1", 14540)),
    ("udpout://10.0.0.2:14550", Endpoint("udpout", "10.0.0.2", 14550)),
    ("tcp://127.0.0.1:5760", Endpoint("tcpout", "127.0.0.1", 5760)),
    ("tcpin://0.0.0.0:5760", Endpoint("tcpin", "0.0.0.0", 5760)),
    ("serial:///dev/ttyAMA0:921600", Endpoint("serial", device="/dev/ttyAMA0", baud=921600)),
    ("serial:///dev/ttyUSB0", Endpoint("serial", device="/dev/ttyUSB0", baud=57600)),
    ("serial:///dev/serial/by-path/platform-usb-0:1.3:1.0-port0:115200",
     Endpoint("serial", device="/dev/serial/by-path/platform-usb-0:1.3:1.0-port0",
              baud=115200)),
])
def test_urls(url, expected):
    assert Endpoint.parse(url) == expected


@pytest.mark.parametrize("url", ["bogus://x", "udpin://127.0.0.1", "tcp://host:port",
                                 "serial://ttyUSB0", "serial:///dev/ttyUSB0:1234", ""])
def test_bad_urls(url):
    with pytest.raises(UrlError):
        Endpoint.parse(url)


def _pair():
    tx = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    rx = mavlink.MAVLink(None, srcSystem=245, srcComponent=191)
    rx.robust_parsing = True
    KEY.apply(tx, mavlink.MAVLink(None))
    KEY.apply(mavlink.MAVLink(None), rx)
    return tx, rx


def test_a_sender_keeps_its_signing_clock_on_time():
    tx, rx = _pair()
    tx.signing.timestamp = signing_timestamp() - 100 * 60 * 100_000  # 100 minutes behind
    refresh(tx)
    assert tx.signing.timestamp >= signing_timestamp() - 100_000
    msgs = rx.parse_buffer(tx.heartbeat_encode(2, 12, 0, 0, 3).pack(tx))
    assert [m.get_type() for m in msgs] == ["HEARTBEAT"]  # a listener that started late


def test_a_forged_frame_cannot_block_the_genuine_stream():
    tx, rx = _pair()
    forger = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)  # the vehicle's ids ...
    Signing(bytes(32)).apply(forger, mavlink.MAVLink(None))  # ... a wrong key
    forger.signing.timestamp = (1 << 47) - 10  # and a far-future time
    forged = rx.parse_buffer(forger.heartbeat_encode(2, 12, 0, 0, 3).pack(forger))
    assert [m.get_type() for m in forged] == ["BAD_DATA"]
    refresh(tx)
    genuine = rx.parse_buffer(tx.heartbeat_encode(2, 12, 0, 0, 3).pack(tx))
    assert [m.get_type() for m in genuine] == ["HEARTBEAT"]
    replay = rx.parse_buffer(tx.heartbeat_encode(2, 12, 0, 0, 3).pack(tx))  # newer: fine
    assert [m.get_type() for m in replay] == ["HEARTBEAT"]


def test_udpout_to_a_host_name_locks_onto_its_address():
    async def main():
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as vehicle:
            vehicle.bind(("127.0.0.1", 0))
            port = vehicle.getsockname()[1]
            got = []
            link = await MavlinkLink.open(f"udpout://localhost:{port}",
                                          lambda msg, addr: got.append(msg))
            try:
                assert link.locked == ("127.0.0.1", port)
                mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
                link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 4))
                _, client = vehicle.recvfrom(1024)
                vehicle.sendto(mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav), client)
                await asyncio.sleep(0.2)
                assert [m.get_type() for m in got] == ["HEARTBEAT"]
            finally:
                link.close()

    asyncio.run(main())


def test_tcpin_takes_the_vehicles_next_connection_after_a_reset():
    async def main():
        link = await MavlinkLink.open("tcpin://127.0.0.1:15761", lambda msg, addr: None)
        try:
            first = socket.create_connection(("127.0.0.1", 15761))
            await asyncio.sleep(0.1)
            assert link._transport is not None
            first.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00"
                             b"\x00\x00")  # close with a reset
            first.close()
            await asyncio.sleep(0.2)
            assert link._transport is None
            second = socket.create_connection(("127.0.0.1", 15761))
            await asyncio.sleep(0.1)
            assert link._transport is not None  # taken, not refused as "a second connection"
            second.close()
        finally:
            link.close()

    asyncio.run(main())


def test_a_serial_port_that_hangs_up_stops_being_read():
    async def main():
        master, slave = os.openpty()
        tty.setraw(master)
        link = await MavlinkLink.open(f"serial://{os.ttyname(slave)}:115200",
                                      lambda msg, addr: None)
        os.close(slave)
        try:
            os.close(master)  # the other end goes away
            await asyncio.sleep(0.2)
            loop = asyncio.get_running_loop()
            with pytest.raises(KeyError):
                loop._selector.get_key(link._serial_fd)  # no reader left spinning
        finally:
            link.close()

    asyncio.run(main())


def test_a_serial_port_that_cannot_keep_up_drops_new_frames_not_memory():
    async def main():
        master, slave = os.openpty()
        tty.setraw(master)
        link = await MavlinkLink.open(f"serial://{os.ttyname(slave)}:57600",
                                      lambda msg, addr: None)
        os.close(slave)
        try:
            for _ in range(5000):  # nobody reads the other end
                link.send(link.mav.heartbeat_encode(18, 8, 0, 0, 4))
            assert link.stats.dropped_out > 0
            assert len(link._serial_out) <= MAX_PENDING_B + 64
        finally:
            link.close()
            os.close(master)

    asyncio.run(main())
