"""The configuration's sections (``runtime``, ``perception``, ``estimation``, ``control``,
``photos``, ``link``, ``vehicle``, ``log``, ``console``, ``failsafe``), each a model whose
fields carry their units and bounds. The target kinds' own sections (how each is found and
estimated: ``perception.<kind>``, ``estimation.<kind>``, …) are their modules'
(:mod:`autopilot.target_kinds`), made fields of :data:`PerceptionConfig`,
:data:`EstimationConfig`, :data:`ControlConfig` and the whole (:mod:`.app`) by
:func:`kind_fields`."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import (
    Field,
    create_model,
    field_validator,
    model_validator,
)

from autopilot.config.base import (
    ConfigModel,
    FiniteFloat,
    NonNegative,
    Positive,
)
from drivers.sim.config import CameraConfig


class YieldConfig(ConfigModel):
    enabled: bool = True
    late_ms: Annotated[float, Field(gt=0, le=500)] = 8.0  # a watchdog beat this late: fewer frames
    on_time_ms: Annotated[float, Field(ge=0, le=500)] = 3.0  # this early: more, back to all
    min_share: Annotated[float, Field(gt=0, le=1)] = 0.15  # perception: never fewer than this share
    viewer_min_share: Annotated[float, Field(gt=0, le=1)] = 0.1  # the console (yields first)

    @model_validator(mode="after")
    def _on_time_before_late(self) -> YieldConfig:
        if self.on_time_ms >= self.late_ms:
            raise ValueError(f"on_time_ms ({self.on_time_ms:g}) must be below late_ms "
                             f"({self.late_ms:g})")
        return self


class RuntimeConfig(ConfigModel):
    control_rate_hz: Annotated[float, Field(ge=5, le=200)]  # at least; also on every estimate
    #: nothing new (a newer position or attitude) received from the vehicle for this long,
    #: judged on our clock at receipt: the vehicle is silent; no more motion setpoints, the
    #: vehicle holds, the step waits
    telemetry_silence_s: Annotated[float, Field(gt=0, le=10)]
    #: a silence longer than this ends the step in the mission's fallback (as a lost link);
    #: a shorter one resumes the step when telemetry comes back
    telemetry_grace_s: Annotated[float, Field(ge=0, le=60)] = 2.0
    setpoint_rate_hz: Annotated[float, Field(ge=20, le=100)]  # streaming to the vehicle
    setpoint_expiry_s: Annotated[float, Field(gt=0, le=1)]  # a setpoint not renewed expires
    offboard_warmup_s: Annotated[float, Field(ge=0.1, le=2)]  # streaming before OFFBOARD
    lockstep_detection_s: Annotated[float, Field(ge=0, le=0.5)]  # modelled detection time
    shutdown_timeout_s: Positive  # bound on the safe stop (hold, land, disarm)
    progress_interval_s: Positive  # plain progress lines (not a terminal), wall seconds
    #: the event loop not answering for this long (wall clock) is a stall: reported, and in
    #: real time, once setpoints have lapsed, the mission's fallback takes over
    loop_stall_s: Annotated[float, Field(gt=0, le=30)] = 0.5
    #: background threads (decoding, detection, encoding) this much lower in priority than the
    #: event loop's (telemetry, control): :mod:`drivers.threads`
    background_nice: Annotated[int, Field(ge=0, le=19)] = 10
    #: in real time, perception and the console take fewer frames while the event loop runs
    #: late: :mod:`autopilot.runtime.governor`
    yield_to_control: YieldConfig = YieldConfig()

    @model_validator(mode="after")
    def _stall_outlasts_setpoints(self) -> RuntimeConfig:
        if self.telemetry_grace_s < self.telemetry_silence_s:
            raise ValueError(
                f"telemetry_grace_s ({self.telemetry_grace_s:g}) must be at least "
                f"telemetry_silence_s ({self.telemetry_silence_s:g}): the grace counts from the "
                "last telemetry received, and a silence starts after telemetry_silence_s")
        if self.loop_stall_s < self.setpoint_expiry_s:
            raise ValueError(
                f"loop_stall_s ({self.loop_stall_s:g}) must be at least setpoint_expiry_s "
                f"({self.setpoint_expiry_s:g}): a stall is when the setpoints have lapsed")
        return self


class TargetEstimationConfig(ConfigModel):
    accel_noise_m_s2: Positive
    gate_chi2: Positive
    stale_after_s: Positive
    initial_velocity_std_m_s: Positive
    max_extrapolation_s: NonNegative
    pixel_noise_px: Positive
    radius_noise_px: Positive
    border_noise_scale: Annotated[float, Field(ge=1)]  # blobs cut by the image border
    restart_after: Annotated[int, Field(ge=2, le=30)]
    confirm_after: Annotated[int, Field(ge=1, le=60)]


class NavigationUncertaintyConfig(ConfigModel):
    """The vehicle's own pose errors (slowly varying), which every target placed in the world
    with that pose inherits."""

    position_std_m: NonNegative  # horizontal, wandering over position_time_constant_s
    position_time_constant_s: Positive
    height_std_m: NonNegative  # wandering over height_time_constant_s
    height_time_constant_s: Positive
    position_noise_m: NonNegative  # white, each sample
    #: the EKF output's lag on the wandering errors (they move smoothly, not as a random walk)
    position_smoothing_s: NonNegative = 0.0
    #: the target filters' memory: their random walk for the wander is its change over this
    drift_window_s: Positive = 1.0
    attitude_std_deg: NonNegative  # roll and pitch
    yaw_std_deg: NonNegative


def kind_fields(parent: str) -> dict[str, Any]:
    """The shipped target kinds' configuration sections under ``parent`` as required model
    fields (:func:`autopilot.targets.config_sections`)."""
    import autopilot.target_kinds  # noqa: F401 (registers the shipped kinds)
    from autopilot.targets import config_sections

    return {key: (model, ...) for key, model in config_sections(parent).items()}


#: How each target is found (``perception.<kind>``): a section for each shipped target kind.
PerceptionConfig = create_model("PerceptionConfig", __base__=ConfigModel, __module__=__name__,
                                **kind_fields("perception"))

#: Estimation: the target filters' motion model (``target``), each target kind's measurement
#: models (``estimation.<kind>``), the vehicle's own navigation errors, the cameras' mounts.
EstimationConfig = create_model(
    "EstimationConfig", __base__=ConfigModel, __module__=__name__,
    target=(TargetEstimationConfig, ...), **kind_fields("estimation"),
    navigation=(NavigationUncertaintyConfig, ...),
    #: How far the cameras may be off their nominal mount (σ per axis): a fixed rotation that
    #: every target seen through them inherits, as an attitude error that averaging frames
    #: does not remove.
    camera_mount_std_deg=(Annotated[float, Field(ge=0, le=10)], ...))


class FollowControlConfig(ConfigModel):
    mode: Literal["yaw", "lateral"]
    standoff_m: Annotated[float, Field(gt=0.3, le=20)]
    position_gain: Positive
    yaw_lead_s: NonNegative
    max_speed_m_s: Positive
    max_vertical_speed_m_s: Positive
    max_accel_m_s2: Positive
    max_yaw_rate_deg_s: Positive
    altitude_floor_m: NonNegative
    accel_lead_s: NonNegative
    accel_filter_s: Positive
    sideways_feedforward: Annotated[float, Field(ge=0, le=1)]
    yaw_tracked_bearing_rate_deg_s: Annotated[float, Field(gt=0, le=720)]
    intercept_horizon_s: Annotated[float, Field(ge=0, le=10)]
    lost_after_s: Positive
    lost_hold_s: NonNegative
    lost_coast_s: Annotated[float, Field(ge=0, le=10)] = 2.0
    search_yaw_rate_deg_s: Positive
    lost_timeout_s: Positive


class TrajectoryControlConfig(ConfigModel):
    """Limits of the time-parametrised trajectories (goto, orbit, survey)."""

    max_speed_m_s: Annotated[float, Field(gt=0, le=20)]  # a step's speed_m_s above this: refused
    accel_m_s2: Annotated[float, Field(gt=0, le=10)]  # along the path
    lateral_accel_m_s2: Annotated[float, Field(gt=0, le=10)]  # on curves (v²κ)
    jerk_m_s3: Annotated[float, Field(gt=0, le=50)]
    climb_speed_m_s: Annotated[float, Field(gt=0, le=10)]
    descent_speed_m_s: Annotated[float, Field(gt=0, le=10)]
    yaw_rate_deg_s: Annotated[float, Field(gt=0, le=360)]  # turning to a new heading
    rounding_m: Annotated[float, Field(ge=0, le=5)]  # corners and joins (Gaussian σ along the path)
    #: fallen this far behind: the reference waits
    lag_slowdown_m: Annotated[float, Field(gt=0, le=20)]
    arrival_tolerance_m: Annotated[float, Field(gt=0, le=5)]  # done: the end reached within this
    #: ... or this long after the reference ended
    settle_timeout_s: Annotated[float, Field(gt=0, le=120)]
    #: ours, or seed004: seed 004's PID on the position error (a baseline for the benchmark)
    tracker: Literal["ours", "seed004"]
    seed004_pid: tuple[NonNegative, NonNegative, NonNegative]  # its Kp, Ki, Kd
    #: one step's planned path at most this long (its way in, laps, lines and turns); a
    #: longer one is refused before it is planned (planning costs ~0.1 s and ~6 MB per km)
    max_path_m: Annotated[float, Field(gt=0, le=100_000)] = 10_000.0
    max_photos: Annotated[int, Field(ge=0, le=100_000)] = 2000  # one orbit's or survey's


class PhotoConfig(ConfigModel):
    """Photos of the offboard steps (orbit, survey): what the JPEGs' EXIF says of the camera."""

    camera: str  # default camera for photos (a step may name another)
    jpeg_quality: Annotated[int, Field(ge=10, le=100)]
    make: str
    model: str
    sensor_width_mm: Annotated[float, Field(gt=0, le=100)]  # focal length in mm = fx × this / width


