"""The configuration's sections (``runtime``, ``perception``, ``estimation``, ``control``,
``photos``, ``link``, ``vehicle``, ``rover``, ``log``, ``console``, ``failsafe``), each a
model whose fields carry their units and bounds."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import (
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)

from autopilot.config.base import (
    ColorName,
    ConfigModel,
    FiniteFloat,
    HsvTriple,
    NonNegative,
    Positive,
)
from drivers.sim.config import CameraConfig


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


class BallPerceptionConfig(ConfigModel):
    camera: str
    color: ColorName
    #: Explicit HSV ranges ([[h, s, v], [h, s, v]] pairs) instead of the colour's preset.
    hsv_ranges: list[tuple[HsvTriple, HsvTriple]] | None = None
    diameter_m: Positive
    open_kernel_px: Annotated[int, Field(ge=1, le=31)]
    close_kernel_px: Annotated[int, Field(ge=1, le=31)]
    min_radius_px: Positive
    max_radius_px: Positive
    min_circularity: Annotated[float, Field(ge=0, le=1)]
    min_fill_ratio: Annotated[float, Field(ge=0, le=1)]
    min_solidity: Annotated[float, Field(ge=0, le=1)] = 0.85  # blob area / its convex hull's


class MarkerPerceptionConfig(ConfigModel):
    """The followed fiducial marker (seed 002: ArUco id 36, 16 cm) and how it is found."""

    camera: str
    backend: Literal["aruco", "apriltag"]
    #: OpenCV dictionary (DICT_ARUCO_ORIGINAL, DICT_4X4_50, DICT_APRILTAG_36h11, …) or an
    #: AprilTag family (tag36h11, tag25h9, tag16h5)
    dictionary: str
    id: Annotated[int, Field(ge=0)]
    size_m: Positive  # side of the black square
    corner_refinement: Literal["edges", "subpix", "apriltag", "contour", "none"]
    min_perimeter_px: Positive

    @field_validator("dictionary")
    @classmethod
    def _known_dictionary(cls, name: str, info: ValidationInfo) -> str:
        from drivers.markers import apriltag_family_name, aruco_dictionary_name

        if info.data.get("backend") == "apriltag":
            apriltag_family_name(name)
        else:
            aruco_dictionary_name(name)
        return name


class ImagePerceptionConfig(ConfigModel):
    """How a known flat image (hover_image, seed 000) is found; which image, and its size, are
    the mission step's."""

    camera: str
    features: Literal["orb", "akaze"]
    reference_features: Annotated[int, Field(ge=100, le=20000)]
    frame_features: Annotated[int, Field(ge=100, le=20000)]
    reference_px: Annotated[int, Field(ge=100, le=4000)]
    ratio: Annotated[float, Field(gt=0, lt=1)]
    ransac_px: Positive
    min_inliers: Annotated[int, Field(ge=6)]
    #: frames tracked (Lucas–Kanade) between full detections; 0: a full detection every frame
    track_frames: Annotated[int, Field(ge=0, le=100)] = 0
    #: ours, or seed 000's pipeline as a baseline (autopilot bench hover_image)
    detector: Literal["ours", "seed000"] = "ours"


class PadPerceptionConfig(ConfigModel):
    """How a landing pad (land_pad, seed 001) is found; its kind, colour and size are the
    mission step's."""

    camera: str
    #: circle pads: explicit HSV ranges instead of the step's colour's preset
    hsv_ranges: list[tuple[HsvTriple, HsvTriple]] | None = None
    min_radius_px: Positive
    max_fit_error: Annotated[float, Field(gt=0, le=0.5)]  # RMS radial residual ÷ radius
    #: circle pads with a rangefinder height: the disc fitted on the ground may be this much
    #: smaller or larger than its size (else it is something else of that colour)
    size_tolerance: Annotated[float, Field(gt=0, lt=1)]
    #: marker pads: the dictionary of its markers (their ids: the mission step's)
    backend: Literal["aruco", "apriltag"]
    dictionary: str
    min_perimeter_px: Positive
    #: ours, or seed 001's multi-scale template matching (circle pads) as a baseline
    #: (autopilot bench land_pad)
    detector: Literal["ours", "seed001"] = "ours"

    @field_validator("dictionary")
    @classmethod
    def _known_dictionary(cls, name: str, info: ValidationInfo) -> str:
        from drivers.markers import apriltag_family_name, aruco_dictionary_name

        if info.data.get("backend") == "apriltag":
            apriltag_family_name(name)
        aruco_dictionary_name(name)
        return name


