"""``autopilot sim --firmware ardrone``: the simulator as a stand-alone Parrot AR.Drone 2.0 that
speaks its SDK 2.0 protocol, as the real drone does on its Wi-Fi network — AT commands on UDP
5556, navdata on UDP 5554, H.264 video in PaVE frames on TCP 5555, its configuration on TCP
5559 — so that ``autopilot run --driver ardrone`` and the AR.Drone client libraries fly it
unmodified.

The drone's protocol engine is :class:`~drivers.sim.ardrone_face.ArdroneFace`; here are its
sockets. As the real drone: navdata goes to the address that last sent a datagram to 5554
(the client's wake-up), the video stream carries the camera ``video:video_channel`` selects,
the configuration is written to the 5559 connections when ``AT*CTRL=…,4,0`` asks for it. Unlike
the real drone (which answers anyone on its network), the ports listen on 127.0.0.1 by default
and, once a client's AT commands have been taken, commands and wake-ups from other hosts are
ignored (counted).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from autopilot.config import AppConfig
from autopilot.mission import Scenario
from autopilot.scenario import build_world
from drivers.ardrone.urls import ArdronePorts
from drivers.ardrone.video import PaveEncoder
from drivers.base import VehicleError
from drivers.mavlink.common import cancel_all
from drivers.sim.ardrone_engine import SimulatedArdrone
from drivers.sim.driver import SimDriver
from drivers.sim.link_impairment import LinkImpairment

SLOW_WARNING_EVERY_S = 10.0
#: the SDK's ports
SDK_PORTS = ArdronePorts()

__all__ = ["ArdronePorts", "ArdroneServer", "serve"]


class _Datagrams(asyncio.DatagramProtocol):
    def __init__(self, handle: Callable[[bytes, tuple], None]) -> None:
        self.handle = handle
        self.transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport) -> None:
        self.transport = transport

    def datagram_received(self, data: bytes, addr) -> None:
        self.handle(data, addr)


@dataclass
class ServerStats:
    """What the simulated drone's sockets have seen."""

    datagrams: int = 0
    ignored: int = 0  # datagrams and connections from hosts other than the client's
    link_dropped: int = 0  # lost to a link_loss fault (commands, navdata, video frames)