class Seed004LandingConfig(ConfigModel):
    """Seed 004's landing action's gain-scheduled PID (autopilot/behaviors/land_on_rover.py),
    the baseline of ``autopilot bench landing --strategy seed004``."""

    approach_pid: tuple[NonNegative, NonNegative, NonNegative]  # Kp, Ki, Kd far from the deck
    near_pid: tuple[NonNegative, NonNegative, NonNegative]  # ... within near_distance_m
    near_distance_m: Positive
    descent_threshold_m: Positive
    vertical_gain_per_s: Positive
    max_descent_speed_m_s: Positive
    max_speed_m_s: Positive


#: Control: the following and trajectory limits, seed 004's landing, and the target kinds'
#: own sections (``control.<kind>``: the keep-out guard's).
ControlConfig = create_model(
    "ControlConfig", __base__=ConfigModel, __module__=__name__,
    follow=(FollowControlConfig, ...), trajectory=(TrajectoryControlConfig, ...),
    seed004_landing=(Seed004LandingConfig, ...), **kind_fields("control"))


class FrameLogConfig(ConfigModel):
    sim_rate_hz: NonNegative  # camera frames logged per second with the simulator; 0: none
    vehicle_rate_hz: NonNegative  # ... with MAVLink drivers (a companion computer)
    jpeg_quality: Annotated[int, Field(ge=10, le=100)]


