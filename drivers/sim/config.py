"""Configuration of the simulated vehicle: physics, sensors, cameras and the PX4-like flight stack.

Models only: the values live in the project's ``config.yaml`` (section ``sim``), which is the
single source of defaults. Unknown keys, wrong types and out-of-range values are rejected.
Names carry their units; the PX4 parameter each one mirrors is noted where there is one.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from drivers.camera_model import distortion_problem, pinhole
from drivers.sim.faults import Fault
from drivers.sim.flight.params import validate_overrides

Positive = Annotated[float, Field(gt=0)]
NonNegative = Annotated[float, Field(ge=0)]
Fraction = Annotated[float, Field(ge=0, le=1)]
Vec3 = tuple[float, float, float]
Gains3 = tuple[NonNegative, NonNegative, NonNegative]
Coefficient = Annotated[float, Field(ge=-2, le=2)]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class CameraConfig(_Model):
    """A body-mounted camera. Orientation is the boresight's direction in the body frame:
    ``pitch_deg`` 0 looks forward, -90 straight down; image "up" stays towards body -z
    (or body +x for a straight-down camera)."""

    enabled: bool
    width_px: Annotated[int, Field(ge=16, le=4096)]
    height_px: Annotated[int, Field(ge=16, le=4096)]
    hfov_deg: Annotated[float, Field(gt=10, lt=170)]
    rate_hz: Annotated[float, Field(gt=0, le=240)]
    position_frd_m: Vec3
    pitch_deg: Annotated[float, Field(ge=-90, le=90)]
    yaw_deg: Annotated[float, Field(ge=-180, le=180)]
    latency_s: Annotated[float, Field(ge=0, le=1)]
    #: A real camera's imperfections (the keys below); false: an ideal pinhole image, as
    #: MuJoCo renders it, with no distortion reported (the keys below are then ignored).
    realistic: bool
    #: Lens distortion, OpenCV's k1 k2 p1 p2 k3 (normalised coordinates); reported with each
    #: frame's intrinsics. Must keep the image one-to-one out to its corners.
    distortion: tuple[Coefficient, Coefficient, Coefficient, Coefficient, Coefficient]
    #: Gaussian read noise, standard deviation in 8-bit digital numbers (per pixel, per channel).
    noise_std_dn: Annotated[float, Field(ge=0, le=50)]
    #: Exposure time: motion blur from the vehicle's motion during it (0: none).
    exposure_s: Annotated[float, Field(ge=0, le=0.1)]
    #: Rolling shutter: time from the first row's exposure to the last's (0: global shutter).
    rolling_shutter_s: Annotated[float, Field(ge=0, le=0.1)]
    #: Capture latency jitter: each frame arrives ``latency_s`` plus a half-normal delay of
    #: this scale later (frames keep their order); its stamp stays the capture time.
    latency_jitter_s: Annotated[float, Field(ge=0, le=0.1)]
    #: Share of frames the camera drops (never delivered; the sequence number skips them).
    drop_fraction: Annotated[float, Field(ge=0, lt=1)]
    #: The mount's error: the camera is turned off its nominal angles by a rotation drawn once
    #: per (seed, camera), σ per axis in degrees; frames report the nominal mount.
    mount_error_deg: Annotated[float, Field(ge=0, le=10)]
    #: Auto-exposure steps: the brightness changes by this fraction (up or down) at random
    #: times, on average every ``auto_exposure_interval_s`` (0: constant brightness).
    auto_exposure_step: Annotated[float, Field(ge=0, le=0.5)]
    auto_exposure_interval_s: Annotated[float, Field(gt=0)]
    #: What the image goes through before the autopilot sees it: ``jpeg`` a JPEG round trip
    #: at ``codec_quality``, ``h264`` an H.264 round trip at ``codec_bitrate_bps`` (the
    #: artefacts of a compressed stream), ``none`` the raw pixels.
    codec: Literal["none", "jpeg", "h264"]
    codec_quality: Annotated[int, Field(ge=1, le=100)]
    #: ``codec: h264``: libx264 at this bit rate, as the network stream (drivers/video.py)
    codec_bitrate_bps: Annotated[int, Field(ge=50_000, le=100_000_000)]
    #: The intrinsics the frames report: ``fitted`` a calibration ``autopilot calibrate``
    #: fitted on simulated board views of this camera (cached), ``truth`` the true ones.
    #: A ``calibration`` file, when given, is reported instead of either.
    sim_calibration: Literal["fitted", "truth"]
    #: OpenCV or ROS calibration YAML: the intrinsics and distortion the autopilot uses (over
    #: MAVLink: None gives the nominal pinhole of the keys above, and a warning; in the
    #: simulator: see ``sim_calibration``)
    calibration: str | None = None

    @model_validator(mode="after")
    def _physical(self) -> CameraConfig:
        period = 1.0 / self.rate_hz
        for key in ("exposure_s", "rolling_shutter_s"):
            if getattr(self, key) >= period:
                raise ValueError(f"{key} ({getattr(self, key)}) must be shorter than the frame "
                                 f"period (1 / rate_hz = {period:.4g} s)")
        if self.realistic and any(self.distortion):
            problem = distortion_problem(pinhole(self.width_px, self.height_px, self.hfov_deg,
                                                 self.distortion))
            if problem:
                raise ValueError(f"distortion {list(self.distortion)}: {problem}")
        return self


class VehicleConfig(_Model):
    """What Python adds to the MJCF model (mass, inertia, rotor layout and thrust limits are
    read from the model itself)."""

    model: str
    initial_north_east_m: tuple[float, float]
    initial_yaw_deg: Annotated[float, Field(ge=-180, le=180)]
    motor_time_constant_s: Annotated[float, Field(gt=0, le=1)]
    rotor_drag_n_per_m_s: NonNegative
    body_drag_coefficient: NonNegative
    body_area_frd_m2: tuple[NonNegative, NonNegative, NonNegative]
    prop_diameter_m: Positive
    propulsion_efficiency: Annotated[float, Field(gt=0, le=1)]


class BatteryConfig(_Model):
    cells: Annotated[int, Field(ge=1, le=14)]
    capacity_mah: Positive
    internal_resistance_ohm: NonNegative
    initial_fraction: Fraction
    avionics_power_w: NonNegative
    low_fraction: Fraction
    critical_fraction: Fraction


class WindConfig(_Model):
    steady_ned_m_s: Vec3
    #: Standard deviation of the gusts (per horizontal axis; vertical gets 30 % of it).
    gust_mps: NonNegative
    gust_time_constant_s: Positive


class NavigationGradeConfig(_Model):
    """Error model of one navigation grade (PX4's EKF output with that aiding): Gauss–Markov
    processes (stationary σ, correlation time) that both the flight controller and the
    telemetry see, plus white noise; an optical-flow grade also drifts with distance flown."""

    #: horizontal position error wandering about the truth, per axis (absolute aiding: GNSS,
    #: RTK); 0 for dead reckoning (optical flow), whose error is the drift below
    horizontal_error_m: NonNegative
    horizontal_time_constant_s: Positive
    #: height error (barometer, or the RTK/GNSS height), wandering
    height_error_m: NonNegative
    height_time_constant_s: Positive
    #: white noise on every position axis, each estimate
    position_noise_m: NonNegative
    #: the EKF output's smoothing of the aiding's errors (a first-order lag on the wandering
    #: position and height errors: they move at centimetres per second, not in steps); 0: none
    position_smoothing_s: NonNegative = 0.0
    #: velocity error, per axis, wandering with its own (short) correlation time
    velocity_error_m_s: NonNegative
    velocity_time_constant_s: Positive
    attitude_error_deg: NonNegative  # roll and pitch
    yaw_error_deg: NonNegative
    attitude_time_constant_s: Positive
    #: dead reckoning on a flow sensor: the scale factor's error (σ, drawn once per flight) and
    #: the heading error turn each metre flown into drift; a wandering velocity bias (σ, with
    #: ``horizontal_time_constant_s``) drifts even in a hover. All 0: absolute aiding.
    flow_scale_error: Annotated[float, Field(ge=0, le=0.5)] = 0.0
    flow_velocity_bias_m_s: NonNegative = 0.0


class EstimatorConfig(_Model):
    """PX4's EKF output: ``grade`` chooses which of ``grades`` the vehicle navigates with (each
    value there settable on its own)."""

    grade: Literal["gnss", "rtk", "optical_flow"]
    grades: dict[Literal["gnss", "rtk", "optical_flow"], NavigationGradeConfig]
    gyro_noise_rad_s: NonNegative
    #: Time after boot before the local position is valid (arming is refused until then).
    init_time_s: NonNegative

    @model_validator(mode="after")
    def _chosen_grade_given(self) -> EstimatorConfig:
        if self.grade not in self.grades:
            raise ValueError(f"grade {self.grade!r} has no entry in grades")
        return self

    @property
    def chosen(self) -> NavigationGradeConfig:
        return self.grades[self.grade]


class TelemetryConfig(_Model):
    rate_hz: Annotated[float, Field(ge=1, le=250)]
    latency_s: Annotated[float, Field(ge=0, le=1)]
    latency_jitter_s: Annotated[float, Field(ge=0, le=0.5)]


class RangefinderConfig(_Model):
    """Downward distance sensor (a single-beam lidar). Readings outside [min_m, max_m] are
    absent (NaN), as PX4's ``distance_sensor`` marks them invalid."""

    min_m: NonNegative
    max_m: Positive
    noise_m: NonNegative
    #: share of readings that are wrong: half read max_m (a missed return), half a random
    #: distance short of the truth (dust, rotor-wash debris, a blade in the beam)
    outlier_fraction: Fraction = 0.0
    #: no return when the beam meets the (level) surface further than this from its normal:
    #: the vehicle's tilt from vertical (specular and dark surfaces send too little back)
    max_incidence_deg: Annotated[float, Field(gt=0, le=90)] = 90.0
    #: share of readings lost at random (low-reflectivity patches, sunlight)
    dropout_fraction: Fraction = 0.0

    @model_validator(mode="after")
    def _ordered(self) -> RangefinderConfig:
        if self.min_m >= self.max_m:
            raise ValueError(f"min_m ({self.min_m}) must be below max_m ({self.max_m})")
        return self


