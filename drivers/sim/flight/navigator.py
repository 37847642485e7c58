"""The simulated vehicle's navigator: what the auto modes fly, after PX4's ``navigator``.

For the effective mode the commander chose, :meth:`Navigator.setpoint` returns the position
controller's setpoint each position-loop tick:

* TAKEOFF: climb straight up to MIS_TAKEOFF_ALT above home (or the altitude asked for), then
  the commander switches to HOLD;
* HOLD (PX4's AUTO.LOITER): stay at the stopping point, or fly to a DO_REPOSITION target;
* LAND: descend at MPC_Z_V_AUTO_DN, slowing to MPC_LAND_SPEED below MPC_LAND_ALT2;
* MISSION: the uploaded mission items in order (see below), MISSION_CURRENT / reached events;
* RETURN: climb to RTL_RETURN_ALT (less inside the RTL_CONE_ANG cone above home), fly home at
  MPC_XY_CRUISE, descend to RTL_DESCEND_ALT, wait RTL_LAND_DELAY (−1: stay), land.

Missions: NAV_WAYPOINT (param1 hold time, param2 acceptance radius or NAV_ACC_RAD, param4 yaw;
a waypoint without hold time that is followed by another is flown through), NAV_TAKEOFF,
NAV_LAND, NAV_RETURN_TO_LAUNCH (switches to RETURN, as PX4 does), NAV_LOITER_TIME,
NAV_LOITER_UNLIM, NAV_DELAY, DO_JUMP, DO_CHANGE_SPEED, and the camera items
(IMAGE_START/STOP_CAPTURE, DO_SET_CAM_TRIGG_DIST / _INTERVAL, DO_DIGICAM_CONTROL,
VIDEO_START/STOP_CAPTURE), which become :class:`NavEvent` photo and video events. Started on
the ground, a mission first takes off (to the first waypoint's altitude, at least
MIS_TAKEOFF_ALT), as PX4 does. Paused (HOLD) and resumed, it continues with the current item.

Geofence (:meth:`Navigator.geofence_breach`): GF_MAX_HOR_DIST and GF_MAX_VER_DIST from home
(0: off), and the uploaded fence (MAVLink mission type 1, :class:`Fence`): the horizontal
position must be inside at least one inclusion polygon or circle (if there is any) and outside
every exclusion polygon and circle. NAV_FENCE_RETURN_POINT is stored but not used (RTL returns
home). As PX4's mission feasibility check, a mission with a waypoint outside an uploaded fence
cannot start ("Geofence violation for waypoint N").

Positions are local NED; global items are placed with PX4's projection about the local origin
(:class:`~drivers.geo.GlobalOrigin`), altitudes relative to home or above mean sea level by the
item's frame.
"""

from __future__ import annotations

import enum
import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import shapely

from drivers.base import FlightMode
from drivers.geo import GlobalOrigin
from drivers.geometry import wrap_pi, yaw_from_quat
from drivers.mission import (
    GLOBAL_FRAMES,
    MISSION_ERROR,
    RELATIVE_ALT_FRAMES,
    Cmd,
    Frame,
    MissionItem,
    MissionRejected,
    MissionType,
)
from drivers.sim.flight.params import Parameters
from drivers.sim.flight.position_control import ControlSetpoint
from drivers.sim.flight.precland import PrecLand
from drivers.sim.flight.trajectory import LineTracker, Profile1D

NAN = float("nan")
_TAKEOFF_DONE_M = 0.1  # TAKEOFF hands over to HOLD this close to its altitude (profile done)
_YAW_TO_TARGET_MIN_M = 1.0  # closer than this, the heading is kept (no spinning on the spot)
_MAX_DO_ITEMS_PER_TICK = 100  # DO_JUMP loops without a nav item must not hang the vehicle
_MIN_CORNER_SPEED_M_S = 0.5  # a waypoint to be passed slower than this is stopped at


class MissionState(enum.IntEnum):
    """MAVLink MISSION_STATE (MISSION_CURRENT.mission_state)."""

    UNKNOWN = 0
    NO_MISSION = 1
    NOT_STARTED = 2
    ACTIVE = 3
    PAUSED = 4
    COMPLETE = 5


@dataclass(frozen=True, slots=True)
class MissionStatus:
    """The mission as MISSION_CURRENT reports it (immutable: read from other threads)."""

    total: int
    current: int
    state: MissionState
    in_mission_mode: bool
    mission_id: int
    fence_id: int
    rally_id: int


@dataclass(frozen=True, slots=True)
class NavEvent:
    """``kind``: ``current`` (the current item changed), ``reached`` (an item was reached),
    ``photo`` (take one now; ``seq`` is the photo's index), ``video_start`` / ``video_stop``,
    ``finished`` (the last item is done)."""

    time_s: float
    kind: str
    seq: int


@dataclass(slots=True)
class NavSetpoint:
    sp: ControlSetpoint
    #: the mode wants to leave the ground (a takeoff or a mission's first climb)
    takeoff: bool = False
    #: descending to touch down (the flight stack spools the motors down on contact)
    landing: bool = False


@dataclass(frozen=True, slots=True)
class Estimate:
    """The part of the state estimate the navigator needs (local NED)."""

    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    yaw_rad: float


