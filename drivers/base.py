"""The vehicle interface: the one door between the autopilot and a vehicle.

Everything above this module (perception, estimation, behaviours, the runtime) talks to a
vehicle only through :class:`Vehicle` and the messages defined here. The MuJoCo simulator
driver implements it today; MAVSDK (PX4 over MAVLink) and pymavlink drivers implement the same
methods, which map one-to-one onto MAVSDK's ``action`` / ``offboard`` / ``telemetry`` plugins and
onto MAVLink commands (COMPONENT_ARM_DISARM, NAV_TAKEOFF, NAV_LAND, DO_SET_MODE,
SET_POSITION_TARGET_LOCAL_NED).

Frames and units follow PX4: world NED, body FRD, camera optical (x right, y down, z forward),
SI units. Every sample carries ``time_s``, its capture time on the driver's :class:`Clock`.

Setpoints are sent one at a time: a driver never re-sends a setpoint on its own. If the caller
stops streaming, the vehicle's offboard-loss failsafe acts, which is the point: an intent that
is not renewed expires.
"""

from __future__ import annotations

import abc
import enum
import math
from collections.abc import AsyncIterator, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from drivers.geometry import yaw_from_quat

if TYPE_CHECKING:
    from drivers.clock import Clock
    from drivers.geo import GlobalOrigin

NAN = float("nan")