class UwbConfig(_Model):
    """UWB ranging between the drone's tag and anchors on a rover (when the scenario has one):
    two-way ranging to every anchor at once."""

    rate_hz: Annotated[float, Field(gt=0, le=100)]
    latency_s: Annotated[float, Field(ge=0, le=1)]
    range_noise_m: NonNegative
    dropout: Fraction  # each anchor's reading is missing with this probability
    nlos_fraction: Fraction  # readings lengthened by a non-line-of-sight path
    nlos_max_m: NonNegative  # by up to this
    max_range_m: Positive
    tag_frd_m: Vec3  # the drone's tag, from its body origin


class RoverLinkConfig(_Model):
    """The rover's own autopilot reporting its state over MAVLink (another system id)."""

    rate_hz: Annotated[float, Field(gt=0, le=100)]
    latency_s: Annotated[float, Field(ge=0, le=2)]
    latency_jitter_s: Annotated[float, Field(ge=0, le=0.5)]
    position_error_m: tuple[NonNegative, NonNegative, NonNegative]  # its GNSS (Gauss–Markov)
    position_error_time_constant_s: Positive
    velocity_noise_m_s: NonNegative
    heading_noise_deg: NonNegative  # its compass, each reading
    heading_bias_deg: NonNegative  # its compass's slowly wandering bias
    system_id: Annotated[int, Field(ge=1, le=255)]
    #: ``autopilot sim``: speak for the rover on the vehicle's MAVLink ports as ``system_id``
    #: (off by default: a ground station that takes the first autopilot it hears could take
    #: the rover)
    mavlink: bool = False


