"""The simulated vehicle's outputs as the driver's streams: each kind of output published to
its own :class:`~drivers.slots.Broadcast` (a camera's frames to that camera's, which turns the
camera on for its first subscriber and off after its last), all closed together when the
vehicle goes away."""

from __future__ import annotations

from collections.abc import Callable, Iterable

from drivers.base import Frame, RoverState, UwbRanges, VehicleState
from drivers.sim.flight.navigator import NavEvent
from drivers.sim.simulator import GroundTruth, Photo, SimOutput
from drivers.slots import Broadcast


class Outlets:
    def __init__(self, cameras: Iterable[str],
                 toggle_camera: Callable[[str, bool], None]) -> None:
        self.telemetry: Broadcast[VehicleState] = Broadcast()
        self.truth: Broadcast[GroundTruth] = Broadcast()
        #: the flight stack's messages: (delivery time, text)
        self.events: Broadcast[tuple[float, str]] = Broadcast()
        self.mission_events: Broadcast[NavEvent] = Broadcast()
        self.photos: Broadcast[Photo] = Broadcast()
        self.uwb: Broadcast[UwbRanges] = Broadcast()
        self.rover: Broadcast[RoverState] = Broadcast()
        self.frames: dict[str, Broadcast[Frame]] = {
            name: Broadcast(on_first=lambda n=name: toggle_camera(n, True),
                            on_last=lambda n=name: toggle_camera(n, False))
            for name in cameras
        }
        self._by_kind = {"telemetry": self.telemetry, "truth": self.truth,
                         "mission": self.mission_events, "photo": self.photos,
                         "uwb": self.uwb, "rover": self.rover}
        #: the newest telemetry sample (None before the first)
        self.latest_state: VehicleState | None = None

    def publish(self, outputs: list[SimOutput]) -> None:
        for out in outputs:
            if out.kind == "frame":
                self.frames[out.payload.camera.name].publish(out.payload)
                continue
            if out.kind == "telemetry":
                self.latest_state = out.payload
            broadcast = self._by_kind.get(out.kind)
            if broadcast is None:  # the flight stack's messages
                self.events.publish((out.delivery_s, out.payload))
            else:
                broadcast.publish(out.payload)

    def close(self, error: BaseException | None) -> None:
        for broadcast in (self.telemetry, self.truth, self.events, self.mission_events,
                          self.photos, self.uwb, self.rover, *self.frames.values()):
            broadcast.close(error)