def _frozen_array(values, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.array(values, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"expected an array of shape {shape}, got {arr.shape}")
    arr.flags.writeable = False
    return arr


class FlightMode(enum.Enum):
    """PX4 flight modes, as a MAVLink vehicle reports them."""

    UNKNOWN = "unknown"
    MANUAL = "manual"
    ALTCTL = "altctl"
    POSCTL = "posctl"
    HOLD = "hold"
    TAKEOFF = "takeoff"
    LAND = "land"
    RETURN = "return"
    MISSION = "mission"
    OFFBOARD = "offboard"
    PRECLAND = "precland"  # AUTO.PRECLAND: PX4's precision landing on LANDING_TARGET


class LandedState(enum.Enum):
    """As MAVLink EXTENDED_SYS_STATE / MAVSDK ``landed_state``."""

    UNKNOWN = "unknown"
    ON_GROUND = "on_ground"
    IN_AIR = "in_air"
    TAKING_OFF = "taking_off"
    LANDING = "landing"


class SetpointFrame(enum.Enum):
    LOCAL_NED = "local_ned"
    #: Heading-relative: x forward, y right, z down, rotated by the vehicle's current yaw only
    #: (MAVLink MAV_FRAME_BODY_NED as PX4 interprets it; MAVSDK ``VelocityBodyYawspeed``).
    BODY_FRD = "body_frd"


# --------------------------------------------------------------------------------------------
# Messages
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Health:
    """Pre-flight health, as PX4 reports it in SYS_STATUS and MAVSDK in ``health()``."""

    gyro_ok: bool = True
    accel_ok: bool = True
    mag_ok: bool = True
    local_position_ok: bool = True
    battery_ok: bool = True
    #: The vehicle's own pre-arm checks as a whole (MAVLink SYS_STATUS PREARM_CHECK bit).
    prearm_ok: bool = True

    @property
    def armable(self) -> bool:
        return all((self.gyro_ok, self.accel_ok, self.mag_ok, self.local_position_ok,
                    self.battery_ok, self.prearm_ok))

    def problems(self) -> list[str]:
        names = ("gyro_ok", "accel_ok", "mag_ok", "local_position_ok", "battery_ok", "prearm_ok")
        return [n.removesuffix("_ok") for n in names if not getattr(self, n)]


@dataclass(frozen=True, slots=True)
class Battery:
    voltage_v: float
    current_a: float
    remaining_fraction: float  # 0..1


@dataclass(frozen=True, slots=True, eq=False)
class VehicleState:
    """One telemetry sample: what PX4's estimator and commander report.

    ``attitude_q`` rotates body FRD into world NED. ``distance_to_ground_m`` is the downward
    range sensor's reading along the body z axis (NaN when out of range or absent).

    ``time_s`` is when the position and velocity were captured; ``attitude_time_s`` when the
    attitude and rates were (over MAVLink they travel in separate messages, and either can
    stop arriving on its own; NaN: at ``time_s``).
    """

    time_s: float
    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    attitude_q: np.ndarray
    angular_velocity_frd_rad_s: np.ndarray
    armed: bool
    mode: FlightMode
    landed_state: LandedState
    distance_to_ground_m: float
    battery: Battery
    health: Health
    failsafe: bool = False
    attitude_time_s: float = NAN

    def __post_init__(self) -> None:
        if math.isnan(self.attitude_time_s):
            object.__setattr__(self, "attitude_time_s", self.time_s)
        object.__setattr__(self, "position_ned_m", _frozen_array(self.position_ned_m, (3,)))
        object.__setattr__(self, "velocity_ned_m_s", _frozen_array(self.velocity_ned_m_s, (3,)))
        object.__setattr__(self, "attitude_q", _frozen_array(self.attitude_q, (4,)))
        object.__setattr__(
            self,
            "angular_velocity_frd_rad_s",
            _frozen_array(self.angular_velocity_frd_rad_s, (3,)),
        )

    @property
    def yaw_rad(self) -> float:
        return yaw_from_quat(self.attitude_q)

    @property
    def altitude_m(self) -> float:
        """Height above the local origin (PX4's boot position), positive up."""
        return -float(self.position_ned_m[2])

    @property
    def in_air(self) -> bool:
        return self.landed_state in (LandedState.IN_AIR, LandedState.TAKING_OFF,
                                     LandedState.LANDING)


@dataclass(frozen=True, slots=True)
class ProgressiveCommand:
    """A Parrot AR.Drone's progressive command (``AT*PCMD``), as fractions in [−1, 1] of the
    drone's limits: ``roll`` of ``control:euler_angle_max`` (+ right), ``pitch`` of it (+ nose
    up: negative flies forward), ``gaz`` of ``control:control_vz_max`` (+ climb), ``yaw`` of
    ``control:control_yaw`` (+ clockwise from above). ``hover``: the drone's own hover (the
    fractions ignored)."""

    roll: float = 0.0
    pitch: float = 0.0
    gaz: float = 0.0
    yaw: float = 0.0
    hover: bool = True


@dataclass(frozen=True, slots=True, eq=False)
class Setpoint:
    """An offboard setpoint, as PX4's SET_POSITION_TARGET_LOCAL_NED understands it.

    NaN in a field means "not controlled" (PX4's convention). Per axis, a finite position is
    tracked with the velocity as feed-forward; with the position NaN the velocity is tracked.
    A finite ``acceleration_m_s2`` is added as feed-forward (a time-parametrised trajectory's
    second derivative). Yaw: a finite ``yaw_rad`` is held, with a finite ``yaw_rate_rad_s`` as
    its feed-forward; otherwise a finite ``yaw_rate_rad_s`` is flown; otherwise the heading is
    kept. In :attr:`SetpointFrame.BODY_FRD` only velocity is allowed.

    ``time_s`` is when the setpoint was computed (for latency accounting); drivers do not send it.

    ``progressive``: the same intent as an AR.Drone's progressive command (a seed rule's own
    ``cmd_vel``, in its units); a vehicle that flies such commands (the AR.Drone) flies it as
    it is, and every other vehicle flies the setpoint's position and velocity.
    """

    position_ned_m: np.ndarray = field(default_factory=lambda: np.full(3, NAN))
    velocity_m_s: np.ndarray = field(default_factory=lambda: np.full(3, NAN))
    yaw_rad: float = NAN
    yaw_rate_rad_s: float = NAN
    frame: SetpointFrame = SetpointFrame.LOCAL_NED
    time_s: float = NAN
    acceleration_m_s2: np.ndarray = field(default_factory=lambda: np.full(3, NAN))
    progressive: ProgressiveCommand | None = None

    def __post_init__(self) -> None:
        pos = _frozen_array(self.position_ned_m, (3,))
        vel = _frozen_array(self.velocity_m_s, (3,))
        acc = _frozen_array(self.acceleration_m_s2, (3,))
        object.__setattr__(self, "position_ned_m", pos)
        object.__setattr__(self, "velocity_m_s", vel)
        object.__setattr__(self, "acceleration_m_s2", acc)
        if self.frame is SetpointFrame.BODY_FRD and (np.isfinite(pos).any()
                                                      or np.isfinite(acc).any()):
            raise ValueError("a BODY_FRD setpoint carries velocity only")
        undefined = ~np.isfinite(pos) & ~np.isfinite(vel)
        if undefined.any():
            axes = ", ".join("xyz"[i] for i in np.flatnonzero(undefined))
            raise ValueError(f"setpoint leaves axis {axes} without position or velocity")

    @classmethod
    def position(cls, north_m: float, east_m: float, down_m: float, yaw_rad: float = NAN,
                 *, time_s: float = NAN) -> Setpoint:
        return cls(position_ned_m=(north_m, east_m, down_m), yaw_rad=yaw_rad, time_s=time_s)

    @classmethod
    def velocity_ned(cls, vn: float, ve: float, vd: float, *, yaw_rad: float = NAN,
                     yaw_rate_rad_s: float = NAN, time_s: float = NAN) -> Setpoint:
        return cls(velocity_m_s=(vn, ve, vd), yaw_rad=yaw_rad, yaw_rate_rad_s=yaw_rate_rad_s,
                   time_s=time_s)

    @classmethod
    def velocity_body(cls, forward: float, right: float, down: float, *,
                      yaw_rate_rad_s: float = 0.0, time_s: float = NAN) -> Setpoint:
        return cls(velocity_m_s=(forward, right, down), yaw_rate_rad_s=yaw_rate_rad_s,
                   frame=SetpointFrame.BODY_FRD, time_s=time_s)

    @classmethod
    def position_velocity(cls, position_ned_m, velocity_ned_m_s, *, yaw_rad: float = NAN,
                          yaw_rate_rad_s: float = NAN, time_s: float = NAN,
                          acceleration_ned_m_s2=(NAN, NAN, NAN)) -> Setpoint:
        return cls(position_ned_m=position_ned_m, velocity_m_s=velocity_ned_m_s,
                   yaw_rad=yaw_rad, yaw_rate_rad_s=yaw_rate_rad_s, time_s=time_s,
                   acceleration_m_s2=acceleration_ned_m_s2)


@dataclass(frozen=True, slots=True)
class CameraIntrinsics:
    """Pinhole intrinsics in OpenCV's convention (pixel centres at integer coordinates)."""

    width_px: int
    height_px: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)  # OpenCV k1 k2 p1 p2 k3

    @property
    def matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def hfov_rad(self) -> float:
        return 2.0 * math.atan(self.width_px / (2.0 * self.fx))

    def project(self, point_cam_m: np.ndarray) -> np.ndarray:
        """Pixel ``(u, v)`` of a point in the optical frame (no distortion applied)."""
        x, y, z = point_cam_m
        return np.array([self.fx * x / z + self.cx, self.fy * y / z + self.cy])


