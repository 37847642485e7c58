"""The simulated vehicle's navigator: what the auto modes fly, after PX4's ``navigator``, one
class per mode as PX4 has them (``NavigatorMode``), sharing the navigator's context
(:mod:`~drivers.sim.flight.navigator.context`):

* TAKEOFF (:mod:`.takeoff`): climb straight up to MIS_TAKEOFF_ALT above home (or the altitude
  asked for), then the commander switches to HOLD;
* HOLD (:mod:`.loiter`, PX4's AUTO.LOITER): stay at the stopping point, or fly to a
  DO_REPOSITION target;
* LAND and PRECLAND (:mod:`.land`): descend at MPC_Z_V_AUTO_DN, slowing to MPC_LAND_SPEED below
  MPC_LAND_ALT2; over the reported landing target;
* MISSION (:mod:`.mission`): the uploaded mission items in order;
* RETURN (:mod:`.rtl`): climb, fly home, descend, wait, land;

with camera triggering (:mod:`.camera_trigger`) and the geofence (:mod:`.geofence`: as PX4's
mission feasibility check, a mission with a waypoint outside an uploaded fence cannot start,
"Geofence violation for waypoint N") on their own. For the effective mode the commander chose,
:meth:`Navigator.setpoint` returns the position controller's setpoint each position-loop tick.

Positions are local NED; global items are placed with PX4's projection about the local origin
(:class:`~drivers.geo.GlobalOrigin`), altitudes relative to home or above mean sea level by the
item's frame.
"""

from __future__ import annotations

import zlib
from collections import deque
from collections.abc import Callable, Sequence

import numpy as np

from drivers.base import FlightMode
from drivers.geo import GlobalOrigin
from drivers.geometry import yaw_from_quat
from drivers.mission import MissionItem, MissionType
from drivers.sim.flight.navigator.camera_trigger import CameraTrigger
from drivers.sim.flight.navigator.context import (
    NAN,
    Estimate,
    MissionState,
    MissionStatus,
    NavContext,
    NavEvent,
    NavSetpoint,
)
from drivers.sim.flight.navigator.geofence import Fence, FenceArea, geofence_breach
from drivers.sim.flight.navigator.land import Land, PrecisionLand
from drivers.sim.flight.navigator.loiter import Loiter
from drivers.sim.flight.navigator.mission import MissionMode
from drivers.sim.flight.navigator.rtl import ReturnToLaunch
from drivers.sim.flight.navigator.takeoff import Takeoff
from drivers.sim.flight.params import Parameters
from drivers.sim.flight.precland import PrecLand

__all__ = ["Estimate", "Fence", "FenceArea", "MissionState", "MissionStatus", "NavEvent",
           "NavSetpoint", "Navigator", "estimate_of"]