class PositionControlConfig(_Model):
    """PX4 ``mc_pos_control`` (MPC_*). Velocity gains are in m/s² per m/s, as PX4's *_ACC."""

    xy_p: Positive  # MPC_XY_P
    z_p: Positive  # MPC_Z_P
    xy_vel_p: Positive  # MPC_XY_VEL_P_ACC
    xy_vel_i: NonNegative  # MPC_XY_VEL_I_ACC
    xy_vel_d: NonNegative  # MPC_XY_VEL_D_ACC
    z_vel_p: Positive  # MPC_Z_VEL_P_ACC
    z_vel_i: NonNegative  # MPC_Z_VEL_I_ACC
    z_vel_d: NonNegative  # MPC_Z_VEL_D_ACC
    xy_vel_max_m_s: Positive  # MPC_XY_VEL_MAX
    xy_cruise_m_s: Positive  # MPC_XY_CRUISE (HOLD / TAKEOFF / LAND)
    z_vel_max_up_m_s: Positive  # MPC_Z_VEL_MAX_UP
    z_vel_max_down_m_s: Positive  # MPC_Z_VEL_MAX_DN
    tilt_max_deg: Annotated[float, Field(gt=0, lt=90)]  # MPC_TILTMAX_AIR
    thrust_min: Fraction  # MPC_THR_MIN
    thrust_max: Fraction  # MPC_THR_MAX
    #: MPC_THR_HOVER; null: the model's true value (a converged hover-thrust estimator).
    hover_thrust: Fraction | None = None
    brake_accel_m_s2: Positive  # MPC_ACC_HOR, used when HOLD brakes to a stop


