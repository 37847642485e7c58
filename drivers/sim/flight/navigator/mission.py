"""MISSION (PX4's ``Mission``): the uploaded mission items in order, MISSION_CURRENT / reached
events.

NAV_WAYPOINT (param1 hold time, param2 acceptance radius or NAV_ACC_RAD, param4 yaw; a waypoint
without hold time that is followed by another is flown through), NAV_TAKEOFF, NAV_LAND,
NAV_RETURN_TO_LAUNCH (switches to RETURN, as PX4 does), NAV_LOITER_TIME, NAV_LOITER_UNLIM,
NAV_DELAY, DO_JUMP, DO_CHANGE_SPEED, and the camera items (IMAGE_START/STOP_CAPTURE,
DO_SET_CAM_TRIGG_DIST / _INTERVAL, DO_DIGICAM_CONTROL, VIDEO_START/STOP_CAPTURE), which become
photo and video events. Started on the ground, a mission first takes off (to the first
waypoint's altitude, at least MIS_TAKEOFF_ALT), as PX4 does. Paused (HOLD) and resumed, it
continues with the current item."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from drivers.base import FlightMode
from drivers.mission import Cmd, MissionItem
from drivers.sim.flight.navigator.camera_trigger import CameraTrigger
from drivers.sim.flight.navigator.context import (
    NAN,
    YAW_TO_TARGET_MIN_M,
    Estimate,
    MissionState,
    NavContext,
    NavSetpoint,
    or_default,
)
from drivers.sim.flight.navigator.takeoff import Takeoff
from drivers.sim.flight.position_control import ControlSetpoint
from drivers.sim.flight.trajectory import LineTracker

_MAX_DO_ITEMS_PER_TICK = 100  # DO_JUMP loops without a nav item must not hang the vehicle
_MIN_CORNER_SPEED_M_S = 0.5  # a waypoint to be passed slower than this is stopped at


class MissionMode:
    def __init__(self, ctx: NavContext, takeoff: Takeoff, camera: CameraTrigger) -> None:
        self.ctx = ctx
        self.takeoff = takeoff
        self.camera = camera
        self.items: list[MissionItem] = []
        self.current = 0
        self.state = MissionState.NO_MISSION
        self._stage = "idle"  # idle | takeoff | fly | wait | land | loiter | done
        self._inserted_takeoff = False  # the takeoff stage climbs before the first item
        self._restart = False  # flown, then disarmed: the next MISSION starts at item 0
        self._line: LineTracker | None = None
        self._wait_until = math.inf
        self._item_target = np.zeros(3)
        self._item_reached_at: float | None = None
        self._jumps: dict[int, int] = {}

    # -- storage and control from outside --------------------------------------------------

    def stored(self, items: list[MissionItem]) -> None:
        """A new mission: from its first item, at the default cruise speed."""
        self.items = items
        self.current = 0
        self._restart = False
        self._jumps.clear()
        self.ctx.speed_override = NAN
        self.state = MissionState.NOT_STARTED if items else MissionState.NO_MISSION
        self._stage = "idle"
        if self.ctx.mode is FlightMode.MISSION:  # a new mission while flying one: restart it
            self._start_item(self.ctx.est)
        self._events_current()

    def set_current(self, seq: int) -> None:
        """MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT: fly item ``seq`` next."""
        if not 0 <= seq < len(self.items):
            raise ValueError(f"mission item {seq} does not exist (the mission has "
                             f"{len(self.items)} items)")
        self.current = seq
        self._jumps.clear()
        self._restart = False  # the user's choice of item stands
        if self.state is MissionState.COMPLETE:
            self.state = MissionState.NOT_STARTED
        self._stage = "idle"
        if self.ctx.mode is FlightMode.MISSION:
            self._start_item(self.ctx.est)
        self._events_current()

    def problem(self, landed: bool, breach: Callable[[np.ndarray], str | None],
                fenced: bool) -> str | None:
        """Why MISSION cannot start now (None: it can): PX4's mission feasibility, simplified."""
        ctx, items = self.ctx, self.items
        if not items:
            return "no mission uploaded"
        if ctx.home is None and not landed:
            return "no home position"
        first = next((i for i in items[self.current:] if i.is_nav and i.has_position), None)
        limit = ctx.params["MIS_DIST_1WP"]
        if first is not None and limit > 0 and ctx.home is not None:
            target = ctx.position_of(first, ctx.home)
            distance = float(np.hypot(*(target[:2] - ctx.home[:2])))
            if distance > limit:
                return (f"first waypoint too far: {distance:.0f} m from home "
                        f"(MIS_DIST_1WP {limit:g} m)")
        if fenced and ctx.home is not None:
            # PX4's MissionFeasibilityChecker::checkGeofence: with a fence uploaded, every
            # item with a position must lie inside it (and within GF_MAX_HOR/VER_DIST)
            for item in items:
                if item.is_nav and item.has_position:
                    why = breach(ctx.position_of(item, ctx.home))
                    if why is not None:
                        return f"Geofence violation for waypoint {item.seq + 1} ({why})"
        return None

    def disarmed(self) -> None:
        if self.state in (MissionState.ACTIVE, MissionState.PAUSED, MissionState.COMPLETE):
            self._restart = True

    def paused(self) -> None:
        if self.state is MissionState.ACTIVE:
            self.state = MissionState.PAUSED

    def activate(self, est: Estimate, landed: bool) -> None:
        if self.state is MissionState.COMPLETE or self._restart:  # from the beginning
            self.current = 0
            self._jumps.clear()
            self._restart = False
        self.state = MissionState.ACTIVE
        self._stage = "idle"
        if landed:
            self._start_takeoff(est)
        else:
            self._start_item(est)
        self._events_current()

    # -- the tick --------------------------------------------------------------------------

    def tick(self, dt: float, est: Estimate, height_agl_m: float, landed: bool) -> NavSetpoint:
        ctx = self.ctx
        p, items = ctx.params, self.items
        if self._stage == "takeoff":
            climb = self.takeoff.tick(dt, est)
            if climb is not None:
                return climb
            self._takeoff_done()
            return NavSetpoint(ctx.hold_setpoint())
        if self._stage == "done" or self.current >= len(items):
            return NavSetpoint(ctx.hold_setpoint())
        item = items[self.current]
        if self._stage == "land":
            if landed:
                self._reached(item.seq)
                self.current += 1
                self._finish(est, landed=True)
                return NavSetpoint(ctx.hold_setpoint())
            return ctx.descend(est, height_agl_m, self._item_target[:2])
        if self._stage == "wait":
            if ctx.now >= self._wait_until:
                self._advance(item, est)
            return NavSetpoint(ControlSetpoint(ctx.hold_pos.tolist(), [NAN, NAN, NAN],
                                               ctx.slew_yaw(ctx.hold_yaw, dt),
                                               xy_vel_max_m_s=p["MPC_XY_CRUISE"]))
        if self._stage == "loiter":
            return NavSetpoint(ControlSetpoint(self._item_target.tolist(), [NAN, NAN, NAN],
                                               ctx.slew_yaw(ctx.hold_yaw, dt)))
        line = self._line
        if line is None:
            self._start_item(est)
            return NavSetpoint(ctx.hold_setpoint())
        v_max = line.speed_limit(min(ctx.cruise_m_s(), p["MPC_XY_VEL_MAX"]),
                                 p["MPC_Z_V_AUTO_UP"], p["MPC_Z_V_AUTO_DN"])
        nxt = next((i for i in items[self.current + 1:] if i.is_nav), None)
        end_speed = corner_speed(ctx, item, nxt, self._line, self._item_target, v_max)
        pos, vel, acc = line.step(dt, v_max, p["MPC_ACC_HOR"], est.position_ned_m, end_speed)
        desired_yaw = item_yaw(ctx.params, item, self._item_target, est)
        if math.isfinite(desired_yaw):
            ctx.hold_yaw = desired_yaw
        yaw = ctx.slew_yaw(ctx.hold_yaw, dt)
        if is_reached(ctx.params, item, self._item_target, est, line, end_speed):
            if self._item_reached_at is None:
                self._item_reached_at = ctx.now
                if item.command == Cmd.NAV_LAND:
                    self._stage = "land"
                    ctx.hold_yaw = yaw
                    return ctx.descend(est, height_agl_m, self._item_target[:2])
            hold_s = or_default(item.param1, 0.0) if item.command in (
                Cmd.NAV_WAYPOINT, Cmd.NAV_LOITER_TIME) else 0.0
            if item.command == Cmd.NAV_LOITER_UNLIM:
                self._reached(item.seq)
                self._stage = "loiter"
                ctx.hold_yaw = yaw
            elif ctx.now - self._item_reached_at >= max(0.0, hold_s):
                ctx.hold_pos = line.position.copy() if end_speed <= 0 else ctx.hold_pos
                self._advance(item, est)
        return NavSetpoint(ControlSetpoint(pos.tolist(), vel.tolist(), yaw,
                                           acceleration_ned_m_s2=acc.tolist()))

    # -- items -----------------------------------------------------------------------------

    def _start_takeoff(self, est: Estimate) -> None:
        ctx, items = self.ctx, self.items
        item = items[self.current] if self.current < len(items) else None
        if item is not None and item.command == Cmd.NAV_TAKEOFF:
            self._start_item(est)  # the mission's own takeoff item
            return
        home = ctx.home_or(est.position_ned_m)
        altitude = ctx.params["MIS_TAKEOFF_ALT"]
        first = next((i for i in items[self.current:] if i.is_nav and i.has_position), None)
        if first is not None:
            altitude = max(altitude, float(home[2] - ctx.position_of(first, home)[2]))
        self.takeoff.start(est, altitude)
        self._stage = "takeoff"
        self._inserted_takeoff = True
        ctx.event(f"Takeoff to {altitude:.1f} meters above home")

    def _takeoff_done(self) -> None:
        self.takeoff.profile = None
        if self._inserted_takeoff or self.current >= len(self.items):
            self._inserted_takeoff = False  # the climb before the first item: fly it now
            self._start_item(self.ctx.est)
        else:  # the mission's own NAV_TAKEOFF item is done
            self._stage = "fly"
            self._advance(self.items[self.current], self.ctx.est)

    def _start_item(self, est: Estimate) -> None:
        """Set up the current item from where the vehicle (or its reference) is now."""
        self._stage = "idle"
        self._line = None
        self._item_reached_at = None
        self._wait_until = math.inf
        self._run_do_items(est)

    def _run_do_items(self, est: Estimate) -> None:
        """Execute non-navigation items up to the next navigation item, then set it up."""
        items = self.items
        for _ in range(_MAX_DO_ITEMS_PER_TICK):
            if self.current >= len(items):
                self._finish(est)
                return
            item = items[self.current]
            if item.is_nav:
                self._setup_nav(item, est)
                return
            jump = do_item(item, self.ctx, self.camera, self._jumps, len(self.items))
            self._reached(item.seq)
            self.current = jump if jump is not None else self.current + 1
            self._events_current()
        self.ctx.event("mission: DO_JUMP loop without a navigation item; holding")
        self._finish(est)

    def _setup_nav(self, item: MissionItem, est: Estimate) -> None:
        ctx = self.ctx
        home = ctx.home_or(est.position_ned_m)
        ref = self._line.position if self._line is not None else ctx.hold_pos \
            if self._stage == "wait" else est.position_ned_m
        cmd = item.command
        self._item_reached_at = None
        self._wait_until = math.inf
        if cmd == Cmd.NAV_RETURN_TO_LAUNCH:
            self._reached(item.seq)
            self.state = MissionState.COMPLETE if self.current == len(self.items) - 1 \
                else MissionState.ACTIVE
            ctx.event("mission: return to launch")
            ctx.request_mode(FlightMode.RETURN)
            return
        if cmd in (Cmd.NAV_DELAY, Cmd.CONDITION_DELAY):
            self._stage = "wait"
            ctx.hold_pos = np.asarray(ref, dtype=float).copy()
            self._wait_until = ctx.now + max(0.0, or_default(item.param1, 0.0))
            self._item_target = ctx.hold_pos.copy()
            return
        target = ctx.position_of(item, home, current=est.position_ned_m)
        self._item_target = target
        if cmd == Cmd.NAV_TAKEOFF:
            self._stage = "takeoff"
            self._inserted_takeoff = False
            self.takeoff.start(est, float(home[2] - target[2]))
            self.takeoff.target[:2] = est.position_ned_m[:2]
            return
        if cmd == Cmd.NAV_LAND:
            target = target.copy()
            target[2] = ref[2]  # fly there at the current altitude, then descend
            self._item_target = target
        speed = float(np.dot(est.velocity_ned_m_s, _unit(target - np.asarray(ref))))
        self._line = LineTracker(ref, target, max(0.0, speed))
        self._stage = "fly"

    def _advance(self, item: MissionItem, est: Estimate) -> None:
        self._reached(item.seq)
        self.current += 1
        self._events_current()
        line, mode = self._line, self.ctx.mode
        self._run_do_items(est)
        if self.ctx.mode is not mode:
            return  # the next item changed the mode (NAV_RETURN_TO_LAUNCH): it flies on
        if self._line is not None and line is not None and self._line is not line and \
                self._stage == "fly":
            # fly through: the new segment starts where the reference is, at its speed
            self._line = LineTracker(line.position, self._line.end,
                                     max(0.0, float(np.dot(line.velocity,
                                                           self._line.direction))))

    def _finish(self, est: Estimate, landed: bool = False) -> None:
        ctx = self.ctx
        self.current = max(0, len(self.items) - 1)
        if self.state is not MissionState.COMPLETE:
            self.state = MissionState.COMPLETE
            self._stage = "done"
            ref = self._line.position if self._line is not None and not landed \
                else est.position_ned_m
            ctx.hold_pos = np.asarray(ref, dtype=float).copy()
            self._line = None
            ctx.emit("finished", self.current)
            # PX4's texts: "Mission finished, landed" after a NAV_LAND, else loitering
            ctx.event("mission finished, landed" if landed else "mission finished, loitering")

    def _reached(self, seq: int) -> None:
        self.ctx.emit("reached", seq)

    def _events_current(self) -> None:
        self.ctx.emit("current", self.current)