class PerceptionConfig(ConfigModel):
    ball: BallPerceptionConfig
    marker: MarkerPerceptionConfig
    image: ImagePerceptionConfig
    pad: PadPerceptionConfig


class ImageEstimationConfig(ConfigModel):
    #: an image lies still on the ground: how hard it may seem to move, and how fast at first
    accel_noise_m_s2: Positive = 0.3
    initial_velocity_std_m_s: Positive = 0.3
    position_noise_px: Positive  # the image centre's bearing noise
    size_noise_px: Positive  # noise of its apparent width (range noise)
    heading_noise_deg: Positive  # of the direction of its top, one detection
    #: learn the down camera's mount tilt from the image, which lies level
    #: (:mod:`autopilot.estimation.level_mount`), after this many frames, to this σ at best
    learn_mount: bool = True
    mount_min_frames: Annotated[int, Field(ge=5, le=10_000)] = 30
    mount_residual_std_deg: NonNegative = 0.1
    #: a frame implying more tilt than this is a bad pose, not the mount (the mount's own
    #: error is a degree or two; raise it for a camera bolted on by eye)
    mount_max_tilt_deg: Annotated[float, Field(gt=0.0, le=30.0)] = 5.0


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


class MarkerEstimationConfig(ConfigModel):
    """Measurement noise of marker detections (the motion model is ``estimation.target``'s)."""

    pixel_noise_px: Positive  # bearing noise of the marker's centre
    size_noise_px: Positive  # noise of its side length in the image (range noise)
    heading_noise_deg: Positive  # direction of its face, one clear detection
    ambiguous_heading_noise_deg: Positive  # … when the two poses fit about equally well
    heading_accel_noise_deg_s2: Positive  # how hard the face may turn


class PadEstimationConfig(ConfigModel):
    accel_noise_m_s2: Positive  # how hard the pad may move (a pad on the ground: hardly)
    initial_velocity_std_m_s: Positive = 0.5  # how fast it may be moving when first seen
    position_noise_px: Positive  # bearing noise of the pad's centre
    size_noise_px: Positive  # of its apparent size (range noise, without the rangefinder)
    height_noise_m: Positive  # of the ground's height from the rangefinder
    heading_noise_deg: Positive  # marker pads: of the direction of its top, one detection


class RelativeEstimationConfig(ConfigModel):
    """The relative-state filter of land_on_rover (autopilot/estimation/relative.py): the drone
    relative to the rover's deck, fused from UWB ranges, the deck's tag, the rangefinder, the
    rover's own reports and the drone's velocity."""

    accel_noise_m_s2: Positive  # white acceleration beyond the modelled one (process noise)
    jerk_noise_m_s3: Positive  # how fast the rover's acceleration may change
    accel_time_constant_s: Positive  # how long its acceleration lasts (Gauss–Markov)
    yaw_accel_noise_rad_s2: Positive  # how hard its turn rate may change
    drone_velocity_noise_m_s: NonNegative  # of the drone's velocity changes (the filter's input)
    uwb_range_noise_m: Positive  # one range (σ)
    uwb_gate_chi2: Positive  # one range's innovation gate (1 dof)
    tag_pixel_noise_px: Positive  # the tag centre's bearing noise
    tag_range_noise_fraction: Positive  # the tag's range noise, a fraction of the range
    tag_heading_noise_deg: Positive
    rangefinder_noise_m: Positive
    rover_velocity_noise_m_s: Positive  # the rover's reported velocity (σ, at least)
    rover_heading_noise_deg: Positive  # its compass, each reading (σ, at least)
    compass_bias_std_deg: Positive  # its compass's slowly wandering bias (σ)
    course_noise_deg: NonNegative  # its course over the ground vs its heading (wheel slip)
    #: how far apart the rover's reported position and the drone's own may be (their two GNSS
    #: errors: a slowly wandering bias, σ per axis), and how slowly it wanders
    rough_position_std_m: tuple[Positive, Positive, Positive]
    bias_time_constant_s: Positive
    gate_chi2: Positive  # 3-dof measurements (tag, rough position)
    history_s: Annotated[float, Field(gt=0, le=5)]  # a measurement this late is still fused
    max_extrapolation_s: Positive  # the estimate is not predicted further than this