class AttitudeControlConfig(_Model):
    """PX4 ``mc_att_control`` (MC_ROLL_P, MC_PITCH_P, MC_YAW_P, MC_YAW_WEIGHT, MC_*RATE_MAX)."""

    p: Gains3
    yaw_weight: Fraction
    rate_max_deg_s: tuple[Positive, Positive, Positive]


class RateControlConfig(_Model):
    """PX4 ``mc_rate_control``. Gains act on angular acceleration (rad/s² per rad/s), so they do
    not depend on the airframe's inertia; PX4's are normalised torque."""

    p: Gains3
    i: Gains3
    d: Gains3
    integrator_limit_rad_s2: Positive
    d_cutoff_hz: Positive


class CommanderConfig(_Model):
    """Modes and failsafes (PX4 commander / navigator)."""

    takeoff_altitude_m: Positive  # MIS_TAKEOFF_ALT
    takeoff_speed_m_s: Positive  # MPC_TKO_SPEED
    takeoff_ramp_s: NonNegative  # MPC_TKO_RAMP_T
    takeoff_accel_m_s2: Positive  # MPC_ACC_UP_MAX: the takeoff climb profile's acceleration
    land_speed_m_s: Positive  # MPC_LAND_SPEED
    descent_speed_m_s: Positive  # MPC_Z_V_AUTO_DN, above land_slow_altitude_m
    land_slow_altitude_m: Positive  # MPC_LAND_ALT2
    offboard_loss_timeout_s: Positive  # COM_OF_LOSS_T
    disarm_after_land_s: NonNegative  # COM_DISARM_LAND
    disarm_preflight_s: Positive  # COM_DISARM_PRFLT


class LandDetectorConfig(_Model):
    """PX4 ``land_detector`` (LNDMC_*)."""

    z_vel_max_m_s: Positive
    xy_vel_max_m_s: Positive
    rot_max_deg_s: Positive
    low_thrust_ratio: Fraction
    trigger_time_s: NonNegative


class FlightStackConfig(_Model):
    rate_loop_hz: Annotated[int, Field(ge=50, le=2000)]
    position_loop_hz: Annotated[int, Field(ge=10, le=500)]
    #: Rotor thrust while armed on the ground, as a fraction of full thrust (PX4's idle PWM).
    motor_idle_fraction: Annotated[float, Field(ge=0, le=0.3)]
    position: PositionControlConfig
    attitude: AttitudeControlConfig
    rates: RateControlConfig
    commander: CommanderConfig
    land_detector: LandDetectorConfig

    @model_validator(mode="after")
    def _integer_ratio(self) -> FlightStackConfig:
        if self.rate_loop_hz % self.position_loop_hz:
            raise ValueError(
                f"rate_loop_hz ({self.rate_loop_hz}) must be an integer multiple of "
                f"position_loop_hz ({self.position_loop_hz})"
            )
        return self


#: the firmwares the simulated vehicle can run: each registered once in each of the places that
#: serve it (drivers/sim/firmwares.py: its flight code; autopilot.run.SIM_VEHICLES: the vehicle
#: flown in process; autopilot.cli.sim.FACES: ``autopilot sim``'s server); a test checks they
#: agree
FIRMWARE_NAMES = ("px4", "ardrone", "ardupilot")


