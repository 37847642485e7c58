"""What every MAVLink driver shares: the monotonic clock, the vehicle-time mapping, the
telemetry assembled from several MAVLink messages, and cameras that arrive as network video
streams."""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator, Iterable, Mapping

import numpy as np

from drivers.base import (
    Battery,
    CameraInfo,
    FlightMode,
    Frame,
    Health,
    LandedState,
    RoverState,
    SensorUnavailable,
    Vehicle,
    VehicleError,
    VehicleState,
)
from drivers.clock import MonotonicClock
from drivers.geo import GlobalOrigin
from drivers.geometry import quat_from_euler
from drivers.mavlink import ardupilot
from drivers.mavlink.firmware import Px4Profile, firmware_profile
from drivers.mavlink.link import BootTimeMapper
from drivers.slots import Broadcast

#: the telemetry both drivers ask for with SET_MESSAGE_INTERVAL (message id → Hz): PX4 streams
#: most of it unasked, ArduCopter (its SRn rates 0 on a fresh port) nothing but HEARTBEAT;
#: HOME_POSITION too, which ArduCopter otherwise sends only when home is set or moves
STREAM_RATES_HZ = {
    32: 30.0,   # LOCAL_POSITION_NED
    31: 50.0,   # ATTITUDE_QUATERNION
    30: 50.0,   # ATTITUDE
    245: 5.0,   # EXTENDED_SYS_STATE
    1: 2.0,     # SYS_STATUS
    132: 10.0,  # DISTANCE_SENSOR
    242: 0.5,   # HOME_POSITION
}


async def cancel_all(tasks: Iterable[asyncio.Task]) -> None:
    """Cancel ``tasks`` and wait for them to end (their errors are not ours any more)."""
    tasks = list(tasks)
    for task in tasks:
        task.cancel()
    for task in tasks:
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await task


#: a stamped message this much older than the newest: the vehicle rebooted (its boot clock
#: started over), not a late one
REBOOT_S = 5.0