class ArdroneServer:
    """The simulated drone's sockets around its protocol engine, on a running
    :class:`~drivers.sim.driver.SimDriver` whose firmware is ``ardrone``."""

    def __init__(self, vehicle: SimDriver, *, host: str = "127.0.0.1",
                 ports: ArdronePorts = SDK_PORTS, log: Callable[[str], None] = print,
                 video: bool = True) -> None:
        self.vehicle = vehicle
        self.host = host
        self.ports = ports
        self.log = log
        self.video = video
        sim = vehicle.simulator
        self._sim = sim
        #: the drone's protocol engine on the simulator
        self.drone = SimulatedArdrone(vehicle)
        self.face = self.drone.face
        self._client_host: str | None = None
        self._navdata_addr: tuple | None = None
        self.stats = ServerStats()
        #: link_loss faults act here, on the datagrams both ways and on the video's frames
        self.impairment = LinkImpairment(vehicle, self.stats)
        sim.link_faults_in_face = True
        self._navdata: _Datagrams | None = None
        self._at: _Datagrams | None = None
        self._tasks: list[asyncio.Task] = []
        self._servers: list[asyncio.base_events.Server] = []
        self._config_writers: set[asyncio.StreamWriter] = set()

    # -- lifecycle ---------------------------------------------------------------------------

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        _, self._navdata = await loop.create_datagram_endpoint(
            lambda: _Datagrams(self._on_wake_up), local_addr=(self.host, self.ports.navdata))
        _, self._at = await loop.create_datagram_endpoint(
            lambda: _Datagrams(self._on_at), local_addr=(self.host, self.ports.at))
        self._servers.append(await asyncio.start_server(self._on_config_client, self.host,
                                                        self.ports.config))
        if self.video:
            self._servers.append(await asyncio.start_server(self._on_video_client, self.host,
                                                            self.ports.video))
        self.drone.start()
        self._tasks.append(loop.create_task(self._send_navdata(), name="ardrone-navdata"))

    async def close(self) -> None:
        await cancel_all(self._tasks)
        await self.drone.close()
        for server in self._servers:
            server.close()
        for writer in list(self._config_writers):
            writer.close()
        self.impairment.close()
        for endpoint in (self._navdata, self._at):
            if endpoint is not None and endpoint.transport is not None:
                endpoint.transport.close()

    # -- AT commands ------------------------------------------------------------------------

    def _accepts(self, addr) -> bool:
        host = addr[0]
        if self._client_host is None or host == self._client_host:
            return True
        self.stats.ignored += 1
        return False

    def _on_at(self, data: bytes, addr) -> None:
        if not self._accepts(addr):
            return
        self._client_host = addr[0]
        self.stats.datagrams += 1
        fault = self.impairment.fault()
        if fault is not None:
            self.impairment.carry(fault, lambda: self._take_at(data))
        else:
            self._take_at(data)

    def _take_at(self, data: bytes) -> None:
        self.drone.take(data)
        if self.face.take_config_request():
            self._write_config()

    # -- navdata ----------------------------------------------------------------------------

    def _on_wake_up(self, data: bytes, addr) -> None:
        if self._accepts(addr):
            self._navdata_addr = addr

    async def _send_navdata(self) -> None:
        async for packet in self.drone.navdata():
            addr = self._navdata_addr
            if addr is None or self._navdata is None or self._navdata.transport is None:
                continue
            transport = self._navdata.transport
            fault = self.impairment.fault()
            if fault is not None:
                self.impairment.carry(fault, lambda p=packet, a=addr, t=transport:
                                      t.sendto(p, a))
            else:
                transport.sendto(packet, addr)

    # -- configuration ----------------------------------------------------------------------

    async def _on_config_client(self, reader: asyncio.StreamReader,
                                writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        if peer is not None and not self._accepts(peer):
            writer.close()
            return
        self._config_writers.add(writer)
        try:
            while await reader.read(1024):
                pass
        except (ConnectionError, OSError):
            pass
        finally:
            self._config_writers.discard(writer)
            writer.close()

    def _write_config(self) -> None:
        text = self.face.config_text()
        for writer in list(self._config_writers):
            with contextlib.suppress(ConnectionError, OSError):
                writer.write(text)

    # -- video ------------------------------------------------------------------------------

    def _video_lost(self) -> bool:
        faults = self._sim.faults
        if faults and faults.video_lost(self._sim.fault_time_s()):
            self.stats.link_dropped += 1
            return True
        return False

    async def _on_video_client(self, reader: asyncio.StreamReader,
                               writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        if peer is not None and not self._accepts(peer):
            writer.close()
            return
        loop = asyncio.get_running_loop()
        executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ardrone-video")
        try:
            while True:
                camera = self.face.video_camera
                info = self.vehicle.cameras[camera]
                encoder = PaveEncoder(info.rate_hz)
                async with contextlib.aclosing(self.vehicle.frames(camera)) as frames:
                    async for frame in frames:
                        data = await loop.run_in_executor(executor, encoder.encode,
                                                          frame.image, frame.time_s)
                        if self._video_lost():
                            continue  # lost on the link: the decoder waits for a key frame
                        writer.write(data)
                        await writer.drain()
                        if self.face.video_camera != camera:
                            break  # video:video_channel switched the stream
                    else:
                        return
        except (ConnectionError, OSError, VehicleError):
            return
        finally:
            executor.shutdown(wait=False)
            writer.close()


async def serve(config: AppConfig, scenario: Scenario | None, *, host: str = "127.0.0.1",
                ports: ArdronePorts = SDK_PORTS, log: Callable[[str], None] = print,
                stop: asyncio.Event | None = None, video: bool = True,
                out_dir: Path | None = None,
                on_ready: Callable[[ArdroneServer], None] | None = None) -> None:
    """Serve a simulated AR.Drone until ``stop`` is set (Ctrl-C / SIGTERM when None); landed
    before it exits if a client left it flying. ``out_dir``: its ground truth recorded into
    ``out_dir/truth.mcap`` (for ``autopilot score``: the drone's PaVE timestamps are on the
    same clock, which a driver maps onto its own)."""
    import signal

    from autopilot.sim_server import record_truth

    sim_config, objects = build_world(scenario, config.sim, config)
    vehicle = SimDriver(sim_config, scenario=objects, lockstep=False,
                        warn_every_s=SLOW_WARNING_EVERY_S, shed_rendering=True, background=False)
    await vehicle.connect()
    server = ArdroneServer(vehicle, host=host, ports=ports, log=log, video=video)
    truth_log = truth = None
    if out_dir is not None:
        truth_log, truth = await record_truth(vehicle, out_dir, log)
    loop = asyncio.get_running_loop()
    handle_signals = stop is None
    stop = stop or asyncio.Event()
    try:
        await server.start()
        if handle_signals:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.add_signal_handler(sig, stop.set)
        log(f"AR.Drone 2.0-compatible simulated drone on {host}: AT commands udp {ports.at}, "
            f"navdata udp {ports.navdata}, video tcp {ports.video} (PaVE H.264), "
            f"configuration tcp {ports.config}; Ctrl-C to stop")
        if on_ready is not None:
            on_ready(server)
        await stop.wait()
        log("stopping")
        firmware = vehicle.simulator.flight
        if firmware.flying:
            log("drone still flying: landing before exit")
            with contextlib.suppress(VehicleError):
                await vehicle.runner.call(vehicle.simulator.command, "ref", False, False)
            for _ in range(300):
                if not firmware.armed:
                    break
                await asyncio.sleep(0.1)
    finally:
        if handle_signals:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)
        await server.close()
        if truth is not None:
            await cancel_all([truth])
        await vehicle.close()
        if truth_log is not None:
            truth_log.close()
