"""``autopilot sim --firmware ardrone`` at the protocol level, in real time: a client made of
raw sockets and the project's codecs (no driver) wakes the navdata up, leaves the bootstrap
mode, reads the configuration over TCP 5559, takes off, flies a progressive command, reads
PaVE H.264 video from TCP 5555 on both channels, and lands; commands from another host are
ignored. The margins allow a busy machine (the simulator slows as a whole there)."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import time

import pytest

from autopilot.ardrone_server import ArdroneServer, serve
from autopilot.config import load_config
from drivers.ardrone import at
from drivers.ardrone import navdata as nav
from drivers.ardrone.config import parse_config_text
from drivers.ardrone.navdata import ControlState, State
from drivers.ardrone.pave import PaveReader
from drivers.ardrone.session import WAKE_UP, NavdataSession
from drivers.ardrone.urls import ArdronePorts
from drivers.ardrone.video import PaveDecoder

pytestmark = pytest.mark.serial

PORTS = ArdronePorts().offset(200)
HOST = "127.0.0.1"


class Client:
    """The client's side, by hand: AT commands out, navdata in, through the session."""

    def __init__(self) -> None:
        self.at = at.AtCommands()
        self.session = NavdataSession(self.at)
        self.at_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.nav_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.nav_sock.bind((HOST, 0))
        self.nav_sock.setblocking(False)
        self.latest: nav.Navdata | None = None
        self.packets = 0

    def send(self, *commands: bytes) -> None:
        for datagram in at.datagrams(list(commands)):
            self.at_sock.sendto(datagram, (HOST, PORTS.at))

    def wake_up(self) -> None:
        self.nav_sock.sendto(WAKE_UP, (HOST, PORTS.navdata))

    def poll(self) -> None:
        while True:
            try:
                data = self.nav_sock.recv(4096)
            except BlockingIOError:
                return
            packet = nav.parse(data)
            self.packets += 1
            self.latest = packet
            step = self.session.on_packet(packet, time.monotonic())
            if step.commands:
                self.send(*step.commands)

    def close(self) -> None:
        self.at_sock.close()
        self.nav_sock.close()


async def _until(client: Client, condition, timeout_s: float, what: str,
                 command=None) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        client.poll()
        if client.latest is not None and condition(client.latest):
            return
        if command is not None:
            client.send(command())
        await asyncio.sleep(0.03)
    raise AssertionError(f"{what}: not within {timeout_s:g} s (last: {client.latest})")


async def _read_video(reader: asyncio.StreamReader, frames_wanted: int,
                      timeout_s: float) -> list:
    pave, decoder, out = PaveReader(), PaveDecoder(), []
    end = time.monotonic() + timeout_s
    while len(out) < frames_wanted and time.monotonic() < end:
        data = await asyncio.wait_for(reader.read(65536), timeout=max(0.1, end - time.monotonic()))
        if not data:
            break
        for header, payload in pave.feed(data):
            out.extend(decoder.decode(header, payload))
    return out


def test_a_raw_client_flies_the_simulated_drone() -> None:
    asyncio.run(_fly())


async def _fly() -> None:
    stop = asyncio.Event()
    ready: asyncio.Future[ArdroneServer] = asyncio.get_running_loop().create_future()
    config = load_config(None, ["sim.firmware=ardrone"])
    task = asyncio.create_task(serve(config, None, ports=PORTS, log=lambda line: None,
                                     stop=stop, on_ready=ready.set_result))
    client = Client()
    try:
        server = await asyncio.wait_for(ready, 120)
        # bootstrap: the header alone, until the client asks for demo navdata
        client.wake_up()
        await _until(client, lambda p: State.NAVDATA_BOOTSTRAP in p.state, 20, "bootstrap",
                     command=lambda: client.at.comwdg())
        await _until(client, lambda p: p.demo is not None and State.COMMAND not in p.state,
                     20, "demo navdata, acknowledged")
        assert client.session.demo
        assert client.latest.demo.major_state is ControlState.LANDED

        # the configuration over TCP 5559 when CTRL 4 asks for it
        reader, writer = await asyncio.open_connection(HOST, PORTS.config)
        await asyncio.sleep(0.2)
        client.send(client.at.ctrl(4))
        text = b""
        with contextlib.suppress(TimeoutError):
            while b"video:video_channel" not in text or not text.endswith(b"\n"):
                text += await asyncio.wait_for(reader.read(65536), 5)
        writer.close()
        values = parse_config_text(text)
        assert values["control:euler_angle_max"] == pytest.approx(0.20943999)
        assert values["general:navdata_demo"] is True

        # take off: about 1 m, hovering
        await _until(client, lambda p: p.demo.major_state is ControlState.HOVERING, 30,
                     "takeoff", command=lambda: client.at.ref(takeoff=True))
        await _until(client, lambda p: p.demo.altitude_mm > 700, 10, "a metre up",
                     command=lambda: client.at.ref(takeoff=True))
        assert State.FLY in client.latest.state

        # a progressive pitch forward: the drone reports flying and a forward speed
        def forward() -> bytes:
            return client.at.pcmd(0.0, -0.5, 0.0, 0.0)

        await _until(client, lambda p: p.demo.vx_mm_s > 300, 15, "flying forward",
                     command=forward)
        assert client.latest.demo.major_state is ControlState.FLYING
        truth = server.vehicle.simulator.ground_truth()
        assert truth.vehicle.velocity_ned_m_s[0] > 0.2  # north: the drone faces north

        # video: the front camera, then the bottom one after video:video_channel 1
        reader, writer = await asyncio.open_connection(HOST, PORTS.video)
        frames = await _read_video(reader, 3, 30)
        assert len(frames) == 3
        assert frames[0].image.shape == (360, 640, 3)
        client.send(client.at.config_ids(*("00000000",) * 3),
                    client.at.config("video:video_channel", 1))
        frames = []
        end = time.monotonic() + 30
        while time.monotonic() < end and not any(f.image.shape[:2] == (240, 320)
                                                 for f in frames):
            client.poll()
            client.send(client.at.pcmd(0, 0, 0, 0, hover=True))
            frames = await _read_video(reader, 1, 5)
        writer.close()
        assert any(f.image.shape == (240, 320, 3) for f in frames)

        # another host's commands are ignored (this client locked the drone first)
        ignored = server.stats.ignored
        server._on_at(client.at.ref(emergency=True), ("10.9.9.9", 5556))
        assert server.stats.ignored == ignored + 1

        # land
        await _until(client, lambda p: p.demo.major_state is ControlState.LANDED
                     and State.FLY not in p.state, 30, "landed",
                     command=lambda: client.at.ref(takeoff=False))
        assert server.vehicle.simulator.ground_truth().vehicle.position_ned_m[2] > -0.1
    finally:
        client.close()
        stop.set()
        await asyncio.wait_for(task, 60)