class LogConfig(ConfigModel):
    frames: FrameLogConfig


class LinkConfig(ConfigModel):
    """How the MAVLink drivers reach a vehicle (``--connect``); its cameras are in
    ``vehicle.cameras``."""

    connect: str  # MAVLink URL: udpin://, udpout://, tcp://, serial://
    connect_timeout_s: Annotated[float, Field(gt=0, le=300)]
    #: a file holding the MAVLink 2 signing key (None: unsigned)
    signing_key: str | None = None
    #: a rover on the same link (land_on_rover): its MAVLink system id (None: none), and how
    #: long its reports take to arrive (the pymavlink driver)
    rover_system_id: Annotated[int, Field(ge=1, le=255)] | None = None
    rover_latency_s: Annotated[float, Field(ge=0, le=2)] = 0.1
    #: the AR.Drone's navdata (driver ardrone): demo at 15 Hz, or full at 200 Hz (the demo,
    #: time, physical measures, angles, altitude and magnetometer options)
    navdata: Literal["demo", "full"] = "demo"
    #: the AR.Drone's configuration keys to write when the driver connects (driver ardrone;
    #: as ardrone_autonomy's parameters), e.g. ``control:euler_angle_max: 0.35`` or
    #: ``control:outdoor: true``; each a key the drone has, a client may write, with a value
    #: of its type within the SDK's range. The keys the driver sets itself are refused.
    ardrone_config: dict[str, str | bool | int | float] = Field(default_factory=dict)

    @field_validator("ardrone_config")
    @classmethod
    def _drone_keys(cls, keys: dict[str, str | bool | int | float]
                    ) -> dict[str, str | bool | int | float]:
        from drivers.ardrone.at import config_value
        from drivers.ardrone.config import DRIVER_KEYS, ConfigError, DroneConfig

        drone = DroneConfig()
        for name, value in keys.items():
            owner = DRIVER_KEYS.get(name.strip().lower())
            if owner is not None:
                raise ValueError(f"{name}: the driver sets it itself (from {owner})")
            try:
                drone.set(name, config_value(value))
            except ConfigError as exc:
                raise ValueError(f"{exc} (see the AR.Drone SDK 2.0 guide, ch. 8)") from None
        return keys