class MavlinkVehicle(Vehicle):
    """Base of the MAVLink drivers (the rest of :class:`Vehicle` is theirs)."""

    def __init__(self, ardupilot_hold: ardupilot.CopterMode = ardupilot.CopterMode.BRAKE
                 ) -> None:
        #: ArduCopter's hold mode (BRAKE or LOITER), when the vehicle is one
        self.ardupilot_hold = ardupilot_hold
        firmware_profile(None, ardupilot_hold)  # (a bad hold mode: ValueError now)
        self._profile: tuple[int | None, Px4Profile] | None = None
        #: the vehicle's HEARTBEAT custom_mode (None before the first)
        self._custom_mode: int | None = None
        #: ArduPilot's EKF_STATUS_REPORT flags (None: none heard; PX4 sends none)
        self.ekf_flags: int | None = None
        self._clock = MonotonicClock()
        self._boot = BootTimeMapper()
        self._video: dict[str, object] = {}  # name → VideoSource
        self._telemetry: Broadcast[VehicleState] = Broadcast()
        # the newest of each piece of telemetry, from whichever message carries it
        self._armed = False
        self._mode = FlightMode.UNKNOWN
        self._q = np.array([1.0, 0.0, 0.0, 0.0])
        self._rates = np.zeros(3)
        self._attitude_vehicle_s = math.nan  # capture time (boot clock) of _q and _rates
        #: the newest capture time (boot clock) of each stamped message: a copy or an older
        #: one that arrives late (a link that duplicates or reorders) is dropped
        self._newest_s: dict[str, float] = {}
        self.out_of_order_dropped = 0
        self._landed = LandedState.UNKNOWN
        self._range_m = math.nan
        self._battery = Battery(math.nan, math.nan, math.nan)
        self._health = Health(local_position_ok=False)
        self._failsafe = False
        #: The newest telemetry sample (None before the first).
        self.latest_state: VehicleState | None = None
        self._origin: GlobalOrigin | None = None
        self._home_ned: np.ndarray | None = None
        self._origin_from_ekf = False  # GPS_GLOBAL_ORIGIN heard (HOME_POSITION then ignored)
        #: a rover on the same link (another MAVLink system: a PX4 rover or ArduRover, e.g.
        #: relayed by a router): its system id (None: no rover), and how long its reports
        #: take to arrive (its clock is not ours: reports are stamped arrival − this)
        self.rover_system_id: int | None = None
        self.rover_latency_s = 0.1
        self._rovers: Broadcast[RoverState] = Broadcast()
        self._texts: Broadcast[tuple[float, str]] = Broadcast()
        #: how each network camera was set up (URL, calibration, latency), by name
        self.camera_setups: dict[str, object] = {}
        #: the vehicle locked onto: its (system, component) and MAV_AUTOPILOT (None: not yet)
        self._target: tuple[int, int] | None = None
        self.autopilot: int | None = None
        self._text_parts: dict[int, list[str]] = {}

    @property
    def firmware(self) -> Px4Profile:
        """What this vehicle's flight stack does its own way (:mod:`drivers.mavlink.firmware`),
        from its HEARTBEAT's ``autopilot``."""
        profile = self._profile
        if profile is None or profile[0] != self.autopilot:
            profile = self._profile = (self.autopilot,
                                       firmware_profile(self.autopilot, self.ardupilot_hold))
        return profile[1]

    @property
    def global_origin(self) -> GlobalOrigin | None:
        return self._origin

    @property
    def home_ned_m(self) -> np.ndarray | None:
        return None if self._home_ned is None else self._home_ned.copy()

    def _on_gps_global_origin(self, msg) -> None:
        """GPS_GLOBAL_ORIGIN: the EKF origin itself."""
        self._origin = GlobalOrigin(msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1e3)
        self._origin_from_ekf = True

    def _on_home_position(self, msg) -> None:
        """HOME_POSITION: home's global and local positions, which place the origin (until
        GPS_GLOBAL_ORIGIN says it directly)."""
        if not all(map(math.isfinite, (msg.x, msg.y, msg.z))):
            return
        self._home_ned = np.array([msg.x, msg.y, msg.z], dtype=float)
        if self._origin_from_ekf:
            return
        home = GlobalOrigin(msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1e3)
        self._origin = GlobalOrigin(*home.to_global(-msg.x, -msg.y, -msg.z))

    def telemetry(self, buffer: int = 1) -> AsyncIterator[VehicleState]:
        return self._telemetry.subscribe(buffer)

    @property
    def sensors(self) -> frozenset[str]:
        return frozenset({"rover"}) if self.rover_system_id is not None else frozenset()

    def rover_states(self, buffer: int = 8) -> AsyncIterator[RoverState]:
        if self.rover_system_id is None:
            raise SensorUnavailable("no rover is heard on this vehicle's link")
        return self._rovers.subscribe(buffer)

    def _on_rover(self, msg) -> None:
        """A message from the rover's system: GLOBAL_POSITION_INT becomes a report (its
        position in our local frame through our EKF origin, its velocity, its heading)."""
        if msg.get_type() != "GLOBAL_POSITION_INT" or self._origin is None:
            return
        n, e, d = self._origin.to_ned(msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1e3)
        heading = math.radians(msg.hdg / 100.0) if msg.hdg != 65535 else math.nan
        self._rovers.publish(RoverState(
            time_s=self._clock.now() - self.rover_latency_s,
            position_ned_m=np.array([n, e, d]),
            velocity_ned_m_s=np.array([msg.vx, msg.vy, msg.vz], dtype=float) / 100.0,
            heading_rad=math.remainder(heading, 2.0 * math.pi) if math.isfinite(heading)
            else math.nan, system_id=msg.get_srcSystem()))

    def _on_attitude(self, msg) -> None:
        """ATTITUDE_QUATERNION or ATTITUDE, whichever the firmware's own (PX4 sends the
        quaternion and derives ATTITUDE from it; ArduCopter sends Euler angles)."""
        euler = msg.get_type() == "ATTITUDE"
        if euler != self.firmware.attitude_from_euler:
            return
        if not self._newer("attitude", msg.time_boot_ms / 1000.0):
            return
        self._q = quat_from_euler(msg.roll, msg.pitch, msg.yaw) if euler else \
            np.array([msg.q1, msg.q2, msg.q3, msg.q4])
        self._rates = np.array([msg.rollspeed, msg.pitchspeed, msg.yawspeed])
        self._attitude_vehicle_s = msg.time_boot_ms / 1000.0

    def _on_ekf_status(self, msg) -> None:
        self.ekf_flags = int(msg.flags)

    def _stream_requests(self) -> dict[int, float]:
        """What to ask the vehicle for (message id → Hz): the drivers' telemetry and the
        firmware's own (ArduPilot's EKF_STATUS_REPORT)."""
        return {**STREAM_RATES_HZ, **self.firmware.streams_hz}

    def _newer(self, kind: str, vehicle_s: float) -> bool:
        """Is this ``kind`` of message, captured at ``vehicle_s`` (boot clock), newer than
        the last one taken? (Much older — by more than :data:`REBOOT_S` — is a vehicle that
        rebooted: taken, and the clock starts over.)"""
        last = self._newest_s.get(kind, -math.inf)
        if last - REBOOT_S <= vehicle_s <= last:
            self.out_of_order_dropped += 1
            return False
        self._newest_s[kind] = vehicle_s
        return True

    def _publish_position(self, vehicle_s: float, position_ned_m, velocity_ned_m_s) -> None:
        """A LOCAL_POSITION_NED stamped ``vehicle_s`` (boot time) arrived: publish a sample
        made of it and the newest of everything else (not if it is a copy, or older than one
        published already)."""
        if not self._newer("position", vehicle_s):
            return
        self._boot.observe(vehicle_s, self._clock.now())
        attitude_s = self._boot.to_local(self._attitude_vehicle_s) \
            if math.isfinite(self._attitude_vehicle_s) else -math.inf
        state = VehicleState(
            time_s=self._boot.to_local(vehicle_s), position_ned_m=position_ned_m,
            velocity_ned_m_s=velocity_ned_m_s, attitude_q=self._q,
            angular_velocity_frd_rad_s=self._rates, armed=self._armed, mode=self._mode,
            landed_state=self._landed, distance_to_ground_m=self._range_m,
            battery=self._battery, health=self._health, failsafe=self._failsafe,
            attitude_time_s=attitude_s)
        self.latest_state = state
        self._telemetry.publish(state)

    def _end_telemetry(self, error: VehicleError | None) -> None:
        self._telemetry.close(error)
        self._rovers.close(error)
        self._texts.close(error)

    def events(self, buffer: int = 64) -> AsyncIterator[tuple[float, str]]:
        """The vehicle's status messages (STATUSTEXT: mode changes, failsafes, refusals),
        each as (arrival time, text), long ones put back together from their chunks."""
        return self._texts.subscribe(buffer)

    def _on_vehicle_text(self, msg) -> str | None:
        """A STATUSTEXT from the vehicle: published whole (None while chunks are missing)."""
        text = msg.text if isinstance(msg.text, str) else msg.text.decode(errors="replace")
        text = text.rstrip("\x00")
        ident = getattr(msg, "id", 0) or 0
        if ident:
            parts = self._text_parts.setdefault(ident, [])
            parts.append(text)
            if len(text) >= 50 and len(parts) < 20:
                return None  # (a full chunk: more follow)
            text = "".join(self._text_parts.pop(ident))
        self._texts.publish((self._clock.now(), text))
        return text

    @property
    def clock(self) -> MonotonicClock:
        return self._clock

    @property
    def cameras(self) -> Mapping[str, CameraInfo]:
        return {name: source.info for name, source in self._video.items()}

    @property
    def target_ids(self) -> tuple[int, int] | None:
        """The (system, component) of the autopilot this driver locked onto (None: none yet)."""
        return self._target

    @property
    def video_sources(self) -> Mapping[str, object]:
        """The network video sources of the cameras, by name (their errors and statistics)."""
        return dict(self._video)

    def add_camera(self, source) -> None:
        """Attach a camera (a :class:`~drivers.video.VideoSource`), by its ``info.name``."""
        self._video[source.info.name] = source

    def frames(self, camera: str) -> AsyncIterator[Frame]:
        if camera not in self._video:
            raise ValueError(f"no camera {camera!r}; this vehicle has {sorted(self._video)}")
        return self._video[camera].frames()

    async def _close_cameras(self) -> None:
        for source in self._video.values():
            await source.close()

    def vehicle_time_to_local(self, vehicle_s: float) -> float:
        """A time on the vehicle's boot clock (``time_boot_ms``, and the simulator's video
        stamps) on our clock; +inf until telemetry or TIMESYNC has fixed the mapping."""
        return self._boot.to_local(vehicle_s) if self._boot.ready else math.inf

    @property
    def vehicle_to_local_s(self) -> float:
        """local time − vehicle boot time (NaN until known)."""
        return self._boot.to_local(0.0) if self._boot.ready else math.nan

    @property
    def time_sync_round_trip_s(self) -> float:
        return self._boot.round_trip_s