def do_item(item: MissionItem, ctx: NavContext, camera: CameraTrigger, jumps: dict[int, int],
            count: int) -> int | None:
    """Carry out a DO/camera item; returns the item to continue with for DO_JUMP (``jumps``:
    how often each DO_JUMP has jumped; ``count``: the mission's items)."""
    cmd = item.command
    if cmd == Cmd.DO_JUMP:
        target, repeat = int(item.param1), int(item.param2)
        done = jumps.get(item.seq, 0)
        if 0 <= target < count and (repeat < 0 or done < repeat):
            jumps[item.seq] = done + 1
            return target
    elif cmd == Cmd.DO_CHANGE_SPEED:
        ctx.speed_override = item.param2 if item.param2 > 0 else NAN
    elif cmd == Cmd.IMAGE_START_CAPTURE:
        camera.start(interval_s=item.param2, count=int(or_default(item.param3, 0)))
    elif cmd == Cmd.IMAGE_STOP_CAPTURE:
        camera.stop()
    elif cmd == Cmd.DO_SET_CAM_TRIGG_DIST:
        camera.set_distance(item.param1, trigger_now=or_default(item.param3, 0) >= 0.5)
    elif cmd == Cmd.DO_SET_CAM_TRIGG_INTERVAL:
        interval = or_default(item.param1, 0.0) / 1000.0
        camera.start(interval_s=interval, count=0) if interval > 0 else \
            camera.start(interval_s=0.0, count=-1)
    elif cmd == Cmd.DO_DIGICAM_CONTROL:
        if or_default(item.x, 0.0) >= 0.5:  # param5 "shoot"
            camera.take_photo()
    elif cmd == Cmd.VIDEO_START_CAPTURE:
        ctx.emit("video_start", item.seq)
    elif cmd == Cmd.VIDEO_STOP_CAPTURE:
        ctx.emit("video_stop", item.seq)
    return None