class Navigator:
    def __init__(self, params: Parameters, origin: GlobalOrigin, *,
                 request_mode: Callable[[FlightMode], None],
                 complete: Callable[[FlightMode, FlightMode], None],
                 event: Callable[[str], None]) -> None:
        self.ctx = ctx = NavContext(params, origin, request_mode=request_mode,
                                    complete=complete, event=event)
        self.params, self.origin = params, origin
        self._takeoff = Takeoff(ctx)
        self._loiter = Loiter(ctx)
        self._land = Land(ctx)
        self._precland = PrecisionLand(ctx)
        self.camera = CameraTrigger(ctx)
        self.mission = MissionMode(ctx, self._takeoff, self.camera)
        self._rtl = ReturnToLaunch(ctx)
        self._lists: dict[int, list[MissionItem]] = {t: [] for t in MissionType}
        self._ids: dict[int, int] = {t: 0 for t in MissionType}
        #: the uploaded geofence areas (None: no fence uploaded, or an empty one)
        self._fence: Fence | None = None
        self.status = MissionStatus(0, 0, MissionState.NO_MISSION, False, 0, 0, 0)

    # -- what the flight stack reads and sets ----------------------------------------------

    @property
    def home(self) -> np.ndarray | None:
        """Home in local NED (set when the vehicle arms), None before."""
        return self.ctx.home

    @home.setter
    def home(self, value: np.ndarray | None) -> None:
        self.ctx.home = value

    @property
    def events(self) -> deque[NavEvent]:
        return self.ctx.events

    @property
    def current(self) -> int:
        return self.mission.current

    @property
    def precland(self) -> PrecLand:
        """AUTO.PRECLAND, on the landing target a companion reports."""
        return self._precland.precland

    @precland.setter
    def precland(self, procedure) -> None:
        """Another firmware's precision landing (ArduCopter's AC_PrecLand), with PrecLand's
        interface: ``landing_target``, ``activate``, ``tick``."""
        self._precland.precland = procedure

    @property
    def takeoff_altitude_override_m(self) -> float | None:
        return self._takeoff.altitude_override_m

    @takeoff_altitude_override_m.setter
    def takeoff_altitude_override_m(self, value: float | None) -> None:
        self._takeoff.altitude_override_m = value

    def takeoff_altitude_m(self) -> float:
        return self._takeoff.altitude_m()

    # -- mission storage (MAVLink mission protocol) ----------------------------------------

    def items(self, mission_type: int = MissionType.MISSION) -> list[MissionItem]:
        return list(self._lists[MissionType(mission_type)])

    def set_items(self, items: Sequence[MissionItem], mission_type: int = MissionType.MISSION,
                  ) -> None:
        """Store an uploaded list. A fence that cannot be built (a polygon with fewer than three
        vertices or inconsistent vertex counts, a circle without a positive radius, an area
        without a position) is refused with :class:`~drivers.mission.MissionRejected`
        (MISSION_ERROR, as PX4 answers a bad fence upload); the previous list and fence stay."""
        kind = MissionType(mission_type)
        ordered = sorted(items, key=lambda i: i.seq)
        if kind is MissionType.FENCE:
            self._fence = Fence.from_items(ordered, self.origin)  # raises before any change
        self._lists[kind] = ordered
        self._ids[kind] = _mission_id(self._lists[kind])
        if kind is MissionType.MISSION:
            self.mission.stored(self._lists[kind])
        self._publish()

    def set_current(self, seq: int) -> None:
        """MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT: fly item ``seq`` next."""
        self.mission.set_current(seq)
        self._publish()

    def mission_problem(self, landed: bool) -> str | None:
        """Why MISSION cannot start now (None: it can): PX4's mission feasibility, simplified."""
        return self.mission.problem(landed, self.geofence_breach, self._fence is not None)

    # -- mode changes and the tick ---------------------------------------------------------

    def disarmed(self) -> None:
        """The vehicle disarmed: a mission that was flown starts again from its first item
        when MISSION is next activated (PX4's mission restart), at the default cruise speed."""
        self.mission.disarmed()
        self.ctx.speed_override = NAN

    def set_time(self, now_s: float) -> None:
        """The time of the commands that follow (events they cause carry it)."""
        self.ctx.now = now_s

    def activate(self, mode: FlightMode, est: Estimate, landed: bool) -> None:
        """The effective mode became ``mode``: set up what it flies."""
        ctx = self.ctx
        previous, ctx.mode = ctx.mode, mode
        ctx.est = est
        if previous is FlightMode.MISSION and mode is not FlightMode.MISSION:
            self.mission.paused()
        if mode is FlightMode.HOLD:
            self._loiter.activate(est, landed)
        elif mode is FlightMode.TAKEOFF:
            ctx.speed_override = NAN  # PX4 resets the cruise speed on takeoff and RTL
            self._takeoff.start(est, self._takeoff.altitude_m())
        elif mode is FlightMode.LAND:
            self._land.activate(est, landed)
        elif mode is FlightMode.PRECLAND:
            self._precland.activate(est, landed)
        elif mode is FlightMode.MISSION:
            self.mission.activate(est, landed)
        elif mode is FlightMode.RETURN:
            self._rtl.activate(est)
        ctx.yaw_sp = est.yaw_rad
        self._publish()

    def reposition(self, target_ned_m, yaw_rad: float, speed_m_s: float, est: Estimate) -> None:
        """DO_REPOSITION: fly to ``target_ned_m`` in HOLD (NaN components: keep current)."""
        self._loiter.reposition(target_ned_m, yaw_rad, speed_m_s, est)

    def set_speed(self, speed_m_s: float) -> None:
        """DO_CHANGE_SPEED: the auto modes' horizontal speed (negative: back to default)."""
        self.ctx.speed_override = speed_m_s if speed_m_s > 0 else NAN

    def setpoint(self, now: float, dt: float, est: Estimate, height_agl_m: float,
                 landed: bool, flying: bool) -> NavSetpoint:
        """The setpoint of the current mode. ``flying``: the vehicle has left the ground (its
        takeoff ramp is over)."""
        ctx = self.ctx
        ctx.now, ctx.est, ctx.flying = now, est, flying
        mode = ctx.mode
        if mode is FlightMode.TAKEOFF:
            climb = self._takeoff.tick(dt, est)
            if climb is not None:
                return climb
            ctx.event("takeoff complete")
            ctx.complete(FlightMode.TAKEOFF, FlightMode.HOLD)
            return NavSetpoint(ctx.hold_setpoint())
        if mode is FlightMode.LAND:
            return self._land.tick(est, height_agl_m)
        if mode is FlightMode.PRECLAND:
            return self._precland.tick(dt, est, height_agl_m, landed)
        if mode is FlightMode.MISSION:
            out = self.mission.tick(dt, est, height_agl_m, landed)
            self._publish()
            return out
        if mode is FlightMode.RETURN:
            return self._rtl.tick(dt, est, height_agl_m)
        return self._loiter.tick(dt, est)

    def return_altitude_m(self, est: Estimate) -> float:
        return self._rtl.return_altitude_m(est)

    # -- camera triggering -----------------------------------------------------------------

    def camera_tick(self, now: float, est: Estimate) -> None:
        """Interval and distance triggering: every position-loop tick in flight, whatever the
        mode (a survey flown in OFFBOARD triggers too)."""
        self.ctx.now = now
        self.camera.tick(now, est)

    def start_photos(self, interval_s: float, count: int) -> None:
        """IMAGE_START_CAPTURE as a command: one photo, or ``count`` every ``interval_s``
        (count 0: until IMAGE_STOP_CAPTURE)."""
        self.camera.start(interval_s, count)

    def stop_photos(self) -> None:
        self.camera.stop()

    def take_photo(self) -> None:
        self.camera.take_photo()

    def set_trigger_distance(self, distance_m: float, trigger_now: bool = False) -> None:
        """DO_SET_CAM_TRIGG_DIST: a photo every ``distance_m`` travelled (0: stop)."""
        self.camera.set_distance(distance_m, trigger_now)

    # -- geofence --------------------------------------------------------------------------

    def geofence_breach(self, position_ned_m: np.ndarray) -> str | None:
        """Why ``position_ned_m`` is outside the geofence (None: inside, or no fence)."""
        return geofence_breach(self.params, self.ctx.home, self._fence, position_ned_m)

    @property
    def fence(self) -> Fence | None:
        """The uploaded geofence's areas (None: none)."""
        return self._fence

    def _publish(self) -> None:
        m = self.mission
        self.status = MissionStatus(
            total=len(m.items), current=m.current if m.items else 0, state=m.state,
            in_mission_mode=self.ctx.mode is FlightMode.MISSION,
            mission_id=self._ids[MissionType.MISSION], fence_id=self._ids[MissionType.FENCE],
            rally_id=self._ids[MissionType.RALLY])


def estimate_of(position_ned_m, velocity_ned_m_s, q_ned_frd) -> Estimate:
    return Estimate(np.asarray(position_ned_m, dtype=float),
                    np.asarray(velocity_ned_m_s, dtype=float), yaw_from_quat(q_ned_frd))


def _mission_id(items: Sequence[MissionItem]) -> int:
    """A 32-bit id of a list's contents (MISSION_CURRENT.mission_id; 0: empty), as PX4's CRC
    of the items lets a ground station tell whether its copy is current."""
    if not items:
        return 0
    data = repr([(i.frame, i.command, i.param1, i.param2, i.param3, i.param4, i.x, i.y, i.z,
                  i.autocontinue) for i in items]).encode()
    return zlib.crc32(data) or 1
