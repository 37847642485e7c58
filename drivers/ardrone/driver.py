"""A :class:`~drivers.base.Vehicle` for the Parrot AR.Drone 2.0 over its SDK 2.0 protocol, spoken
directly (no ROS, no ARDroneLib): AT commands to UDP 5556, navdata from UDP 5554, H.264 video
in PaVE frames from TCP 5555, the configuration from TCP 5559.

The async shell around the synchronous core (:mod:`drivers.ardrone.telemetry`,
:mod:`~drivers.ardrone.outer_loop`, :mod:`~drivers.ardrone.commander`), on a link to the drone
(:class:`~drivers.ardrone.link.UdpLink`: the sockets; the simulated drone in process has its
own, :mod:`drivers.sim.ardrone_driver`):

* navdata: each packet's handshake and upkeep answered (:class:`~drivers.ardrone.session.
  NavdataSession`: CONFIG with CONFIG_IDS, CTRL 5, COMWDG), each demo packet a telemetry
  sample (:class:`~drivers.ardrone.telemetry.NavdataTelemetry`, dead-reckoned), published
  through a latest-value :class:`~drivers.slots.Broadcast`;
* the AT loop, at :data:`AT_RATE_HZ`: REF (the takeoff bit as last asked) and PCMD (the
  outer loop on the newest setpoint in offboard — a setpoint carrying a progressive command
  flies that —, until it is older than the offboard timeout; the drone's hover otherwise,
  and while the newest navdata is older than :data:`NAVDATA_STALE_S`), from
  :class:`~drivers.ardrone.commander.Commander`; nothing before the first navdata says
  whether the drone flies;
* video: :class:`~drivers.ardrone.video_feed.VideoFeed` (one camera at a time, selected with
  ``CONFIG video:video_channel``).

The AR.Drone has no position control and no GPS: the driver's own outer loop flies setpoints
on the dead-reckoned position (``drift_m`` says how far off it may be). It has no arming
either: :meth:`ArdroneDriver.arm` checks and flat-trims, the motors start with the takeoff.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import math
from collections.abc import AsyncIterator, Callable, Mapping

import numpy as np

from drivers.ardrone import at
from drivers.ardrone import navdata as nav
from drivers.ardrone.cameras import VIDEO_CHANNELS, ardrone_cameras, streamed_cameras
from drivers.ardrone.commander import Commander
from drivers.ardrone.config import parse_config_text
from drivers.ardrone.link import UdpLink
from drivers.ardrone.navdata import ControlState, State
from drivers.ardrone.outer_loop import OuterLoop, OuterLoopGains
from drivers.ardrone.session import NavdataSession
from drivers.ardrone.telemetry import AIRBORNE, DroneLimits, NavdataTelemetry
from drivers.ardrone.urls import DEFAULT_URL, ArdronePorts, parse_ardrone_url
from drivers.ardrone.video_feed import PaveFrames, VideoFeed
from drivers.base import (
    CameraInfo,
    CommandDenied,
    CommandTimeout,
    ConnectionLost,
    Frame,
    Setpoint,
    Vehicle,
    VehicleNotFound,
    VehicleState,
)
from drivers.clock import Clock, MonotonicClock
from drivers.slots import Broadcast

log = logging.getLogger(__name__)

AT_RATE_HZ = 30.0
#: navdata older than this: the AT loop sends the hover, not the outer loop's output
NAVDATA_STALE_S = 0.5


class ArdroneDriver(Vehicle):
    """The AR.Drone 2.0 at ``url`` (``ardrone://HOST[:NAVDATA_PORT]``, see
    :mod:`drivers.ardrone.urls`; ``ardrone://192.168.1.1``: on its own Wi-Fi network).

    ``ports``: the drone's ports, when not the URL's; ``cameras``: the cameras' intrinsics and
    mounts (default: the nominal ones, :func:`~drivers.ardrone.cameras.ardrone_cameras`);
    ``limits``: what PCMD's fractions are fractions of (default: read from the drone's
    configuration at connect, its defaults if that fails); ``offboard_timeout_s``: a setpoint
    flies this long, then the drone hovers and offboard is left (PX4's COM_OF_LOSS_T);
    ``command_timeout_s``: how long takeoff, land and disarm wait for the navdata to show the
    drone took them; ``navdata``: ``demo`` (15 Hz) or ``full`` (200 Hz); ``drone_config``:
    keys written (and acknowledged) at connect, before the limits are read. Statistics:
    ``link.bad_packets``, ``link.foreign_datagrams``, :attr:`frames_decoded`.
    """

    has_global_position = False  # no GNSS: optical flow and the sonar
    time_sync_round_trip_s = math.nan  # (no TIMESYNC: the video's capture times map the clock)

    @property
    def vehicle_to_local_s(self) -> float:
        """Add to a time on the drone's clock to get ours (NaN until a video frame came)."""
        offset = self._video_clock.offset_s
        return math.nan if offset is None else offset

    def __init__(self, url: str = DEFAULT_URL, *, ports: ArdronePorts | None = None,
                 clock: Clock | None = None, cameras: Mapping[str, CameraInfo] | None = None,
                 limits: DroneLimits | None = None, gains: OuterLoopGains | None = None,
                 offboard_timeout_s: float = 0.5, command_timeout_s: float = 5.0,
                 navdata_latency_s: float = 0.03, video_latency_s: float = 0.05,
                 navdata: str = "demo",
                 drone_config: Mapping[str, str | int | float | bool] | None = None) -> None:
        address = parse_ardrone_url(url)
        self.url = url
        self.host = address.host
        self.ports = ports if ports is not None else address.ports
        self._clock = clock or MonotonicClock()
        self._cameras = streamed_cameras(cameras) if cameras is not None else ardrone_cameras()
        self._read_limits = limits is None
        self.command_timeout_s = command_timeout_s
        self._at = at.AtCommands()
        self._session = NavdataSession(self._at, mode=navdata, configs=drone_config)
        self.navdata_mode = navdata
        self._telemetry = NavdataTelemetry(navdata_latency_s)
        self._loop = OuterLoop(limits, gains)
        self._commander = Commander(self._at, self._loop, offboard_timeout_s)
        self._states: Broadcast[VehicleState] = Broadcast()
        self._state: VehicleState | None = None
        self._state_s = -1e9  # when it came
        self._news = asyncio.Event()
        self._tasks: list[asyncio.Task] = []
        self._home: np.ndarray | None = None
        self._closed = False
        self._opened = False
        #: the sockets (the simulated drone in process: :meth:`_make_link`'s)
        self.link = self._make_link()
        self._video = self._make_video(video_latency_s)

    def _make_link(self):
        return UdpLink(self.host, self.ports, self._clock, self._on_navdata)

    def _make_video(self, latency_s: float) -> VideoFeed:
        source = PaveFrames(self.link, self._clock, self._cameras,
                            lambda: self._video.channel_camera, latency_s)
        self._video_clock = source.video_clock
        return VideoFeed(self._cameras, self._clock, self._select, source, self.host,
                         on_close=source.close)

    # -- the interface's properties --------------------------------------------------------

    @property
    def clock(self) -> Clock:
        return self._clock

    @property
    def cameras(self) -> Mapping[str, CameraInfo]:
        return dict(self._cameras)

    @property
    def limits(self) -> DroneLimits:
        """What PCMD's fractions are fractions of (the drone's configuration, once read)."""
        return self._loop.limits

    #: how far off the dead-reckoned position may be by now (an estimate), and the path it
    #: was integrated over (:class:`~drivers.capabilities.DeadReckoning`)
    drift_m = property(lambda self: self._telemetry.drift_m)
    path_m = property(lambda self: self._telemetry.path_m)

    @property
    def home_ned_m(self) -> np.ndarray | None:
        return None if self._home is None else self._home.copy()

    @property
    def latest_state(self) -> VehicleState | None:
        return self._state

    @property
    def video_camera(self) -> str | None:
        """The camera the drone's video stream was last switched to (None: not yet)."""
        return self._video.channel_camera

    @property
    def frames_decoded(self) -> int:
        return self._video.frames_published

    # -- the link ---------------------------------------------------------------------------

    async def connect(self, timeout_s: float = 10.0) -> None:
        if self._opened:
            return
        if self._closed:
            raise ConnectionLost("this driver was closed")
        await self.link.open()
        self._opened = True
        self._tasks.append(asyncio.get_running_loop().create_task(self._at_loop(),
                                                                  name="ardrone-at"))
        try:
            await self._until(lambda s: self._session.configured, timeout_s, "connect")
        except CommandTimeout:
            await self._stop_link()  # (connect may be tried again)
            raise VehicleNotFound(
                f"no demo navdata from the AR.Drone at {self.host} (udp {self.ports.navdata}) "
                f"within {timeout_s:g} s" if self._state is None else f"the AR.Drone at "
                f"{self.host} did not acknowledge {self._session.pending_key}") from None
        if self._read_limits:
            text = await self.link.read_config(lambda: self._at.ctrl(4, 0))
            if text:
                self._loop.limits = DroneLimits.from_config(parse_config_text(text))
            else:
                log.warning("AR.Drone at %s: no configuration: its default limits", self.host)

    async def close(self) -> None:
        self._closed = True
        await self._stop_link()
        self._states.close()
        self._video.close()

    async def _stop_link(self) -> None:
        """The tasks stopped and the sockets closed (nothing sent)."""
        tasks, self._tasks = self._tasks, []
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        await self.link.close()
        self._opened = False

    async def _at_loop(self) -> None:
        period = 1.0 / AT_RATE_HZ
        next_s = self._clock.now()
        while True:
            now = self._clock.now()
            if self._state is not None:
                # (no control on old news: the hover, until navdata comes again)
                fresh = now - self._state_s <= NAVDATA_STALE_S
                self.link.send(self._commander.tick(now, self._state if fresh else None,
                                                self._telemetry.control_state))
            next_s = max(next_s + period, now)
            await self._clock.sleep_until(next_s)

    def _on_navdata(self, packet: nav.Navdata, now: float) -> None:
        step = self._session.on_packet(packet, now)
        self.link.send(list(step.commands))
        if step.navdata is None:
            return
        state = self._telemetry.update(step.navdata, now)
        if state is None:
            return
        control_state = self._telemetry.control_state
        self._commander.on_state(state, control_state)
        mode = self._commander.mode(state, control_state)
        if mode is not state.mode:
            state = dataclasses.replace(state, mode=mode)
        self._state, self._state_s = state, now
        self._states.publish(state)
        self._news.set()
        self._news = asyncio.Event()

    async def _until(self, done: Callable[[VehicleState], bool], timeout_s: float,
                     command: str) -> VehicleState:
        """The first sample (the newest, or one to come) for which ``done`` holds; raises
        :class:`CommandTimeout` after ``timeout_s``."""
        deadline = self._clock.now() + timeout_s
        while True:
            state = self._state
            if state is not None and done(state):
                return state
            remaining = deadline - self._clock.now()
            if remaining <= 0.0:
                raise CommandTimeout(command, timeout_s)
            with contextlib.suppress(TimeoutError):
                await self._clock.wait_for(self._news.wait(), remaining)

    # -- commands ----------------------------------------------------------------------------

    def _current(self, command: str) -> VehicleState:
        if self._state is None:
            raise ConnectionLost(f"{command}: not connected to the AR.Drone at {self.host}")
        return self._state

    def _airborne(self) -> bool:
        return self._telemetry.control_state in AIRBORNE

    def _refusal(self) -> str | None:
        flags = self._telemetry.flags
        if State.EMERGENCY in flags:
            return "the drone is in its emergency state (reset_emergency() on the ground)"
        if State.VBAT_LOW in flags:
            return "battery low"
        return None

    async def arm(self) -> None:
        """The AR.Drone has no arming (its motors start with the takeoff): accepted on the
        ground unless it is in its emergency state or its battery is low; flat-trims it."""
        state = self._current("arm")
        if state.armed or self._airborne():
            return
        if (reason := self._refusal()) is not None:
            raise CommandDenied("arm", reason)
        self.link.send([self._at.ftrim()])

    async def disarm(self, *, force: bool = False) -> None:
        """On the ground: nothing to stop (the takeoff bit cleared). In the air: refused
        unless ``force``, which is the emergency cut (REF's emergency bit)."""
        state = self._current("disarm")
        if not state.armed and not self._airborne():
            self._commander.land()
            return
        if not force:
            raise CommandDenied("disarm", "in the air (force=True cuts the motors)")
        self._commander.emergency()
        await self._until(lambda s: not s.armed, self.command_timeout_s, "disarm")

    async def reset_emergency(self) -> None:
        """Leave the emergency state (on the ground: REF's emergency bit again)."""
        self._current("reset emergency")
        if State.EMERGENCY not in self._telemetry.flags:
            return
        if self._airborne():
            raise CommandDenied("reset emergency", "in the air")
        self._commander.emergency()
        await self._until(lambda s: State.EMERGENCY not in self._telemetry.flags,
                          self.command_timeout_s, "reset emergency")

    async def takeoff(self, altitude_m: float | None = None) -> None:
        """REF's takeoff: the drone climbs to about 1 m by itself and hovers; with
        ``altitude_m``, the driver then climbs (or descends) to that height above the
        takeoff point (TAKEOFF until there, then HOLD; capped below control:altitude_max).
        Returns once the navdata shows the drone taking off."""
        state = self._current("takeoff")
        if self._airborne():
            raise CommandDenied("takeoff", "already flying")
        if (reason := self._refusal()) is not None:
            raise CommandDenied("takeoff", reason)
        self._home = np.array([state.position_ned_m[0], state.position_ned_m[1], 0.0])
        target = None if altitude_m is None else state.altitude_m + float(altitude_m)
        self._commander.takeoff(target, self._loop.limits)
        try:
            await self._until(lambda s: self._airborne(), self.command_timeout_s, "takeoff")
        except CommandTimeout:
            self._commander.land()  # (no late takeoff after the caller gave up)
            raise

    async def land(self) -> None:
        """REF's land: the drone descends where it is and stops its motors on the ground.
        Returns once the navdata shows it landing (or landed)."""
        self._current("land")
        self._commander.land()
        await self._until(lambda s: self._telemetry.control_state not in (
            ControlState.TAKING_OFF, ControlState.HOVERING, ControlState.FLYING),
            self.command_timeout_s, "land")

    async def hold(self) -> None:
        """The drone's own hover (PCMD with its progressive bit clear)."""
        self._current("hold")
        self._commander.hold()

    async def start_offboard(self) -> None:
        self._current("start offboard")
        reason = self._commander.start_offboard(self._clock.now())
        if reason is not None:
            raise CommandDenied("start offboard", reason)

    async def stop_offboard(self) -> None:
        self._commander.stop_offboard()

    async def send_setpoint(self, setpoint: Setpoint) -> None:
        self._commander.setpoint(setpoint, self._clock.now())

    # -- streams ------------------------------------------------------------------------------

    def telemetry(self, buffer: int = 1) -> AsyncIterator[VehicleState]:
        return self._states.subscribe(buffer)

    def frames(self, camera: str) -> AsyncIterator[Frame]:
        return self._video.subscribe(camera)

    def _select(self, camera: str) -> None:
        """Switch the drone's one video stream to ``camera``."""
        self._session.configure("video:video_channel", VIDEO_CHANNELS[camera])