class VehicleCameraConfig(CameraConfig):
    """A camera of the vehicle: its geometry (what the simulator renders, and the nominal
    intrinsics of an uncalibrated real camera), and how a MAVLink driver gets its frames."""

    #: its video stream over MAVLink (RTP H.264 udp://HOST:PORT, rtsp://, a device)
    video: str | None = None
    #: accept video only from this host (or host:port); None: lock onto the first sender
    video_source: str | None = None
    #: capture → arrival, for a stream whose packets carry no usable clock (see the README)
    stream_latency_s: Annotated[float, Field(ge=0, lt=2)] = 0.0


class VehicleSetup(ConfigModel):
    """The vehicle's cameras (``vehicle.cameras``), shared by the simulator and MAVLink drivers,
    and the height it never flies above by its own rules (``max_altitude_m``)."""

    cameras: dict[str, VehicleCameraConfig]
    #: the vehicle's own ceiling above its take-off point (the AR.Drone's
    #: ``control:altitude_max``); None: none of its own (the geofence's applies)
    max_altitude_m: Annotated[float, Field(gt=0, le=1000)] | None = None


KeyName = Annotated[str, Field(min_length=1, max_length=12)]


class ConsoleKeysConfig(ConfigModel):
    """The console's keys (``KeyboardEvent.key`` names, case-insensitive): seed 000's."""

    forward: KeyName = "w"
    back: KeyName = "s"
    left: KeyName = "a"
    right: KeyName = "d"
    yaw_left: KeyName = "q"
    yaw_right: KeyName = "e"
    up: KeyName = "]"
    down: KeyName = "["
    takeoff: KeyName = "t"
    land: KeyName = "l"
    emergency: KeyName = "r"
    autopilot: KeyName = "y"
    follow_mode: KeyName = "f"

    @model_validator(mode="after")
    def _distinct(self) -> ConsoleKeysConfig:
        seen: dict[str, str] = {}
        for name, key in self.model_dump().items():
            if key.lower() in seen:
                raise ValueError(f"{name} and {seen[key.lower()]} both use the key {key!r}")
            seen[key.lower()] = name
        return self


