"""What the simulated vehicle offers beyond the :class:`~drivers.base.Vehicle` interface, as a
PX4 vehicle does over MAVLink (and what the MAVLink face serves for ``autopilot sim``):
parameters, missions and their progress, return to launch, modes, the reposition and speed
commands, the camera and its photos, home and the geofence. Mixed into
:class:`~drivers.sim.driver.SimDriver`, whose hooks it calls: commands and calls run on the
simulator's thread between physics batches (``_command``, ``_call``)."""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.base import FlightMode
from drivers.mission import MissionItem, MissionType
from drivers.sim.flight.navigator import MissionStatus, NavEvent
from drivers.sim.flight.param_tables import PARAM_TABLES
from drivers.sim.flight.params import ParamSpec
from drivers.sim.outlets import Outlets
from drivers.sim.runner import SimRunner
from drivers.sim.simulator import Photo, Simulator

if TYPE_CHECKING:
    from drivers.sim.config import SimConfig


class Px4Services:
    # provided by the driver
    runner: SimRunner
    outlets: Outlets
    _param_defaults: dict[str, float]
    config: SimConfig
    _failure: Exception | None

    def _require_sim(self) -> Simulator:
        raise NotImplementedError

    async def _command(self, name: str, *args: Any) -> None:
        raise NotImplementedError

    async def _call(self, name: str, fn, *args: Any) -> Any:
        raise NotImplementedError

    def param_specs(self) -> list[ParamSpec]:
        """The vehicle's parameters (its firmware's table), in index order."""
        specs = self._param_specs()
        return [specs[name] for name in sorted(specs)]

    def _param_specs(self) -> dict[str, ParamSpec]:
        return PARAM_TABLES[self.config.firmware].specs

    def param(self, name: str) -> float:
        """A parameter's current value (KeyError if there is none)."""
        if self.runner.sim is not None:
            return self.runner.sim.ground_params[name]
        specs = self._param_specs()
        if name not in specs:
            raise KeyError(name)
        return self._param_defaults.get(name, specs[name].default)

    async def get_param(self, name: str) -> float:
        """:meth:`param` as the MAVLink drivers ask for it (one value read from another
        thread: safe, see :class:`~drivers.sim.flight.params.Parameters`)."""
        return float(self.param(name))

    async def set_param(self, name: str, value: float) -> float:
        """Set one of the firmware's parameters; returns the stored value. Refused
        (:class:`ParamError`) for unknown names and values of the wrong type or out of range."""
        return await self._call(f"set {name}", self._require_sim().set_param, name, value)

    async def firmware_command(self, name: str, *args: Any) -> Any:
        """A command of the firmware's own (ArduCopter's ``set_copter_mode``,
        ``mission_start``) on the simulator's thread; its result."""
        sim = self._require_sim()
        return await self._call(name, sim.command, name, *args)

    async def start_mission(self) -> None:
        await self._command("start_mission")

    async def return_to_launch(self) -> None:
        await self._command("return_to_launch")

    async def set_mode(self, mode: FlightMode) -> None:
        await self._command("set_mode", mode)

    async def reposition(self, target_ned_m, yaw_rad: float = float("nan"),
                         speed_m_s: float = float("nan")) -> None:
        await self._command("reposition", target_ned_m, yaw_rad, speed_m_s)

    async def set_speed(self, speed_m_s: float) -> None:
        await self._command("set_speed", speed_m_s)

    async def take_photo(self) -> None:
        await self._command("take_photo")

    async def start_photos(self, interval_s: float, count: int) -> None:
        """IMAGE_START_CAPTURE: one photo, or ``count`` every ``interval_s`` (0: until
        :meth:`stop_photos`)."""
        await self._command("start_photos", interval_s, count)

    async def stop_photos(self) -> None:
        await self._command("stop_photos")

    async def set_trigger_distance(self, distance_m: float, trigger_now: bool = False) -> None:
        sim = self._require_sim()
        await self._call("set trigger distance", sim.flight.navigator.set_trigger_distance,
                         distance_m, trigger_now)

    async def upload_mission(self, items: list[MissionItem],
                             mission_type: int = MissionType.MISSION) -> None:
        await self._command("set_mission", list(items), mission_type)

    def mission_items(self, mission_type: int = MissionType.MISSION) -> list[MissionItem]:
        return self._require_sim().flight.navigator.items(mission_type)

    async def set_mission_current(self, seq: int) -> None:
        await self._command("set_mission_current", seq)

    @property
    def mission_status(self) -> MissionStatus:
        return self._require_sim().flight.navigator.status

    def mission_events(self, buffer: int = 64) -> AsyncIterator[NavEvent]:
        """Mission progress (current item, item reached, finished) and video events."""
        return self.outlets.mission_events.subscribe(buffer)

    def photos(self, buffer: int = 16) -> AsyncIterator[Photo]:
        """Photos taken by the vehicle's camera (missions, trigger distance, commands)."""
        return self.outlets.photos.subscribe(buffer)

    def home(self) -> tuple[float, float, float, np.ndarray] | None:
        """Home as (lat °, lon °, alt AMSL m, local NED), None before the first arming."""
        sim = self._require_sim()
        home = sim.flight.navigator.home
        if home is None:
            return None
        lat, lon, alt = sim.origin.to_global(*(float(v) for v in home))
        return lat, lon, alt, home

    @property
    def global_origin(self):
        return self._require_sim().origin

    @property
    def home_ned_m(self) -> np.ndarray | None:
        home = self._require_sim().flight.navigator.home
        return None if home is None else np.array(home, dtype=float)

    @property
    def geofence_breach(self) -> str | None:
        """Why the vehicle is outside its geofence (None: inside, or no fence)."""
        return self._require_sim().flight.geofence_breach

    async def gcs_heartbeat(self) -> None:
        """A ground station was heard (feeds the data-link loss failsafe, NAV_DLL_ACT)."""
        sim = self.runner.sim
        if sim is None or self._failure is not None:
            return
        await self._call("gcs heartbeat", sim.command, "gcs_heartbeat")