class Navigator:
    def __init__(self, params: Parameters, origin: GlobalOrigin, *,
                 request_mode: Callable[[FlightMode], None],
                 complete: Callable[[FlightMode, FlightMode], None],
                 event: Callable[[str], None]) -> None:
        self.params = params
        self.origin = origin
        self._request_mode = request_mode
        self._complete = complete
        self._event = event
        self.events: deque[NavEvent] = deque(maxlen=1024)
        #: home in local NED (set when the vehicle arms), None before
        self.home: np.ndarray | None = None
        self._now = 0.0
        self._flying = False
        self._mode: FlightMode | None = None
        self._est: Estimate | None = None

        # hold / reposition / takeoff / land
        self._hold_pos = np.zeros(3)
        self._hold_yaw = 0.0
        self._reposition: LineTracker | None = None
        self._reposition_speed = NAN
        self._takeoff_target = np.zeros(3)
        self._takeoff_profile: Profile1D | None = None
        self.takeoff_altitude_override_m: float | None = None
        self._land_xy = np.zeros(2)
        self._yaw_sp = 0.0
        #: AUTO.PRECLAND, on the landing target a companion reports
        self.precland = PrecLand(params, event)

        # mission
        self._lists: dict[int, list[MissionItem]] = {t: [] for t in MissionType}
        self._ids: dict[int, int] = {t: 0 for t in MissionType}
        self.current = 0
        self._state = MissionState.NO_MISSION
        self._stage = "idle"  # idle | takeoff | fly | wait | land | loiter | done
        self._inserted_takeoff = False  # the takeoff stage climbs before the first item
        self._restart = False  # flown, then disarmed: the next MISSION starts at item 0
        self._line: LineTracker | None = None
        self._wait_until = math.inf
        self._item_target = np.zeros(3)
        self._item_reached_at: float | None = None
        self._jumps: dict[int, int] = {}
        self._speed_override = NAN
        self.status = self._status()

        # camera triggering
        self._photo_index = 0
        self._photo_interval_s = 0.0
        self._photo_next_s = math.inf
        self._photos_left = 0  # 0: unlimited while the interval runs
        self._trigger_dist_m = 0.0
        self._dist_since_photo = 0.0
        self._last_xy: np.ndarray | None = None

        # RTL
        self._rtl_stage = "climb"
        self._rtl_alt_down = 0.0

        #: the uploaded geofence areas (None: no fence uploaded, or an empty one)
        self._fence: Fence | None = None

    # ------------------------------------------------------------------------------------
    # Mission storage (MAVLink mission protocol)
    # ------------------------------------------------------------------------------------

    def items(self, mission_type: int = MissionType.MISSION) -> list[MissionItem]:
        return list(self._lists[MissionType(mission_type)])

    def set_items(self, items: Sequence[MissionItem], mission_type: int = MissionType.MISSION,
                  ) -> None:
        """Store an uploaded list. A fence that cannot be built (a polygon with fewer than three
        vertices or inconsistent vertex counts, a circle without a positive radius, an area
        without a position) is refused with :class:`MissionRejected` (MISSION_ERROR, as PX4
        answers a bad fence upload); the previous list and fence stay."""
        kind = MissionType(mission_type)
        ordered = sorted(items, key=lambda i: i.seq)
        if kind is MissionType.FENCE:
            self._fence = Fence.from_items(ordered, self.origin)  # raises before any change
        self._lists[kind] = ordered
        self._ids[kind] = _mission_id(self._lists[kind])
        if kind is MissionType.MISSION:
            self.current = 0
            self._restart = False
            self._jumps.clear()
            self._speed_override = NAN
            self._state = MissionState.NOT_STARTED if items else MissionState.NO_MISSION
            self._stage = "idle"
            if self._mode is FlightMode.MISSION:  # a new mission while flying one: restart it
                self._start_item(self._estimate_now())
            self._events_current()
        self._publish()

    def set_current(self, seq: int) -> None:
        """MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT: fly item ``seq`` next."""
        items = self._lists[MissionType.MISSION]
        if not 0 <= seq < len(items):
            raise ValueError(f"mission item {seq} does not exist (the mission has "
                             f"{len(items)} items)")
        self.current = seq
        self._jumps.clear()
        self._restart = False  # the user's choice of item stands
        if self._state is MissionState.COMPLETE:
            self._state = MissionState.NOT_STARTED
        self._stage = "idle"
        if self._mode is FlightMode.MISSION:
            self._start_item(self._estimate_now())
        self._events_current()
        self._publish()

    def mission_problem(self, landed: bool) -> str | None:
        """Why MISSION cannot start now (None: it can): PX4's mission feasibility, simplified."""
        items = self._lists[MissionType.MISSION]
        if not items:
            return "no mission uploaded"
        if self.home is None and not landed:
            return "no home position"
        first = next((i for i in items[self.current:] if i.is_nav and i.has_position), None)
        limit = self.params["MIS_DIST_1WP"]
        if first is not None and limit > 0 and self.home is not None:
            target = self._position_of(first, self.home)
            distance = float(np.hypot(*(target[:2] - self.home[:2])))
            if distance > limit:
                return (f"first waypoint too far: {distance:.0f} m from home "
                        f"(MIS_DIST_1WP {limit:g} m)")
        if self._fence is not None and self.home is not None:
            # PX4's MissionFeasibilityChecker::checkGeofence: with a fence uploaded, every
            # item with a position must lie inside it (and within GF_MAX_HOR/VER_DIST)
            for item in items:
                if item.is_nav and item.has_position:
                    why = self.geofence_breach(self._position_of(item, self.home))
                    if why is not None:
                        return f"Geofence violation for waypoint {item.seq + 1} ({why})"
        return None

    # ------------------------------------------------------------------------------------
    # Mode changes and the tick
    # ------------------------------------------------------------------------------------

    def disarmed(self) -> None:
        """The vehicle disarmed: a mission that was flown starts again from its first item
        when MISSION is next activated (PX4's mission restart), at the default cruise speed."""
        if self._state in (MissionState.ACTIVE, MissionState.PAUSED, MissionState.COMPLETE):
            self._restart = True
        self._speed_override = NAN

    def set_time(self, now_s: float) -> None:
        """The time of the commands that follow (events they cause carry it)."""
        self._now = now_s

    def activate(self, mode: FlightMode, est: Estimate, landed: bool) -> None:
        """The effective mode became ``mode``: set up what it flies."""
        previous, self._mode = self._mode, mode
        self._est = est
        if previous is FlightMode.MISSION and mode is not FlightMode.MISSION and \
                self._state is MissionState.ACTIVE:
            self._state = MissionState.PAUSED
        if mode is FlightMode.HOLD:
            self._reposition = None
            self._enter_hold(est, landed)
        elif mode is FlightMode.TAKEOFF:
            self._speed_override = NAN  # PX4 resets the cruise speed on takeoff and RTL
            self._start_takeoff(est, self.takeoff_altitude_m())
        elif mode is FlightMode.LAND:
            self._land_xy = self._stopping_point(est, landed)[:2]
            self._hold_yaw = est.yaw_rad
        elif mode is FlightMode.PRECLAND:
            self._hold_yaw = est.yaw_rad
            self.precland.activate(self._now, self._stopping_point(est, landed))
        elif mode is FlightMode.MISSION:
            if self._state is MissionState.COMPLETE or self._restart:  # from the beginning
                self.current = 0
                self._jumps.clear()
                self._restart = False
            self._state = MissionState.ACTIVE
            self._stage = "idle"
            if landed:
                self._start_mission_takeoff(est)
            else:
                self._start_item(est)
            self._events_current()
        elif mode is FlightMode.RETURN:
            self._start_rtl(est)
        self._yaw_sp = est.yaw_rad
        self._publish()

    def reposition(self, target_ned_m, yaw_rad: float, speed_m_s: float, est: Estimate) -> None:
        """DO_REPOSITION: fly to ``target_ned_m`` in HOLD (NaN components: keep current)."""
        target = np.where(np.isfinite(target_ned_m), target_ned_m, est.position_ned_m)
        self._reposition = LineTracker(self._hold_pos if self._mode is FlightMode.HOLD
                                       else est.position_ned_m, target)
        self._reposition_speed = speed_m_s
        self._hold_pos = target.astype(float)
        if math.isfinite(yaw_rad):
            self._hold_yaw = yaw_rad
        elif float(np.hypot(*(target[:2] - est.position_ned_m[:2]))) > _YAW_TO_TARGET_MIN_M:
            self._hold_yaw = math.atan2(target[1] - est.position_ned_m[1],
                                        target[0] - est.position_ned_m[0])

    def set_speed(self, speed_m_s: float) -> None:
        """DO_CHANGE_SPEED: the auto modes' horizontal speed (negative: back to default)."""
        self._speed_override = speed_m_s if speed_m_s > 0 else NAN

    def setpoint(self, now: float, dt: float, est: Estimate, height_agl_m: float,
                 landed: bool, flying: bool) -> NavSetpoint:
        """The setpoint of the current mode. ``flying``: the vehicle has left the ground (its
        takeoff ramp is over)."""
        self._now = now
        self._est = est
        self._flying = flying
        mode = self._mode
        if mode is FlightMode.TAKEOFF:
            return self._takeoff_tick(dt, est, FlightMode.TAKEOFF)
        if mode is FlightMode.LAND:
            return self._land_tick(est, height_agl_m, self._land_xy)
        if mode is FlightMode.PRECLAND:
            return self._precland_tick(dt, est, height_agl_m, landed)
        if mode is FlightMode.MISSION:
            out = self._mission_tick(dt, est, height_agl_m, landed)
            self._publish()
            return out
        if mode is FlightMode.RETURN:
            return self._rtl_tick(dt, est, height_agl_m)
        return self._hold_tick(dt, est)

    # ------------------------------------------------------------------------------------
    # Takeoff, hold, land
    # ------------------------------------------------------------------------------------

    def takeoff_altitude_m(self) -> float:
        alt = self.takeoff_altitude_override_m
        return alt if alt is not None else self.params["MIS_TAKEOFF_ALT"]

    def _start_takeoff(self, est: Estimate, altitude_m: float) -> None:
        home_z = self.home[2] if self.home is not None else est.position_ned_m[2]
        target = est.position_ned_m.astype(float).copy()
        target[2] = min(target[2], home_z - altitude_m)
        self._takeoff_target = target
        self._takeoff_profile = None  # starts from the vehicle's state once it flies
        self._hold_yaw = est.yaw_rad

    def _takeoff_tick(self, dt: float, est: Estimate, mode: FlightMode) -> NavSetpoint:
        """Climb to the takeoff target; True in ``done`` when there."""
        p = self.params
        target = self._takeoff_target
        if self._takeoff_profile is None:
            if not self._flying:
                # still on the ground / ramping up: aim at the target, the ramp limits the climb
                return NavSetpoint(ControlSetpoint(target.tolist(), [0.0, 0.0, 0.0],
                                                   self._hold_yaw,
                                                   xy_vel_max_m_s=p["MPC_XY_CRUISE"],
                                                   z_vel_max_up_m_s=p["MPC_TKO_SPEED"]),
                                   takeoff=True)
            self._takeoff_profile = Profile1D(float(est.position_ned_m[2]),
                                              float(est.velocity_ned_m_s[2]))
        prof = self._takeoff_profile
        prof.step(float(target[2]), p["MPC_TKO_SPEED"], p["MPC_ACC_UP_MAX"], dt)
        if prof.done and abs(est.position_ned_m[2] - target[2]) < _TAKEOFF_DONE_M:
            self._hold_pos = target.copy()
            self._takeoff_done(mode)
            return NavSetpoint(self._hold_setpoint())
        return NavSetpoint(ControlSetpoint([target[0], target[1], prof.position],
                                           [0.0, 0.0, prof.velocity], self._hold_yaw,
                                           acceleration_ned_m_s2=[0.0, 0.0, prof.acceleration],
                                           xy_vel_max_m_s=p["MPC_XY_CRUISE"]), takeoff=True)

    def _takeoff_done(self, mode: FlightMode) -> None:
        if mode is FlightMode.TAKEOFF:
            self._event("takeoff complete")
            self._complete(FlightMode.TAKEOFF, FlightMode.HOLD)
        else:
            self._takeoff_profile = None
            items = self._lists[MissionType.MISSION]
            if self._inserted_takeoff or self.current >= len(items):
                self._inserted_takeoff = False  # the climb before the first item: fly it now
                self._start_item(self._est)
            else:  # the mission's own NAV_TAKEOFF item is done
                self._stage = "fly"
                self._advance(items[self.current], self._est)

    def _enter_hold(self, est: Estimate, landed: bool) -> None:
        self._hold_pos = self._stopping_point(est, landed)
        self._hold_yaw = est.yaw_rad

    def _hold_setpoint(self) -> ControlSetpoint:
        return ControlSetpoint(self._hold_pos.tolist(), [NAN, NAN, NAN], self._hold_yaw,
                               xy_vel_max_m_s=self.params["MPC_XY_CRUISE"])

    def _hold_tick(self, dt: float, est: Estimate) -> NavSetpoint:
        line = self._reposition
        if line is None:
            return NavSetpoint(self._hold_setpoint())
        p = self.params
        cruise = self._reposition_speed if self._reposition_speed > 0 else p["MPC_XY_CRUISE"]
        v_max = line.speed_limit(cruise, p["MPC_Z_V_AUTO_UP"], p["MPC_Z_V_AUTO_DN"])
        pos, vel, acc = line.step(dt, v_max, p["MPC_ACC_HOR"], est.position_ned_m)
        if line.done:
            self._reposition = None
        yaw = self._slew_yaw(self._hold_yaw, dt)
        return NavSetpoint(ControlSetpoint(pos.tolist(), vel.tolist(), yaw,
                                           acceleration_ned_m_s2=acc.tolist()))

    def _land_tick(self, est: Estimate, height_agl_m: float, xy) -> NavSetpoint:
        p = self.params
        home_z = self.home[2] if self.home is not None else 0.0
        height = height_agl_m if math.isfinite(height_agl_m) \
            else home_z - est.position_ned_m[2]
        alt1, alt2 = p["MPC_LAND_ALT1"], p["MPC_LAND_ALT2"]
        slow, fast = p["MPC_LAND_SPEED"], p["MPC_Z_V_AUTO_DN"]
        if height <= alt2 or alt1 <= alt2:
            speed = slow if height <= alt2 else fast
        else:  # between the two altitudes the descent slows down linearly
            blend = min(max((height - alt2) / (alt1 - alt2), 0.0), 1.0)
            speed = slow + blend * (fast - slow)
        return NavSetpoint(ControlSetpoint([float(xy[0]), float(xy[1]), NAN], [NAN, NAN, speed],
                                           self._hold_yaw, xy_vel_max_m_s=p["MPC_XY_CRUISE"],
                                           z_vel_max_down_m_s=max(speed,
                                                                  p["MPC_Z_VEL_MAX_DN"])),
                           landing=True)

    def _precland_tick(self, dt: float, est: Estimate, height_agl_m: float,
                       landed: bool) -> NavSetpoint:
        origin_down = self.home[2] if self.home is not None else 0.0
        out = self.precland.tick(self._now, est.position_ned_m, est.velocity_ned_m_s, landed,
                                 origin_down)
        if out.land:
            return self._land_tick(est, height_agl_m, out.position_ned_m[:2])
        yaw = self._slew_yaw(self._hold_yaw, dt)
        return NavSetpoint(ControlSetpoint(out.position_ned_m.tolist(), [NAN, NAN, NAN], yaw,
                                           xy_vel_max_m_s=self.params["MPC_XY_CRUISE"]))

    def _stopping_point(self, est: Estimate, landed: bool) -> np.ndarray:
        """Where the vehicle comes to rest braking at MPC_ACC_HOR (PX4's loiter brake)."""
        pos = est.position_ned_m.astype(float).copy()
        if landed:
            return pos
        vel = est.velocity_ned_m_s
        speed = float(np.hypot(vel[0], vel[1]))
        pos[:2] += vel[:2] * speed / (2.0 * self.params["MPC_ACC_HOR"])
        return pos

    def _slew_yaw(self, target: float, dt: float) -> float:
        """Turn towards ``target`` at most at MPC_YAWRAUTO_MAX (auto modes turn gently)."""
        step = math.radians(self.params["MPC_YAWRAUTO_MAX"]) * dt
        err = wrap_pi(target - self._yaw_sp)
        self._yaw_sp = wrap_pi(self._yaw_sp + max(-step, min(step, err)))
        return self._yaw_sp

    # ------------------------------------------------------------------------------------
    # Mission
    # ------------------------------------------------------------------------------------

    def _start_mission_takeoff(self, est: Estimate) -> None:
        items = self._lists[MissionType.MISSION]
        item = items[self.current] if self.current < len(items) else None
        if item is not None and item.command == Cmd.NAV_TAKEOFF:
            self._start_item(est)  # the mission's own takeoff item
            return
        home = self.home if self.home is not None else est.position_ned_m
        altitude = self.params["MIS_TAKEOFF_ALT"]
        first = next((i for i in items[self.current:] if i.is_nav and i.has_position), None)
        if first is not None:
            altitude = max(altitude, float(home[2] - self._position_of(first, home)[2]))
        self._start_takeoff(est, altitude)
        self._stage = "takeoff"
        self._inserted_takeoff = True
        self._event(f"Takeoff to {altitude:.1f} meters above home")

    def _start_item(self, est: Estimate) -> None:
        """Set up the current item from where the vehicle (or its reference) is now."""
        self._stage = "idle"
        self._line = None
        self._item_reached_at = None
        self._wait_until = math.inf
        self._run_do_items(est)

    def _run_do_items(self, est: Estimate) -> None:
        """Execute non-navigation items up to the next navigation item, then set it up."""
        items = self._lists[MissionType.MISSION]
        for _ in range(_MAX_DO_ITEMS_PER_TICK):
            if self.current >= len(items):
                self._finish(est)
                return
            item = items[self.current]
            if item.is_nav:
                self._setup_nav(item, est)
                return
            jump = self._do_item(item)
            self._reached(item.seq)
            if jump is not None:
                self.current = jump
            else:
                self.current += 1
            self._events_current()
        self._event("mission: DO_JUMP loop without a navigation item; holding")
        self._finish(est)

    def _do_item(self, item: MissionItem) -> int | None:
        """Carry out a DO/camera item; returns the item to continue with for DO_JUMP."""
        cmd = item.command
        if cmd == Cmd.DO_JUMP:
            target, repeat = int(item.param1), int(item.param2)
            done = self._jumps.get(item.seq, 0)
            if 0 <= target < len(self._lists[MissionType.MISSION]) and \
                    (repeat < 0 or done < repeat):
                self._jumps[item.seq] = done + 1
                return target
        elif cmd == Cmd.DO_CHANGE_SPEED:
            self.set_speed(item.param2)
        elif cmd == Cmd.IMAGE_START_CAPTURE:
            self._start_photos(interval_s=item.param2, count=int(_or(item.param3, 0)))
        elif cmd == Cmd.IMAGE_STOP_CAPTURE:
            self._photo_interval_s, self._photo_next_s, self._photos_left = 0.0, math.inf, 0
        elif cmd == Cmd.DO_SET_CAM_TRIGG_DIST:
            self.set_trigger_distance(item.param1, trigger_now=_or(item.param3, 0) >= 0.5)
        elif cmd == Cmd.DO_SET_CAM_TRIGG_INTERVAL:
            interval = _or(item.param1, 0.0) / 1000.0
            self._start_photos(interval_s=interval, count=0) if interval > 0 else \
                self._start_photos(interval_s=0.0, count=-1)
        elif cmd == Cmd.DO_DIGICAM_CONTROL:
            if _or(item.x, 0.0) >= 0.5:  # param5 "shoot"
                self.take_photo()
        elif cmd == Cmd.VIDEO_START_CAPTURE:
            self.events.append(NavEvent(self._now, "video_start", item.seq))
        elif cmd == Cmd.VIDEO_STOP_CAPTURE:
            self.events.append(NavEvent(self._now, "video_stop", item.seq))
        return None

    def _setup_nav(self, item: MissionItem, est: Estimate) -> None:
        home = self.home if self.home is not None else est.position_ned_m
        ref = self._line.position if self._line is not None else self._hold_pos \
            if self._stage == "wait" else est.position_ned_m
        cmd = item.command
        self._item_reached_at = None
        self._wait_until = math.inf
        if cmd == Cmd.NAV_RETURN_TO_LAUNCH:
            self._reached(item.seq)
            self._state = MissionState.COMPLETE if self.current == len(
                self._lists[MissionType.MISSION]) - 1 else MissionState.ACTIVE
            self._event("mission: return to launch")
            self._request_mode(FlightMode.RETURN)
            return
        if cmd in (Cmd.NAV_DELAY, Cmd.CONDITION_DELAY):
            self._stage = "wait"
            self._hold_pos = np.asarray(ref, dtype=float).copy()
            delay = _or(item.param1, 0.0)
            self._wait_until = self._now + max(0.0, delay)
            self._item_target = self._hold_pos.copy()
            return
        target = self._position_of(item, home, current=est.position_ned_m)
        self._item_target = target
        if cmd == Cmd.NAV_TAKEOFF:
            self._stage = "takeoff"
            self._inserted_takeoff = False
            self._start_takeoff(est, float(home[2] - target[2]))
            self._takeoff_target[:2] = est.position_ned_m[:2]
            return
        if cmd == Cmd.NAV_LAND:
            target = target.copy()
            target[2] = ref[2]  # fly there at the current altitude, then descend
            self._item_target = target
        speed = float(np.dot(est.velocity_ned_m_s, _unit(target - np.asarray(ref))))
        self._line = LineTracker(ref, target, max(0.0, speed))
        self._stage = "fly"

    def _mission_tick(self, dt: float, est: Estimate, height_agl_m: float,
                      landed: bool) -> NavSetpoint:
        p = self.params
        items = self._lists[MissionType.MISSION]
        if self._stage == "takeoff":
            return self._takeoff_tick(dt, est, FlightMode.MISSION)
        if self._stage == "done" or self.current >= len(items):
            return NavSetpoint(self._hold_setpoint())
        item = items[self.current]
        if self._stage == "land":
            if landed:
                self._reached(item.seq)
                self.current += 1
                self._finish(est, landed=True)
                return NavSetpoint(self._hold_setpoint())
            return self._land_tick(est, height_agl_m, self._item_target[:2])
        if self._stage == "wait":
            if self._now >= self._wait_until:
                self._advance(item, est)
            return NavSetpoint(ControlSetpoint(self._hold_pos.tolist(), [NAN, NAN, NAN],
                                               self._slew_yaw(self._hold_yaw, dt),
                                               xy_vel_max_m_s=p["MPC_XY_CRUISE"]))
        if self._stage == "loiter":
            return NavSetpoint(ControlSetpoint(self._item_target.tolist(), [NAN, NAN, NAN],
                                               self._slew_yaw(self._hold_yaw, dt)))
        line = self._line
        if line is None:
            self._start_item(est)
            return NavSetpoint(self._hold_setpoint())
        cruise = self._speed_override if math.isfinite(self._speed_override) \
            else p["MPC_XY_CRUISE"]
        v_max = line.speed_limit(min(cruise, p["MPC_XY_VEL_MAX"]), p["MPC_Z_V_AUTO_UP"],
                                 p["MPC_Z_V_AUTO_DN"])
        end_speed = self._corner_speed(item, v_max)
        pos, vel, acc = line.step(dt, v_max, p["MPC_ACC_HOR"], est.position_ned_m, end_speed)
        desired_yaw = self._item_yaw(item, est)
        if math.isfinite(desired_yaw):
            self._hold_yaw = desired_yaw
        yaw = self._slew_yaw(self._hold_yaw, dt)
        if self._is_reached(item, est, line, end_speed):
            if self._item_reached_at is None:
                self._item_reached_at = self._now
                if item.command == Cmd.NAV_LAND:
                    self._stage = "land"
                    self._land_xy = self._item_target[:2].copy()
                    self._hold_yaw = yaw
                    return self._land_tick(est, height_agl_m, self._item_target[:2])
            hold_s = _or(item.param1, 0.0) if item.command in (Cmd.NAV_WAYPOINT,
                                                                Cmd.NAV_LOITER_TIME) else 0.0
            if item.command == Cmd.NAV_LOITER_UNLIM:
                self._reached(item.seq)
                self._stage = "loiter"
                self._hold_yaw = yaw
            elif self._now - self._item_reached_at >= max(0.0, hold_s):
                self._hold_pos = line.position.copy() if end_speed <= 0 else self._hold_pos
                self._advance(item, est)
        return NavSetpoint(ControlSetpoint(pos.tolist(), vel.tolist(), yaw,
                                           acceleration_ned_m_s2=acc.tolist()))

    def _advance(self, item: MissionItem, est: Estimate) -> None:
        self._reached(item.seq)
        self.current += 1
        self._events_current()
        line, mode = self._line, self._mode
        self._run_do_items(est)
        if self._mode is not mode:
            return  # the next item changed the mode (NAV_RETURN_TO_LAUNCH): it flies on
        if self._line is not None and line is not None and self._line is not line and \
                self._stage == "fly":
            # fly through: the new segment starts where the reference is, at its speed
            self._line = LineTracker(line.position, self._line.end,
                                     max(0.0, float(np.dot(line.velocity,
                                                           self._line.direction))))

    def _finish(self, est: Estimate, landed: bool = False) -> None:
        items = self._lists[MissionType.MISSION]
        self.current = max(0, len(items) - 1)
        if self._state is not MissionState.COMPLETE:
            self._state = MissionState.COMPLETE
            self._stage = "done"
            ref = self._line.position if self._line is not None and not landed \
                else est.position_ned_m
            self._hold_pos = np.asarray(ref, dtype=float).copy()
            self._line = None
            self.events.append(NavEvent(self._now, "finished", self.current))
            # PX4's texts: "Mission finished, landed" after a NAV_LAND, else loitering
            self._event("mission finished, landed" if landed else "mission finished, loitering")

    def _is_reached(self, item: MissionItem, est: Estimate, line: LineTracker,
                    end_speed: float) -> bool:
        p = self.params
        target = self._item_target
        acc_rad = item.param2 if item.command == Cmd.NAV_WAYPOINT and _or(item.param2, 0) > 0 \
            else p["NAV_ACC_RAD"]
        horizontal = float(np.hypot(*(est.position_ned_m[:2] - target[:2])))
        vertical = abs(float(est.position_ned_m[2] - target[2]))
        if horizontal > acc_rad or vertical > p["NAV_MC_ALT_RAD"]:
            return False
        # a waypoint flown through counts when the vehicle is within the radius; one that is
        # stopped at, once the reference has arrived too
        return end_speed > 0 or line.done

    def _corner_speed(self, item: MissionItem, v_max: float) -> float:
        """Speed to pass ``item`` at: 0 to stop there, more when it is flown through towards
        the next waypoint (slower the sharper the turn)."""
        if item.command != Cmd.NAV_WAYPOINT or _or(item.param1, 0.0) > 0:
            return 0.0
        nxt = self._next_nav(self.current + 1)
        if nxt is None or nxt.command != Cmd.NAV_WAYPOINT or self._line is None:
            return 0.0
        home = self.home if self.home is not None else self._item_target
        after = self._position_of(nxt, home, current=self._item_target) - self._item_target
        if float(np.linalg.norm(after)) < 1e-3:
            return 0.0
        cos_turn = float(np.dot(self._line.direction, _unit(after)))
        speed = v_max * max(0.0, cos_turn) ** 2 * 0.5 + 0.5 * max(0.0, cos_turn) * \
            min(v_max, math.sqrt(self.params["MPC_ACC_HOR"] * self.params["NAV_ACC_RAD"]))
        # a corner this slow is a stop: without the threshold a right angle off by a rounding
        # error counted as flown through, reached a whole NAV_ACC_RAD early at cruise speed
        return speed if speed >= _MIN_CORNER_SPEED_M_S else 0.0

    def _next_nav(self, start: int) -> MissionItem | None:
        items = self._lists[MissionType.MISSION]
        return next((i for i in items[start:] if i.is_nav), None)

    def _item_yaw(self, item: MissionItem, est: Estimate) -> float:
        if item.command == Cmd.NAV_WAYPOINT and math.isfinite(item.param4):
            return math.radians(item.param4)
        if int(self.params["MPC_YAW_MODE"]) != 0:
            return NAN
        delta = self._item_target[:2] - est.position_ned_m[:2]
        if float(np.hypot(*delta)) < _YAW_TO_TARGET_MIN_M:
            return NAN
        return math.atan2(delta[1], delta[0])

    def _position_of(self, item: MissionItem, home: np.ndarray,
                     current: np.ndarray | None = None) -> np.ndarray:
        """Local NED of an item's position (a missing or zero lat/lon: ``current``'s)."""
        here = home if current is None else current
        n, e, d = (float(v) for v in here)
        frame = item.frame
        if item.has_position and not (frame in GLOBAL_FRAMES and item.x == 0 and item.y == 0):
            if frame in GLOBAL_FRAMES:
                n, e, _ = self.origin.to_ned(item.x, item.y, self.origin.alt_amsl_m)
            elif frame == Frame.LOCAL_NED:
                n, e = item.x, item.y
        if math.isfinite(item.z):
            if frame in RELATIVE_ALT_FRAMES:
                d = float(home[2]) - item.z
            elif frame in GLOBAL_FRAMES:
                d = self.origin.alt_amsl_m - item.z
            elif frame == Frame.LOCAL_NED:
                d = item.z
        return np.array([n, e, d])

    def _reached(self, seq: int) -> None:
        self.events.append(NavEvent(self._now, "reached", seq))

    def _events_current(self) -> None:
        self.events.append(NavEvent(self._now, "current", self.current))

    def _estimate_now(self) -> Estimate:
        return self._est

    # ------------------------------------------------------------------------------------
    # Camera triggering
    # ------------------------------------------------------------------------------------

    def camera_tick(self, now: float, est: Estimate) -> None:
        """Interval and distance triggering: every position-loop tick in flight, whatever the
        mode (a survey flown in OFFBOARD triggers too)."""
        self._now = now
        self._camera(now, est)

    def start_photos(self, interval_s: float, count: int) -> None:
        """IMAGE_START_CAPTURE as a command: one photo, or ``count`` every ``interval_s``
        (count 0: until IMAGE_STOP_CAPTURE)."""
        self._start_photos(interval_s=interval_s, count=count)

    def stop_photos(self) -> None:
        self._photo_interval_s, self._photo_next_s, self._photos_left = 0.0, math.inf, 0

    def take_photo(self) -> None:
        self.events.append(NavEvent(self._now, "photo", self._photo_index))
        self._photo_index += 1
        self._dist_since_photo = 0.0

    def _start_photos(self, interval_s: float, count: int) -> None:
        """IMAGE_START_CAPTURE: one photo (count 1 or no interval), or one every
        ``interval_s`` (``count`` of them; 0: until stopped)."""
        if count < 0:
            self._photo_interval_s, self._photo_next_s, self._photos_left = 0.0, math.inf, 0
            return
        interval = _or(interval_s, 0.0)
        if count == 1 or interval <= 0:
            self.take_photo()
            return
        self.take_photo()
        self._photo_interval_s = interval
        self._photo_next_s = self._now + interval
        self._photos_left = count - 1 if count > 0 else 0
        if count > 0 and self._photos_left == 0:
            self._photo_next_s = math.inf

    def set_trigger_distance(self, distance_m: float, trigger_now: bool = False) -> None:
        """DO_SET_CAM_TRIGG_DIST: a photo every ``distance_m`` travelled (0: stop)."""
        self._trigger_dist_m = max(0.0, _or(distance_m, 0.0))
        self._dist_since_photo = 0.0
        if trigger_now and self._trigger_dist_m > 0:
            self.take_photo()

    def _camera(self, now: float, est: Estimate) -> None:
        xy = est.position_ned_m[:2]
        if self._last_xy is not None and self._trigger_dist_m > 0:
            self._dist_since_photo += float(np.hypot(*(xy - self._last_xy)))
            if self._dist_since_photo >= self._trigger_dist_m:
                self.take_photo()
        self._last_xy = np.array(xy, dtype=float)
        if now >= self._photo_next_s:
            self.take_photo()
            if self._photos_left > 0:
                self._photos_left -= 1
                if self._photos_left == 0:
                    self._photo_next_s = math.inf
                    return
            self._photo_next_s += self._photo_interval_s

    # ------------------------------------------------------------------------------------
    # Return to launch
    # ------------------------------------------------------------------------------------

    def return_altitude_m(self, est: Estimate) -> float:
        """Height above home to return at (PX4's RTL with RTL_CONE_ANG): RTL_RETURN_ALT, but
        within RTL_MIN_DIST of home only as high as the cone of half-angle RTL_CONE_ANG above
        it (at least twice NAV_ACC_RAD, and twice the distance inside NAV_ACC_RAD); never
        below the current height (RTL does not descend before it returns)."""
        p = self.params
        home = self.home if self.home is not None else est.position_ned_m
        height = float(home[2] - est.position_ned_m[2])
        ret = p["RTL_RETURN_ALT"]
        cone = p["RTL_CONE_ANG"]
        if cone > 0:
            distance = float(np.hypot(*(est.position_ned_m[:2] - home[:2])))
            acc_rad = p["NAV_ACC_RAD"]
            if distance <= acc_rad:
                ret = 2.0 * distance
            else:
                if distance <= p["RTL_MIN_DIST"]:
                    half_angle = math.radians(min(max(cone, 1.0), 89.0))
                    ret = min(distance / math.tan(half_angle), ret)
                ret = max(ret, 2.0 * acc_rad)
        return max(min(ret, p["RTL_RETURN_ALT"]), height)

    def _start_rtl(self, est: Estimate) -> None:
        home = self.home if self.home is not None else est.position_ned_m
        self._rtl_alt_down = float(home[2] - self.return_altitude_m(est))
        start = self._stopping_point(est, landed=False)
        self._line = LineTracker(est.position_ned_m, [start[0], start[1], self._rtl_alt_down])
        self._rtl_stage = "climb"
        self._hold_yaw = est.yaw_rad
        self._speed_override = NAN  # PX4 resets the cruise speed on RTL
        self._event(f"RTL: start return at {self.origin.alt_amsl_m - self._rtl_alt_down:.0f} m "
                    f"({home[2] - self._rtl_alt_down:.0f} m above destination)")

    def _rtl_tick(self, dt: float, est: Estimate, height_agl_m: float) -> NavSetpoint:
        p = self.params
        home = self.home if self.home is not None else est.position_ned_m
        if self._rtl_stage == "land":
            return self._land_tick(est, height_agl_m, home[:2])
        if self._rtl_stage == "loiter":
            delay = p["RTL_LAND_DELAY"]
            if delay >= 0 and self._now >= self._wait_until:
                self._rtl_stage = "land"
                self._event("RTL: land at destination")
                return self._land_tick(est, height_agl_m, home[:2])
            return NavSetpoint(ControlSetpoint(self._hold_pos.tolist(), [NAN, NAN, NAN],
                                               self._slew_yaw(self._hold_yaw, dt)))
        line = self._line
        cruise = self._speed_override if math.isfinite(self._speed_override) \
            else p["MPC_XY_CRUISE"]
        v_max = line.speed_limit(cruise, p["MPC_Z_V_AUTO_UP"], p["MPC_Z_V_AUTO_DN"])
        pos, vel, acc = line.step(dt, v_max, p["MPC_ACC_HOR"], est.position_ned_m)
        if self._rtl_stage == "return":
            delta = home[:2] - est.position_ned_m[:2]
            if float(np.hypot(*delta)) > _YAW_TO_TARGET_MIN_M:
                self._hold_yaw = math.atan2(delta[1], delta[0])
        yaw = self._slew_yaw(self._hold_yaw, dt)
        near = float(np.linalg.norm(est.position_ned_m - line.end)) < p["NAV_ACC_RAD"]
        if line.done and near:
            self._next_rtl_stage(est, home)
        return NavSetpoint(ControlSetpoint(pos.tolist(), vel.tolist(), yaw,
                                           acceleration_ned_m_s2=acc.tolist()))

    def _next_rtl_stage(self, est: Estimate, home: np.ndarray) -> None:
        p = self.params
        end = self._line.end
        if self._rtl_stage == "climb":
            self._rtl_stage = "return"
            self._line = LineTracker(end, [home[0], home[1], end[2]])
            self._event("RTL: returning home")
            return
        delay = p["RTL_LAND_DELAY"]
        if delay == 0:  # PX4: straight from the return altitude into the landing
            self._rtl_stage = "land"
            self._hold_yaw = self._yaw_sp
            self._event("RTL: land at destination")
            return
        loiter_down = float(home[2] - min(p["RTL_DESCEND_ALT"], home[2] - end[2]))
        if self._rtl_stage == "return" and end[2] < loiter_down - 0.1:
            self._rtl_stage = "descend"
            self._line = LineTracker(end, [home[0], home[1], loiter_down])
            return
        self._hold_pos = np.array(end, dtype=float)
        self._wait_until = self._now + max(0.0, delay)
        self._rtl_stage = "loiter"
        if delay < 0:
            self._event("RTL: completed, loitering")

    # ------------------------------------------------------------------------------------
    # Geofence
    # ------------------------------------------------------------------------------------

    def geofence_breach(self, position_ned_m: np.ndarray) -> str | None:
        """Why ``position_ned_m`` is outside the geofence (None: inside, or no fence)."""
        if self.home is None:
            return None
        p = self.params
        horizontal = float(np.hypot(*(position_ned_m[:2] - self.home[:2])))
        height = float(self.home[2] - position_ned_m[2])
        max_h, max_v = p["GF_MAX_HOR_DIST"], p["GF_MAX_VER_DIST"]
        if max_h > 0 and horizontal > max_h:
            return f"{horizontal:.0f} m from home, GF_MAX_HOR_DIST {max_h:g} m"
        if max_v > 0 and height > max_v:
            return f"{height:.0f} m above home, GF_MAX_VER_DIST {max_v:g} m"
        fence = self._fence
        return fence.breach(float(position_ned_m[0]), float(position_ned_m[1])) \
            if fence is not None else None

    @property
    def fence(self) -> Fence | None:
        """The uploaded geofence's areas (None: none)."""
        return self._fence

    def _publish(self) -> None:
        items = self._lists[MissionType.MISSION]
        self.status = MissionStatus(
            total=len(items), current=self.current if items else 0, state=self._state,
            in_mission_mode=self._mode is FlightMode.MISSION,
            mission_id=self._ids[MissionType.MISSION], fence_id=self._ids[MissionType.FENCE],
            rally_id=self._ids[MissionType.RALLY])

    def _status(self) -> MissionStatus:
        return MissionStatus(0, 0, MissionState.NO_MISSION, False, 0, 0, 0)