class SimConfig(_Model):
    #: Which world: ``realistic`` (config.yaml's values) or ``ideal`` (the kind world laid over
    #: them from autopilot/profiles/ideal.yaml); see autopilot.config.PROFILES.
    profile: Literal["realistic", "ideal"]
    #: Which autopilot the simulated vehicle runs (drivers/sim/firmwares.py): ``px4`` (the
    #: PX4-like flight stack, spoken to over MAVLink), ``ardupilot`` (ArduCopter, over
    #: MAVLink as ArduCopter SITL) or ``ardrone`` (a Parrot AR.Drone 2.0's firmware, spoken to
    #: over its SDK protocol; laid over by autopilot/vehicles/ardrone.yaml).
    firmware: Literal[FIRMWARE_NAMES] = "px4"
    seed: Annotated[int, Field(ge=0)]
    #: Where the local origin (the vehicle's start, PX4's EKF origin and first home) is on
    #: Earth: latitude °, longitude °, altitude above mean sea level m.
    global_origin: tuple[Annotated[float, Field(ge=-90, le=90)],
                         Annotated[float, Field(ge=-180, le=180)],
                         Annotated[float, Field(ge=-500, le=9000)]]
    #: The firmware's parameters that differ from their defaults, by name: PX4's
    #: (drivers/sim/flight/params.py), or ArduCopter's with ``firmware: ardupilot``
    #: (drivers/sim/flight/arducopter_params.py)
    params: dict[str, float]
    world: str
    physics_rate_hz: Annotated[int, Field(ge=100, le=10000)]
    ground_truth_rate_hz: Annotated[float, Field(gt=0, le=1000)]
    #: Longest physics batch in real-time mode (bounds how late a setpoint takes effect).
    realtime_batch_s: Annotated[float, Field(gt=0, le=0.1)]
    #: Real-time mode: rendering of a frame starts no earlier than this before it is due.
    realtime_render_lead_s: Annotated[float, Field(gt=0, le=1)]
    vehicle: VehicleConfig
    battery: BatteryConfig
    wind: WindConfig
    estimator: EstimatorConfig
    telemetry: TelemetryConfig
    rangefinder: RangefinderConfig
    uwb: UwbConfig
    rover_link: RoverLinkConfig
    flight_stack: FlightStackConfig
    #: Lockstep: what detection is charged in simulated time. ``model``: each detector its
    #: kind's cost in ``compute_cost_ms`` (measured once; deterministic); ``measured``: the
    #: time it really took on this machine, frame by frame (not deterministic); ``fixed``:
    #: ``runtime.lockstep_detection_s`` each. Scaled by ``compute_scale`` (model, measured).
    compute_charge: Literal["model", "measured", "fixed"]
    #: How much slower the emulated companion computer is than this machine's core.
    compute_scale: Annotated[float, Field(gt=0, le=100)]
    #: Per detector kind (ball, marker, image, pad, deck), its mean cost on this machine (ms);
    #: a kind not listed is charged ``runtime.lockstep_detection_s``.
    compute_cost_ms: dict[str, Annotated[float, Field(ge=0, le=1000)]]
    #: the vehicle's cameras (the application fills them in from ``vehicle.cameras``)
    cameras: dict[str, CameraConfig] = Field(default_factory=dict)
    #: injected faults (a mission's ``scenario.faults``; see drivers/sim/faults.py)
    faults: list[Fault] = Field(default_factory=list)

    @model_validator(mode="after")
    def _known_params(self) -> SimConfig:
        from drivers.sim.flight.param_tables import PARAM_TABLES

        table = PARAM_TABLES[self.firmware]
        problems = validate_overrides(self.params, table.specs, table.title, table.source)
        if problems:
            raise ValueError("params: " + "; ".join(problems))
        return self

    @model_validator(mode="after")
    def _integer_ratio(self) -> SimConfig:
        if self.physics_rate_hz % self.flight_stack.rate_loop_hz:
            raise ValueError(
                f"physics_rate_hz ({self.physics_rate_hz}) must be an integer multiple of "
                f"flight_stack.rate_loop_hz ({self.flight_stack.rate_loop_hz})"
            )
        return self