class GeofenceConfig(ConfigModel):
    """The autopilot's own fence, checked on every setpoint and on every goto, orbit and
    survey before it flies (0 / null: that limit is off; on by default)."""

    max_distance_m: Annotated[float, Field(ge=0)] = 500.0  # horizontal, from home
    max_altitude_m: Annotated[float, Field(ge=0)] = 120.0  # above home
    #: goto, orbit and survey never planned lower than this above home (null: off)
    min_altitude_m: Annotated[float, Field(ge=-100, le=100)] | None = 1.0
    polygon_m: list[tuple[FiniteFloat, FiniteFloat]] | None = None  # north, east (local)
    lookahead_s: Annotated[float, Field(gt=0, le=10)] = 1.0  # velocity setpoints

    @field_validator("polygon_m")
    @classmethod
    def _polygon(cls, value):
        if value is not None:
            from shapely.geometry import Polygon

            if len(value) < 3 or not Polygon(value).is_valid or Polygon(value).area <= 0:
                raise ValueError("a polygon needs 3 or more corners and must not cross itself")
        return value


class BatteryReserveConfig(ConfigModel):
    """The battery reserve for the way home (autopilot/control/battery.py)."""

    reserve_fraction: Annotated[float, Field(ge=0, le=0.9)] = 0.0  # 0: off
    action: Literal["return", "land"] = "return"  # return: the vehicle's RTL; land: here
    speed_m_s: Annotated[float, Field(gt=0, le=30)] = 5.0  # the vehicle's return speed
    descent_m_s: Annotated[float, Field(gt=0, le=10)] = 0.7  # its landing speed (MPC_LAND_SPEED)
    #: its descent above ``slow_below_m`` (MPC_Z_V_AUTO_DN above MPC_LAND_ALT1)
    fast_descent_m_s: Annotated[float, Field(gt=0, le=20)] = 1.5
    slow_below_m: Annotated[float, Field(ge=0, le=500)] = 10.0
    margin: Annotated[float, Field(ge=1, le=10)] = 1.5  # on the estimated cost of getting home
    #: the vehicle's RTL_RETURN_ALT (it climbs there first) and climb speed (MPC_Z_V_AUTO_UP)
    return_altitude_m: Annotated[float, Field(ge=0, le=500)] = 60.0
    climb_m_s: Annotated[float, Field(gt=0, le=20)] = 3.0


class FailsafeConfig(ConfigModel):
    geofence: GeofenceConfig = GeofenceConfig()
    battery: BatteryReserveConfig = BatteryReserveConfig()


class ConsoleConfig(ConfigModel):
    """The operator console (``--console HOST:PORT``): video, values, keyboard flying."""

    video_fps: Annotated[float, Field(gt=0, le=30)] = 15.0  # MJPEG rate (a viewer may ask less)
    jpeg_quality: Annotated[int, Field(ge=20, le=95)] = 70
    state_rate_hz: Annotated[float, Field(gt=0, le=20)] = 5.0  # values, map and status pushed
    keys: ConsoleKeysConfig = ConsoleKeysConfig()
    speed_m_s: Annotated[float, Field(gt=0, le=10)] = 1.5  # W/S/A/D
    vertical_speed_m_s: Annotated[float, Field(gt=0, le=5)] = 0.8  # ] and [
    yaw_rate_deg_s: Annotated[float, Field(gt=0, le=180)] = 45.0  # Q/E
    #: wall clock: a held key the browser stops renewing counts as released after this long
    key_timeout_s: Annotated[float, Field(ge=0.1, le=2)] = 0.5
    min_altitude_m: Annotated[float, Field(ge=0.3, le=20)] = 0.8  # [ stops here (L lands)
    max_altitude_m: Annotated[float, Field(ge=2, le=500)] = 30.0  # ] stops here
    takeoff_altitude_m: Annotated[float, Field(ge=1, le=50)] = 3.0  # T