@dataclass(frozen=True, slots=True, eq=False)
class FenceArea:
    """One inclusion or exclusion area of an uploaded geofence, in local NED (north, east)."""

    inclusion: bool
    shape: str  # "polygon" | "circle"
    #: the area's number among the fence's polygons (or circles), in upload order
    index: int
    #: the mission items it was made of (sequence numbers)
    seqs: tuple[int, ...]
    #: polygons: a prepared shapely geometry (a self-intersecting outline is made valid with
    #: the even-odd rule, as PX4's crossing-number test sees it)
    geometry: shapely.Geometry | None = None
    center_ne_m: tuple[float, float] = (0.0, 0.0)
    radius_m: float = 0.0

    @property
    def name(self) -> str:
        return f"{'inclusion' if self.inclusion else 'exclusion'} {self.shape} {self.index}"

    def contains(self, north_m: float, east_m: float) -> bool:
        """Whether the point is in the area. The boundary counts as allowed: inside an
        inclusion area, outside an exclusion area."""
        if self.geometry is None:
            inside = math.hypot(north_m - self.center_ne_m[0], east_m - self.center_ne_m[1])
            return inside <= self.radius_m if self.inclusion else inside < self.radius_m
        if self.inclusion:
            return bool(shapely.intersects_xy(self.geometry, north_m, east_m))
        return bool(shapely.contains_xy(self.geometry, north_m, east_m))


