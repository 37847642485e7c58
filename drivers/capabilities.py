"""What only some vehicles can do, as small protocols a driver implements and the autopilot
finds with ``isinstance`` (as MAVSDK's plugins are found per vehicle): the
:class:`~drivers.base.Vehicle` interface stays the part every vehicle has.

==================  ======================================================================
protocol            who has it
==================  ======================================================================
PrecisionLanding    MAVLink (PX4's AUTO.PRECLAND, ArduCopter's LAND with PLND), the
                    simulator: LANDING_TARGET in, the vehicle lands on it
LandingSettings     the same drivers: whether the vehicle's parameters let it (ArduCopter's
                    PLND_ENABLED is 0 by default)
UwbRanging          the simulator (UWB ranges to anchors on a rover)
RoverLink           the simulator, a MAVLink link that hears a rover (its reported state)
StatusTexts         the simulator, MAVLink (STATUSTEXT): the vehicle's own messages
VideoInput          MAVLink drivers: cameras that are network video streams
MavlinkIdentity     MAVLink drivers: the autopilot locked onto (ids, MAV_AUTOPILOT)
LinkTimeSync        MAVLink drivers: the vehicle's clock mapped onto ours (TIMESYNC)
OnDemandCameras     the simulator: cameras rendered only while someone reads them
DeadReckoning       the AR.Drone: a position integrated from velocities, and how far off it
                    may be by now
SimulatorTruth      the simulator: ground truth and the cameras as they really are
                    (for scoring and the log only, never for the autopilot's decisions)
==================  ======================================================================

A vehicle without a global position (no GNSS: the AR.Drone) says so with
``has_global_position = False`` (:class:`~drivers.base.Vehicle`). What a mission step needs of
these is named in :data:`NEEDS`.

A stream that a driver has but a particular vehicle does not deliver (the simulator without
a rover in its world) is also absent from :attr:`~drivers.base.Vehicle.sensors`.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Mapping
from typing import TYPE_CHECKING, Protocol, runtime_checkable

if TYPE_CHECKING:
    from drivers.base import CameraInfo, LandingTarget, RoverState, UwbRanges


@runtime_checkable
class PrecisionLanding(Protocol):
    async def precision_land(self) -> None:
        """Switch to PX4's precision landing (AUTO.PRECLAND): it lands on the target that
        :meth:`send_landing_target` reports (searching for it, then falling back to a normal
        landing, as its PLD_* parameters say)."""

    async def send_landing_target(self, target: LandingTarget) -> None:
        """Report the landing target's position (MAVLink LANDING_TARGET, MAV_FRAME_LOCAL_NED:
        what PX4's precision landing flies to). Fire and forget; stream it while it is seen."""


@runtime_checkable
class LandingSettings(Protocol):
    async def precision_landing_problem(self) -> str | None:
        """What in the vehicle's own parameters keeps its precision landing from landing on
        the reported target (ArduCopter with PLND_ENABLED 0 lands anywhere), None if nothing
        does. Asked before a mission that hands a landing to the vehicle flies; the landing
        itself is refused the same way (:class:`~drivers.base.CommandDenied`)."""


@runtime_checkable
class UwbRanging(Protocol):
    def uwb_ranges(self, buffer: int = 8) -> AsyncIterator[UwbRanges]:
        """A new subscription to UWB ranges (buffered: every reading counts)."""


@runtime_checkable
class RoverLink(Protocol):
    def rover_states(self, buffer: int = 8) -> AsyncIterator[RoverState]:
        """A new subscription to the rover's reported state (buffered)."""


@runtime_checkable
class StatusTexts(Protocol):
    def events(self, buffer: int = 64) -> AsyncIterator[tuple[float, str]]:
        """The vehicle's own messages (time, text): the simulator's, or STATUSTEXT."""


@runtime_checkable
class VideoInput(Protocol):
    #: the network video streams, by camera (their timing, statistics and last error)
    video_sources: Mapping[str, object]
    #: how each was set up (its URL, calibration, latency): ``autopilot.cameras``
    camera_setups: Mapping[str, object]


@runtime_checkable
class MavlinkIdentity(Protocol):
    #: the autopilot locked onto: (system, component), None before its first HEARTBEAT
    target_ids: tuple[int, int] | None
    #: its MAV_AUTOPILOT (12 PX4, 3 ArduPilot), None before its first HEARTBEAT
    autopilot: int | None


@runtime_checkable
class LinkTimeSync(Protocol):
    #: add to a vehicle time to get ours (s; NaN while not known)
    vehicle_to_local_s: float
    time_sync_round_trip_s: float


@runtime_checkable
class OnDemandCameras(Protocol):
    #: cameras rendered only while someone reads them (a photo keeps its camera running only
    #: while one is near)
    renders_on_demand: bool


@runtime_checkable
class DeadReckoning(Protocol):
    #: how far off the reported position may be by now (m): the vehicle integrates it from
    #: its velocities (no GNSS), so its error grows with the distance flown
    drift_m: float
    #: the distance it has been integrated over (m)
    path_m: float


@runtime_checkable
class SimulatorTruth(Protocol):
    sim_time_s: float

    def ground_truth(self, buffer: int = 256) -> AsyncIterator[object]:
        """The true state of the world (scoring and the log only)."""

    def true_cameras(self) -> Mapping[str, CameraInfo]:
        """The cameras as they really are (a realistic camera reports its fitted ones)."""


#: the extra sensor streams by name (``vehicle.sensors``): the protocol that delivers each,
#: and how to subscribe
SENSOR_STREAMS = {
    "uwb": (UwbRanging, lambda vehicle: vehicle.uwb_ranges),
    "rover": (RoverLink, lambda vehicle: vehicle.rover_states),
}


def _knows_global_position(vehicle) -> bool:
    return bool(getattr(vehicle, "has_global_position", True))


#: what a mission step may need of its vehicle beyond the interface every vehicle has, by
#: name: (does this vehicle have it, what it is). A step kind says what it needs
#: (:attr:`autopilot.steps.registry.StepKind.needs`); a mission whose step needs what the
#: vehicle lacks is refused before anything flies.
NEEDS = {
    "global_position": (_knows_global_position,
                        "a global position (GNSS): positions on Earth, geotagged photos"),
    "precision_landing": (lambda vehicle: isinstance(vehicle, PrecisionLanding),
                          "the vehicle's own precision landing (PX4 AUTO.PRECLAND, "
                          "ArduCopter PLND)"),
    "rover_link": (lambda vehicle: isinstance(vehicle, RoverLink),
                   "the rover's reports (a MAVLink link that hears the rover)"),
}


def lacks(vehicle, needs) -> list[str]:
    """Of ``needs`` (names in :data:`NEEDS`), what ``vehicle`` does not have."""
    return [need for need in needs if not NEEDS[need][0](vehicle)]


#: the needs a vehicle may have by its driver yet not by its settings: how to ask it (once
#: connected) what keeps it from one, None if nothing does
SETTINGS = {
    "precision_landing": lambda vehicle: vehicle.precision_landing_problem()
    if isinstance(vehicle, LandingSettings) else None,
}


async def settings_problem(vehicle, need: str) -> str | None:
    """What in a connected ``vehicle``'s own settings keeps it from ``need``, None if nothing
    does (or it cannot say)."""
    ask = SETTINGS.get(need)
    pending = ask(vehicle) if ask is not None else None
    return None if pending is None else await pending