@dataclass(frozen=True, slots=True, eq=False)
class CameraInfo:
    """A camera's identity, intrinsics and mounting.

    ``rotation_body_cam`` turns optical-frame vectors into body FRD; ``position_body_m`` is the
    optical centre in body FRD.
    """

    name: str
    intrinsics: CameraIntrinsics
    rotation_body_cam: np.ndarray
    position_body_m: np.ndarray
    rate_hz: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "rotation_body_cam",
                           _frozen_array(self.rotation_body_cam, (3, 3)))
        object.__setattr__(self, "position_body_m", _frozen_array(self.position_body_m, (3,)))


@dataclass(frozen=True, slots=True, eq=False)
class Frame:
    """One camera image (BGR, ``uint8``, H×W×3, read-only) with its capture time."""

    camera: CameraInfo
    time_s: float
    seq: int
    image: np.ndarray
    #: the JPEG the image was decoded from, when it came out of a JPEG codec as it is (a
    #: frame log keeps these bytes, so a replay sees exactly what the detectors saw)
    jpeg: bytes | None = None


# --------------------------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class LandingTarget:
    """Where the landing target is (MAVLink LANDING_TARGET with ``position_valid``): its
    position in the vehicle's local NED frame, at ``time_s`` (the vehicle's clock)."""

    time_s: float
    position_ned_m: tuple[float, float, float]
    target_num: int = 0

    def __post_init__(self) -> None:
        if len(self.position_ned_m) != 3 or not all(map(math.isfinite, self.position_ned_m)):
            raise ValueError(f"landing target position must be 3 finite numbers, got "
                             f"{self.position_ned_m}")