def is_reached(p, item: MissionItem, target: np.ndarray, est: Estimate, line: LineTracker,
               end_speed: float) -> bool:
    """Whether ``item`` (its position ``target``) counts as reached."""
    acc_rad = item.param2 if item.command == Cmd.NAV_WAYPOINT and \
        or_default(item.param2, 0) > 0 else p["NAV_ACC_RAD"]
    horizontal = float(np.hypot(*(est.position_ned_m[:2] - target[:2])))
    vertical = abs(float(est.position_ned_m[2] - target[2]))
    if horizontal > acc_rad or vertical > p["NAV_MC_ALT_RAD"]:
        return False
    # a waypoint flown through counts when the vehicle is within the radius; one that is
    # stopped at, once the reference has arrived too
    return end_speed > 0 or line.done


def corner_speed(ctx: NavContext, item: MissionItem, nxt: MissionItem | None,
                 line: LineTracker | None, target: np.ndarray, v_max: float) -> float:
    """Speed to pass ``item`` (at ``target``) at: 0 to stop there, more when it is flown
    through towards the next waypoint ``nxt`` (slower the sharper the turn)."""
    if item.command != Cmd.NAV_WAYPOINT or or_default(item.param1, 0.0) > 0:
        return 0.0
    if nxt is None or nxt.command != Cmd.NAV_WAYPOINT or line is None:
        return 0.0
    p = ctx.params
    home = ctx.home_or(target)
    after = ctx.position_of(nxt, home, current=target) - target
    if float(np.linalg.norm(after)) < 1e-3:
        return 0.0
    cos_turn = float(np.dot(line.direction, _unit(after)))
    speed = v_max * max(0.0, cos_turn) ** 2 * 0.5 + 0.5 * max(0.0, cos_turn) * \
        min(v_max, math.sqrt(p["MPC_ACC_HOR"] * p["NAV_ACC_RAD"]))
    # a corner this slow is a stop: without the threshold a right angle off by a rounding
    # error counted as flown through, reached a whole NAV_ACC_RAD early at cruise speed
    return speed if speed >= _MIN_CORNER_SPEED_M_S else 0.0


def item_yaw(p, item: MissionItem, target: np.ndarray, est: Estimate) -> float:
    """The heading an item asks for (its yaw, or towards it with MPC_YAW_MODE 0; NaN: keep)."""
    if item.command == Cmd.NAV_WAYPOINT and math.isfinite(item.param4):
        return math.radians(item.param4)
    if int(p["MPC_YAW_MODE"]) != 0:
        return NAN
    delta = target[:2] - est.position_ned_m[:2]
    if float(np.hypot(*delta)) < YAW_TO_TARGET_MIN_M:
        return NAN
    return math.atan2(delta[1], delta[0])

def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else np.zeros(3)
