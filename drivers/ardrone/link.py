"""The AR.Drone 2.0 driver's link to its drone: the sockets, and nothing of what goes over them
(:class:`~drivers.ardrone.driver.ArdroneDriver` decides that).

:class:`UdpLink` is the drone on a network: AT commands to its UDP 5556; navdata from its UDP
5554 after a wake-up datagram, sent again every :data:`WAKE_UP_EVERY_S` while nothing arrives
(packets parsed: a bad checksum or a broken packet dropped and counted, datagrams from any host
but the drone's ignored and counted); its configuration over TCP 5559 once ``AT*CTRL=…,4,0``
asks for it; its video over TCP 5555 (:meth:`UdpLink.open_video`). Every socket is bound to
the local address that routes to the drone (loopback for a simulated drone on this host).

A link for the simulated drone in process (:mod:`drivers.sim.ardrone_driver`) implements the
same methods without sockets.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import Callable

from drivers.ardrone import at
from drivers.ardrone import navdata as nav
from drivers.ardrone.session import WAKE_UP
from drivers.ardrone.urls import ArdronePorts
from drivers.base import VehicleNotFound
from drivers.clock import Clock

log = logging.getLogger(__name__)

#: the wake-up is sent again while no navdata came for this long
WAKE_UP_EVERY_S = 0.5
#: the configuration's read: how long to wait for it, and the silence that ends it
CONFIG_READ_S = 2.0
CONFIG_IDLE_S = 0.3

#: what the link hands on: a navdata packet, parsed, and when it came (our clock)
OnNavdata = Callable[[nav.Navdata, float], None]


def _local_address(host_ip: str, port: int) -> str:
    """The local address the route to the drone leaves from (no datagram is sent)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.connect((host_ip, port))
        return probe.getsockname()[0]


class _Datagrams(asyncio.DatagramProtocol):
    def __init__(self, handle: Callable[[bytes, tuple], None]) -> None:
        self.handle = handle
        self.errors = 0

    def datagram_received(self, data: bytes, addr) -> None:
        self.handle(data, addr)

    def error_received(self, exc: Exception) -> None:  # (ICMP unreachable: no drone yet)
        self.errors += 1


class UdpLink:
    """The drone at ``host`` on its ``ports``; ``on_navdata`` gets each good navdata packet."""

    def __init__(self, host: str, ports: ArdronePorts, clock: Clock,
                 on_navdata: OnNavdata) -> None:
        self.host = host
        self.ports = ports
        self._clock = clock
        self._on_navdata = on_navdata
        self.drone_ip: str | None = None
        self.local_ip: str | None = None
        self._navdata: asyncio.DatagramTransport | None = None
        self._at: asyncio.DatagramTransport | None = None
        self._wake: asyncio.Task | None = None
        self.last_navdata_s: float | None = None
        #: the drone's configuration as it last sent it (empty: not read)
        self.config_text = b""
        #: counts, for statistics
        self.bad_packets = 0
        self.foreign_datagrams = 0

    @property
    def navdata_address(self) -> tuple[str, int] | None:
        """Where this end's navdata socket is (None: not open)."""
        return None if self._navdata is None else self._navdata.get_extra_info("sockname")

    async def open(self) -> None:
        """Open the sockets and start waking the navdata up (:class:`VehicleNotFound` when
        the drone's address does not resolve or route)."""
        loop = asyncio.get_running_loop()
        try:
            infos = await loop.getaddrinfo(self.host, self.ports.navdata,
                                           family=socket.AF_INET, type=socket.SOCK_DGRAM)
            self.drone_ip = infos[0][4][0]
            self.local_ip = _local_address(self.drone_ip, self.ports.at)
            self._navdata, _ = await loop.create_datagram_endpoint(
                lambda: _Datagrams(self._datagram), local_addr=(self.local_ip, 0))
            self._at, _ = await loop.create_datagram_endpoint(
                lambda: _Datagrams(lambda data, addr: None), local_addr=(self.local_ip, 0),
                remote_addr=(self.drone_ip, self.ports.at))
        except OSError as exc:
            await self.close()
            raise VehicleNotFound(f"AR.Drone at {self.host}: {exc}") from exc
        self._wake = loop.create_task(self._wake_up(), name="ardrone-wake-up")

    async def close(self) -> None:
        if self._wake is not None:
            self._wake.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._wake
            self._wake = None
        for transport in (self._navdata, self._at):
            if transport is not None:
                transport.close()
        self._navdata = self._at = None

    def send(self, commands: list[bytes]) -> None:
        """AT commands, packed into as few datagrams as the drone takes."""
        if self._at is None or not commands:
            return
        for datagram in at.datagrams(commands):
            self._at.sendto(datagram)

    async def _wake_up(self) -> None:
        while True:
            last = self.last_navdata_s
            if (last is None or self._clock.now() - last > WAKE_UP_EVERY_S) and \
                    self._navdata is not None:
                self._navdata.sendto(WAKE_UP, (self.drone_ip, self.ports.navdata))
            await self._clock.sleep(WAKE_UP_EVERY_S)

    def _datagram(self, data: bytes, addr) -> None:
        if addr[0] != self.drone_ip:
            self.foreign_datagrams += 1
            return
        now = self._clock.now()
        self.last_navdata_s = now
        try:
            packet = nav.parse(data)
        except nav.NavdataError:
            self.bad_packets += 1
            return
        self._on_navdata(packet, now)

    async def read_config(self, ask: Callable[[], bytes]) -> bytes:
        """The drone's configuration text (TCP 5559), asked for with ``ask()`` (an
        ``AT*CTRL=…,4,0``: again every 0.5 s while nothing comes, as datagrams get lost); empty
        if none came within :data:`CONFIG_READ_S`."""
        clock = self._clock
        try:
            reader, writer = await clock.wait_for(asyncio.open_connection(
                self.drone_ip, self.ports.config, local_addr=(self.local_ip, 0)),
                CONFIG_READ_S)
        except (OSError, TimeoutError) as exc:
            log.warning("AR.Drone at %s: no configuration (%s)", self.host, exc)
            return b""
        text = b""
        try:
            deadline = clock.now() + CONFIG_READ_S
            asked_s = -1e9
            while (remaining := deadline - clock.now()) > 0.0:
                if not text and clock.now() - asked_s >= 0.5:
                    self.send([ask()])
                    asked_s = clock.now()
                wait = min(remaining, CONFIG_IDLE_S if text else 0.5)
                try:
                    chunk = await clock.wait_for(reader.read(65536), wait)
                except TimeoutError:
                    if text:
                        break  # the whole text came (the drone sends it in one go)
                    continue
                if not chunk:
                    break
                text += chunk
        except OSError as exc:
            log.warning("AR.Drone at %s: configuration read failed (%s)", self.host, exc)
        finally:
            writer.close()
        self.config_text = text
        return text

    async def open_video(self) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        """A connection to the drone's video port."""
        return await asyncio.open_connection(self.drone_ip, self.ports.video,
                                             local_addr=(self.local_ip, 0))
