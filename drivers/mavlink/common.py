"""What every MAVLink driver shares: the monotonic clock, the vehicle-time mapping, and
cameras that arrive as network video streams."""

from __future__ import annotations

import math
from collections.abc import AsyncIterator, Mapping

from drivers.base import CameraInfo, Frame, Vehicle
from drivers.clock import MonotonicClock
from drivers.mavlink.link import BootTimeMapper


class MavlinkVehicle(Vehicle):
    """Base of the MAVLink drivers (the rest of :class:`Vehicle` is theirs)."""

    def __init__(self) -> None:
        self._clock = MonotonicClock()
        self._boot = BootTimeMapper()
        self._video: dict[str, object] = {}  # name → VideoSource

    @property
    def clock(self) -> MonotonicClock:
        return self._clock

    @property
    def cameras(self) -> Mapping[str, CameraInfo]:
        return {name: source.info for name, source in self._video.items()}

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