class Seed004EstimationConfig(ConfigModel):
    """Seed 004's fused filter (autopilot/estimation/seed004.py), the baseline of
    ``autopilot bench landing --strategy seed004``: its R values (each a single diagonal
    value), its timers, and what the seed does not give (Q, R_px4, R_compass, R_range)."""

    update_rate_hz: Positive
    predict_rate_hz: Positive
    r_uwb: Positive
    r_tag: Positive
    r_px4: Positive
    r_compass: Positive
    r_range: Positive
    drone_accel_var: Positive
    rover_accel_var: Positive
    yaw_rate_var: Positive
    initial_rover_std_m: Positive
    initial_velocity_std_m_s: Positive


class EstimationConfig(ConfigModel):
    target: TargetEstimationConfig
    marker: MarkerEstimationConfig
    image: ImageEstimationConfig
    pad: PadEstimationConfig
    relative: RelativeEstimationConfig
    seed004: Seed004EstimationConfig
    navigation: NavigationUncertaintyConfig
    #: How far the cameras may be off their nominal mount (σ per axis): a fixed rotation that
    #: every target seen through them inherits, as an attitude error that averaging frames
    #: does not remove.
    camera_mount_std_deg: Annotated[float, Field(ge=0, le=10)]


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


class ControlConfig(ConfigModel):
    follow: FollowControlConfig
    trajectory: TrajectoryControlConfig
    seed004_landing: Seed004LandingConfig


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
    """The vehicle's cameras (``vehicle.cameras``), shared by the simulator and MAVLink drivers."""

    cameras: dict[str, VehicleCameraConfig]


class DeckTagConfig(ConfigModel):
    """The tag printed on the rover's deck: the nested marker pad (five markers of one
    dictionary — AprilTag families included — the small one in the centre), its top towards
    the rover's front."""

    kind: Literal["markers"]
    size_m: Annotated[float, Field(gt=0.1, le=5)]
    ids: tuple[int, int, int, int, int]
    dictionary: str

    @model_validator(mode="after")
    def _layout(self) -> DeckTagConfig:
        from autopilot.perception.pad import marker_pad_layout

        marker_pad_layout(self.size_m, self.ids, self.dictionary)  # raises ValueError
        return self


class RoverUwbConfig(ConfigModel):
    """Where the UWB anchors are on the rover (FRD from its reference point, the ground under
    the deck's centre) and the tag on the drone (FRD from its body origin)."""

    anchors_frd_m: Annotated[list[tuple[float, float, float]], Field(min_length=1,
                                                                       max_length=16)]
    tag_frd_m: tuple[float, float, float]


class RoverConfig(ConfigModel):
    """The rover land_on_rover lands on, as the autopilot knows it (a scenario's rover is built
    to match unless it says otherwise)."""

    deck_size_m: tuple[Annotated[float, Field(gt=0.2, le=10)],
                       Annotated[float, Field(gt=0.2, le=10)]]  # along the rover, across
    deck_height_m: Annotated[float, Field(ge=0, le=5)]  # its top above the reference point
    camera: str  # the camera that sees the deck's tag (pointing down)
    tag: DeckTagConfig
    uwb: RoverUwbConfig

    @model_validator(mode="after")
    def _fits(self) -> RoverConfig:
        if self.tag.size_m > min(self.deck_size_m):
            raise ValueError(f"tag.size_m ({self.tag.size_m}) is larger than the deck "
                             f"({list(self.deck_size_m)})")
        return self


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