@dataclass(frozen=True, slots=True, eq=False)
class UwbRanges:
    """Ultra-wideband ranges from the drone's tag to anchors on another vehicle (a rover),
    all captured at ``time_s``: ``ranges_m[i]`` to anchor ``anchor_ids[i]`` (where each anchor
    is, on that vehicle, is configuration: ``rover.uwb.anchors_frd_m``)."""

    time_s: float
    anchor_ids: tuple[int, ...]
    ranges_m: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.anchor_ids) != len(self.ranges_m):
            raise ValueError("one range per anchor id")


@dataclass(frozen=True, slots=True, eq=False)
class RoverState:
    """Another vehicle's state as its own autopilot reports it (a PX4 rover or ArduRover on
    the same MAVLink network): its reference point's position in *this* vehicle's local NED
    frame (from its global position and this vehicle's EKF origin), its velocity, its compass
    heading, and the accuracy it claims; captured at ``time_s`` (this vehicle's clock)."""

    time_s: float
    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    heading_rad: float  # NaN: not reported
    position_std_m: float = NAN  # horizontal (MAVLink eph)
    velocity_std_m_s: float = NAN
    heading_std_rad: float = NAN
    system_id: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_ned_m", _frozen_array(self.position_ned_m, (3,)))
        object.__setattr__(self, "velocity_ned_m_s",
                           _frozen_array(self.velocity_ned_m_s, (3,)))


class SensorUnavailable(Exception):
    """The vehicle has no such sensor stream (no UWB radio, no rover on the link)."""


class VehicleError(Exception):
    """Base class for everything a driver raises."""


class CommandDenied(VehicleError):
    """The vehicle refused a command (MAV_RESULT_DENIED / MAVSDK COMMAND_DENIED)."""

    def __init__(self, command: str, reason: str) -> None:
        super().__init__(f"{command} denied: {reason}")
        self.command = command
        self.reason = reason


class CommandTimeout(VehicleError):
    """No answer to a command within its timeout."""

    def __init__(self, command: str, timeout_s: float) -> None:
        super().__init__(f"{command}: no answer within {timeout_s:g} s")
        self.command = command
        self.timeout_s = timeout_s


class ConnectionLost(VehicleError):
    """The link to the vehicle is gone (heartbeats stopped, socket closed, simulator failed)."""


class VehicleNotFound(ConnectionLost):
    """``connect()`` heard no vehicle (heartbeat, then telemetry) within its timeout."""


class CameraUnavailable(VehicleError):
    """A camera cannot deliver frames: the simulator cannot render (``rendering``), or no
    video arrives from the stream (``no_video``)."""

    def __init__(self, message: str, cause: str) -> None:
        super().__init__(message)
        self.cause = cause


# --------------------------------------------------------------------------------------------
# The interface
# --------------------------------------------------------------------------------------------