class Fence:
    """An uploaded geofence (MAVLink mission type 1), built once per upload: the horizontal
    position is inside when it is in at least one inclusion area (or there is none) and in no
    exclusion area, as PX4's ``Geofence::isInsidePolygonOrCircle``."""

    def __init__(self, areas: Sequence[FenceArea]) -> None:
        self.areas = tuple(areas)
        self.inclusions = tuple(a for a in self.areas if a.inclusion)
        self.exclusions = tuple(a for a in self.areas if not a.inclusion)

    @classmethod
    def from_items(cls, items: Sequence[MissionItem], origin: GlobalOrigin) -> Fence | None:
        """The fence of a list of fence items (sorted by seq); None if it has no area.
        Raises :class:`MissionRejected` (MISSION_ERROR) for a malformed list."""
        areas: list[FenceArea] = []
        counts = {"polygon": 0, "circle": 0}
        i = 0
        while i < len(items):
            item = items[i]
            cmd = item.command
            if cmd in (Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                       Cmd.NAV_FENCE_POLYGON_VERTEX_EXCLUSION):
                group = _polygon_group(items, i)
                vertices = [_fence_point(v, origin) for v in group]
                areas.append(FenceArea(cmd == Cmd.NAV_FENCE_POLYGON_VERTEX_INCLUSION, "polygon",
                                       counts["polygon"], tuple(v.seq for v in group),
                                       geometry=_polygon_geometry(vertices, group[0].seq)))
                counts["polygon"] += 1
                i += len(group)
                continue
            if cmd in (Cmd.NAV_FENCE_CIRCLE_INCLUSION, Cmd.NAV_FENCE_CIRCLE_EXCLUSION):
                radius = item.param1
                if not (math.isfinite(radius) and radius > 0):
                    raise MissionRejected(f"fence item {item.seq}: circle radius (param1) must "
                                          f"be positive, got {radius:g}", MISSION_ERROR,
                                          item.seq)
                areas.append(FenceArea(cmd == Cmd.NAV_FENCE_CIRCLE_INCLUSION, "circle",
                                       counts["circle"], (item.seq,),
                                       center_ne_m=_fence_point(item, origin),
                                       radius_m=float(radius)))
                counts["circle"] += 1
            elif cmd != Cmd.NAV_FENCE_RETURN_POINT:  # the return point is not used
                raise MissionRejected(f"fence item {item.seq}: command {cmd} is not a fence "
                                      "item", MISSION_ERROR, item.seq)
            i += 1
        return cls(areas) if areas else None

    def breach(self, north_m: float, east_m: float) -> str | None:
        """Why the horizontal position is outside the fence (None: inside)."""
        if self.inclusions and not any(a.contains(north_m, east_m) for a in self.inclusions):
            if len(self.inclusions) == 1:
                return f"outside the {self.inclusions[0].name}"
            return "outside every inclusion area (" + ", ".join(
                a.name.removeprefix("inclusion ") for a in self.inclusions) + ")"
        for area in self.exclusions:
            if area.contains(north_m, east_m):
                return f"inside the {area.name}"
        return None


