"""Configuration: ``config.yaml`` (the defaults) + command-line overrides → validated models:
the sections (:mod:`.sections`, the whole in :mod:`.app`), YAML with its lines
(:mod:`.yaml_source`), overrides, validation and profiles (:mod:`.loader`).

Validation happens once, at the boundary, before anything flies. Every problem is reported with
the file, the line and the dotted key path, and what was expected, e.g.::

    config.yaml:17: vehicle.cameras.front.width_px: Input should be greater than or equal to 16
"""

from autopilot.config.app import (
    AppConfig,
)
from autopilot.config.base import (
    ColorName,
    ConfigError,
    ConfigModel,
    FiniteFloat,
    HsvTriple,
    InputError,
    KeyPath,
    NonNegative,
    Positive,
    Problem,
)
from autopilot.config.loader import (
    PROFILES,
    apply_overrides,
    known_keys,
    load_config,
    merge_located,
    unknown_key_hint,
    validate,
    with_profile,
)
from autopilot.config.sections import (
    BatteryReserveConfig,
    ConsoleConfig,
    ConsoleKeysConfig,
    ControlConfig,
    EstimationConfig,
    FailsafeConfig,
    FollowControlConfig,
    FrameLogConfig,
    GeofenceConfig,
    KeyName,
    LinkConfig,
    LogConfig,
    NavigationUncertaintyConfig,
    PerceptionConfig,
    PhotoConfig,
    RuntimeConfig,
    Seed004LandingConfig,
    TargetEstimationConfig,
    TrajectoryControlConfig,
    VehicleCameraConfig,
    VehicleSetup,
)
from autopilot.config.yaml_source import (
    MAX_YAML_DEPTH,
    MAX_YAML_NODES,
    Located,
    dotted_key,
    load_yaml,
    parse_yaml,
)

__all__ = [
    "MAX_YAML_DEPTH",
    "MAX_YAML_NODES",
    "PROFILES",
    "AppConfig",
    "BatteryReserveConfig",
    "ColorName",
    "ConfigError",
    "ConfigModel",
    "ConsoleConfig",
    "ConsoleKeysConfig",
    "ControlConfig",
    "EstimationConfig",
    "FailsafeConfig",
    "FiniteFloat",
    "FollowControlConfig",
    "FrameLogConfig",
    "GeofenceConfig",
    "HsvTriple",
    "InputError",
    "KeyName",
    "KeyPath",
    "LinkConfig",
    "Located",
    "LogConfig",
    "NavigationUncertaintyConfig",
    "NonNegative",
    "PerceptionConfig",
    "PhotoConfig",
    "Positive",
    "Problem",
    "RuntimeConfig",
    "Seed004LandingConfig",
    "TargetEstimationConfig",
    "TrajectoryControlConfig",
    "VehicleCameraConfig",
    "VehicleSetup",
    "apply_overrides",
    "dotted_key",
    "known_keys",
    "load_config",
    "load_yaml",
    "merge_located",
    "parse_yaml",
    "unknown_key_hint",
    "validate",
    "with_profile"
]