class Vehicle(abc.ABC):
    """A flyable vehicle. All methods are coroutines run on the caller's event loop.

    Commands return once the vehicle has accepted them (as MAVSDK's ``action`` calls do), not
    once the manoeuvre is finished; watch :meth:`telemetry` for that. A refused command raises
    :class:`CommandDenied`, an unanswered one :class:`CommandTimeout`, and a broken link
    :class:`ConnectionLost` (also from the streams).
    """

    @property
    @abc.abstractmethod
    def clock(self) -> Clock:
        """The clock that stamps this vehicle's samples (lockstep in the simulator)."""

    @property
    @abc.abstractmethod
    def cameras(self) -> Mapping[str, CameraInfo]:
        """The cameras :meth:`frames` can stream, by name."""

    @abc.abstractmethod
    async def connect(self, timeout_s: float = 10.0) -> None:
        """Open the link and wait until the vehicle is seen."""

    @abc.abstractmethod
    async def arm(self) -> None:
        """Arm the motors; refused (:class:`CommandDenied`) while the vehicle is not armable."""

    @abc.abstractmethod
    async def disarm(self, *, force: bool = False) -> None:
        """Disarm; refused in the air unless ``force`` (which stops the motors wherever it is)."""

    @abc.abstractmethod
    async def takeoff(self, altitude_m: float | None = None) -> None:
        """Switch to TAKEOFF; climbs to ``altitude_m`` above the current position (or to the
        vehicle's own takeoff-altitude parameter) and then holds."""

    @abc.abstractmethod
    async def land(self) -> None:
        """Switch to the vehicle's LAND mode: it descends where it is, detects the touchdown
        and disarms."""

    @abc.abstractmethod
    async def hold(self) -> None:
        """Position hold (PX4 AUTO.LOITER)."""

    @abc.abstractmethod
    async def start_offboard(self) -> None:
        """Enter OFFBOARD. Refused in flight unless a setpoint arrived within the vehicle's
        offboard timeout (PX4's COM_OF_LOSS_T): send one first, then keep streaming."""

    @abc.abstractmethod
    async def stop_offboard(self) -> None:
        """Leave OFFBOARD for HOLD."""

    @abc.abstractmethod
    async def send_setpoint(self, setpoint: Setpoint) -> None:
        """Send one setpoint. Never re-sent by the driver: stream it to keep OFFBOARD alive."""

    async def return_to_launch(self) -> None:
        """Return to launch (PX4 AUTO.RTL, ArduPilot RTL): home at the return altitude, then
        land there."""
        raise CommandDenied("return to launch", "this vehicle has no return mode")

    #: whether the vehicle knows where it is on Earth (GNSS: global positions, geotags); a
    #: vehicle without (the AR.Drone: optical flow and sonar) sets it False
    has_global_position: bool = True

    @property
    def home_ned_m(self) -> np.ndarray | None:
        """Home (where the vehicle armed, or was told home is) in the local frame; None while
        not known (MAVLink: HOME_POSITION)."""
        return None

    @property
    def global_origin(self) -> GlobalOrigin | None:
        """Where the local NED frame's origin is on Earth (PX4's EKF origin), None while not
        known (a MAVLink vehicle tells it with GPS_GLOBAL_ORIGIN or HOME_POSITION)."""
        return None

    @property
    def sensors(self) -> frozenset[str]:
        """The extra sensor streams this vehicle delivers now, by name: ``uwb``
        (:class:`~drivers.capabilities.UwbRanging`), ``rover``
        (:class:`~drivers.capabilities.RoverLink`); none by default."""
        return frozenset()

    @abc.abstractmethod
    def telemetry(self, buffer: int = 1) -> AsyncIterator[VehicleState]:
        """A new subscription to telemetry. A slow consumer gets the newest sample, not a queue
        (a logger that must miss nothing asks for a small ``buffer`` of unread samples)."""

    @abc.abstractmethod
    def frames(self, camera: str) -> AsyncIterator[Frame]:
        """A new subscription to one camera's frames (newest only). The camera is rendered or
        decoded only while at least one subscription is open."""

    @abc.abstractmethod
    async def close(self) -> None:
        """Release the link. Does not command anything: bring the vehicle to a safe state first."""

    async def __aenter__(self) -> Vehicle:
        await self.connect()
        return self

    async def __aexit__(self, *exc_info) -> None:
        await self.close()