def _polygon_group(items: Sequence[MissionItem], start: int) -> list[MissionItem]:
    """The vertices of the polygon that starts at ``items[start]`` (param1: vertex count)."""
    first = items[start]
    count = first.param1
    if not (math.isfinite(count) and count == int(count) and count >= 3):
        raise MissionRejected(f"fence item {first.seq}: a polygon needs at least 3 vertices "
                              f"(param1 = {count:g})", MISSION_ERROR, first.seq)
    group = list(items[start:start + int(count)])
    for vertex in group:
        if vertex.command != first.command or vertex.param1 != count:
            raise MissionRejected(f"fence item {vertex.seq}: polygon from item {first.seq} "
                                  f"should have {int(count)} vertices of command "
                                  f"{first.command}", MISSION_ERROR, vertex.seq)
    if len(group) < count:
        raise MissionRejected(f"fence item {first.seq}: polygon of {int(count)} vertices has "
                              f"only {len(group)}", MISSION_ERROR, first.seq)
    return group


def _fence_point(item: MissionItem, origin: GlobalOrigin) -> tuple[float, float]:
    """(north, east) of a fence item's position."""
    if not item.has_position:
        raise MissionRejected(f"fence item {item.seq}: no position", MISSION_ERROR, item.seq)
    if item.frame in GLOBAL_FRAMES:
        north, east, _ = origin.to_ned(item.x, item.y, origin.alt_amsl_m)
        return north, east
    if item.frame == Frame.LOCAL_NED:
        return float(item.x), float(item.y)
    raise MissionRejected(f"fence item {item.seq}: frame {item.frame} is not supported",
                          MISSION_ERROR, item.seq)


