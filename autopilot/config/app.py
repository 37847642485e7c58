"""The whole of ``config.yaml``: :class:`AppConfig`."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import (
    Field,
    create_model,
    model_validator,
)
from pydantic_core import PydanticCustomError

from autopilot.config.base import (
    ConfigModel,
)
from autopilot.config.sections import (
    ConsoleConfig,
    ControlConfig,
    EstimationConfig,
    FailsafeConfig,
    LinkConfig,
    LogConfig,
    PerceptionConfig,
    PhotoConfig,
    RuntimeConfig,
    VehicleSetup,
    kind_fields,
)
from autopilot.vehicle_kinds import DRIVER_NAMES
from drivers.sim.config import SimConfig


class AppConfigRules(ConfigModel):
    """The rules of the whole configuration (:data:`AppConfig` is this with its sections)."""

    @model_validator(mode="after")
    def _target_settings(self) -> AppConfigRules:
        from autopilot.targets import validate_sections

        validate_sections(self.targets, lambda kind: kind.settings, "targets",
                          unknown="unknown target kind", list_known=True, fill_defaults=True)
        return self

    @model_validator(mode="before")
    @classmethod
    def _cameras_moved(cls, data: Any) -> Any:
        sim = data.get("sim") if isinstance(data, dict) else None
        if isinstance(sim, dict) and sim.get("cameras"):
            raise PydanticCustomError(
                "moved", "moved to vehicle.cameras (one section for the simulator and MAVLink "
                "drivers alike)", {"key_path": ("sim", "cameras")})
        return data

    @model_validator(mode="after")
    def _simulator_cameras(self) -> AppConfigRules:
        # the simulator renders the vehicle's cameras (validated here, once)
        object.__setattr__(self, "sim", self.sim.model_copy(
            update={"cameras": dict(self.vehicle.cameras)}))
        return self


#: The whole of ``config.yaml``: the sections, with the shipped target kinds' top-level ones
#: (the ``rover``) after ``photos``.
AppConfig = create_model(
    "AppConfig", __base__=AppConfigRules, __module__=__name__,
    __doc__="The whole of ``config.yaml``.",
    driver=(Literal[DRIVER_NAMES], ...),  # autopilot/vehicle_kinds.py
    link=(LinkConfig, ...),
    vehicle=(VehicleSetup, ...),
    runtime=(RuntimeConfig, ...),
    perception=(PerceptionConfig, ...),
    estimation=(EstimationConfig, ...),
    control=(ControlConfig, ...),
    photos=(PhotoConfig, ...),
    **kind_fields(""),
    log=(LogConfig, ...),
    console=(ConsoleConfig, ConsoleConfig()),
    failsafe=(FailsafeConfig, FailsafeConfig()),
    sim=(SimConfig, ...),  # its cameras are vehicle.cameras
    #: how the plugins' target kinds are found (:mod:`autopilot.targets`), by kind: each
    #: section validated by its kind's settings model, whose defaults apply when it is absent
    targets=(dict[str, Any], Field(default_factory=dict)),
)
