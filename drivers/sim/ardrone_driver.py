"""The simulated AR.Drone 2.0 in process (``driver: sim`` with ``sim.firmware: ardrone``): the
simulator running the AR.Drone's firmware, its protocol engine
(:class:`~drivers.sim.ardrone_face.ArdroneFace`), and the AR.Drone driver
(:class:`~drivers.ardrone.driver.ArdroneDriver`) speaking to it — the same AT commands and
navdata bytes as over the drone's Wi-Fi, handed over by :class:`SimLink` instead of sockets, on
the simulator's clock (lockstep by default: deterministic for a seed, as fast as the CPU
allows).

What differs from the network: the video is the simulator's frames of the camera the drone
streams (``video:video_channel``), with the realistic camera's own H.264 round trip (the
vehicle overlay's ``codec: h264``) instead of the PaVE stream; the configuration is read from
the engine directly (what TCP 5559 carries). A ``link_loss`` fault acts on the datagrams both
ways, as behind ``autopilot sim --firmware ardrone`` (in lockstep its losses only: no
latency, duplicates or reordering, which would take wall-clock timers).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable, Mapping, Sequence

from drivers.ardrone import at
from drivers.ardrone import navdata as nav
from drivers.ardrone.cameras import VideoClock
from drivers.ardrone.driver import ArdroneDriver
from drivers.ardrone.video_feed import VideoFeed
from drivers.base import CameraInfo, Frame
from drivers.sim.ardrone_engine import SimulatedArdrone
from drivers.sim.config import SimConfig
from drivers.sim.driver import SimDriver
from drivers.sim.link_impairment import LinkImpairment
from drivers.sim.scenario import ScenarioObject

_HOST = "127.0.0.1"


class SimLink:
    """The in-process link: AT datagrams into the simulated drone
    (:class:`~drivers.sim.ardrone_engine.SimulatedArdrone`), its navdata out, a packet per
    telemetry sample (the wake-up is not needed: nothing else listens)."""

    def __init__(self, sim: SimDriver, on_navdata: Callable[[nav.Navdata, float], None]) -> None:
        self.sim = sim
        self._on_navdata = on_navdata
        self.drone: SimulatedArdrone | None = None
        self._task: asyncio.Task | None = None
        self._impairment: LinkImpairment | None = None
        self.last_navdata_s: float | None = None
        self.navdata_address = (_HOST, 0)
        self.config_text = b""
        self.bad_packets = 0
        self.foreign_datagrams = 0

    class _Stats:
        link_dropped = 0

    @property
    def face(self):
        return self.drone.face if self.drone is not None else None

    async def open(self) -> None:
        if self.drone is not None:
            return
        await self.sim.connect()
        self.drone = SimulatedArdrone(self.sim)
        self.drone.start()
        self._impairment = LinkImpairment(self.sim, self._Stats())
        self.sim.simulator.link_faults_in_face = True
        self._task = asyncio.get_running_loop().create_task(self._send_navdata(),
                                                            name="ardrone-navdata")

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._task
            self._task = None
        if self.drone is not None:
            await self.drone.close()
        if self._impairment is not None:
            self._impairment.close()

    def _carry(self, deliver: Callable[[], None]) -> None:
        fault = self._impairment.fault() if self._impairment is not None else None
        if fault is None:
            deliver()
        elif self.sim.lockstep:  # (lost or not, at once: no wall-clock delays in lockstep)
            if self.sim.simulator.faults.link_rng.random() >= fault.fraction:
                deliver()
            else:
                self._impairment.stats.link_dropped += 1
        else:
            self._impairment.carry(fault, deliver)

    def send(self, commands: list[bytes]) -> None:
        if self.drone is None or not commands:
            return
        for datagram in at.datagrams(commands):
            self._carry(lambda d=datagram: self.drone.take(d))

    async def _send_navdata(self) -> None:
        clock = self.sim.clock
        async for packet in self.drone.navdata():
            parsed = nav.parse(packet)
            self._carry(lambda p=parsed: self._deliver(p, clock.now()))

    def _deliver(self, packet: nav.Navdata, now: float) -> None:
        self.last_navdata_s = now
        self._on_navdata(packet, now)

    async def read_config(self, ask: Callable[[], bytes]) -> bytes:
        self.config_text = self.face.config_text() if self.face is not None else b""
        return self.config_text

    def frames(self) -> AsyncIterator[Frame]:
        """The camera the drone streams, as the simulator renders it, until it switches."""
        return self._frames()

    async def _frames(self) -> AsyncIterator[Frame]:
        camera = self.face.video_camera if self.face is not None else None
        if camera is None:
            return
        async with contextlib.aclosing(self.sim.frames(camera)) as frames:
            async for frame in frames:
                yield frame
                if self.face.video_camera != camera:
                    return


class SimArdroneDriver(ArdroneDriver):
    """The AR.Drone driver flying the simulator's AR.Drone in process. The simulator's extras
    (ground truth, true cameras, its clock's figures, its events) are the inner
    :class:`~drivers.sim.driver.SimDriver`'s, for scoring and the log only."""

    renders_on_demand = True

    def __init__(self, config: SimConfig, *, scenario: Sequence[ScenarioObject] = (),
                 seed: int | None = None, lockstep: bool = True, **driver_options) -> None:
        if config.firmware != "ardrone":
            raise ValueError("SimArdroneDriver flies sim.firmware: ardrone")
        self.sim = SimDriver(config, scenario=scenario, seed=seed, lockstep=lockstep)
        super().__init__(f"ardrone://{_HOST}", clock=self.sim.clock,
                         cameras=self.sim.cameras, **driver_options)

    def _make_link(self) -> SimLink:
        return SimLink(self.sim, self._on_navdata)

    def _make_video(self, latency_s: float) -> VideoFeed:
        self._video_clock = VideoClock(latency_s)  # (unused: frames come on the sim's clock)
        return VideoFeed(self._cameras, self._clock, self._select, self.link.frames, _HOST)

    async def close(self) -> None:
        await super().close()
        await self.sim.close()

    # -- the simulator's extras (scoring and the log only) -------------------------------------

    @property
    def sim_time_s(self) -> float:
        return self.sim.sim_time_s

    @property
    def wall_time_s(self) -> float:
        return self.sim.wall_time_s

    @property
    def real_time_factor(self) -> float:
        return self.sim.real_time_factor

    @property
    def lockstep(self) -> bool:
        return self.sim.lockstep

    @property
    def runner(self):
        return self.sim.runner

    @property
    def simulator(self):
        return self.sim.simulator

    def ground_truth(self, buffer: int = 256) -> AsyncIterator[object]:
        return self.sim.ground_truth(buffer)

    def true_cameras(self) -> Mapping[str, CameraInfo]:
        return self.sim.true_cameras()

    def events(self, buffer: int = 64) -> AsyncIterator[tuple[float, str]]:
        return self.sim.events(buffer)