def _polygon_geometry(vertices: list[tuple[float, float]], seq: int) -> shapely.Geometry:
    geometry = shapely.make_valid(shapely.Polygon(vertices))
    if not geometry.geom_type.endswith("Polygon"):  # e.g. lines left of a degenerate outline
        parts = [g for g in shapely.get_parts(geometry) if g.geom_type == "Polygon"]
        geometry = shapely.MultiPolygon(parts) if parts else shapely.Polygon()
    if geometry.is_empty or geometry.area <= 1e-6:
        raise MissionRejected(f"fence item {seq}: the polygon encloses no area",
                              MISSION_ERROR, seq)
    shapely.prepare(geometry)
    return geometry


def estimate_of(position_ned_m, velocity_ned_m_s, q_ned_frd) -> Estimate:
    return Estimate(np.asarray(position_ned_m, dtype=float),
                    np.asarray(velocity_ned_m_s, dtype=float), yaw_from_quat(q_ned_frd))


def _or(value: float, default: float) -> float:
    return value if math.isfinite(value) else default


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else np.zeros(3)


def _mission_id(items: Sequence[MissionItem]) -> int:
    """A 32-bit id of a list's contents (MISSION_CURRENT.mission_id; 0: empty), as PX4's CRC
    of the items lets a ground station tell whether its copy is current."""
    if not items:
        return 0
    import zlib

    data = repr([(i.frame, i.command, i.param1, i.param2, i.param3, i.param4, i.x, i.y, i.z,
                  i.autocontinue) for i in items]).encode()
    return zlib.crc32(data) or 1
